# eg2scope: `make demo` and `make test` set everything up on a fresh machine.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
NATIVE := $(VENV)/.native
# the native core's sources: the extension analyzer._native is rebuilt when one changes
# (native/src/generated.rs among them: native/codegen.py writes it from the Python tables)
NATIVE_SRC := $(wildcard native/Cargo.toml native/Cargo.lock native/src/*.rs native/src/*/*.rs) \
	native/src/generated.rs

.PHONY: venv native demo test lint typecheck unit rust bench clean

venv: $(STAMP) $(NATIVE)

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || { echo "eg2scope needs Python 3.11 or newer (PYTHON=$(PYTHON))"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,fleet]'
	@touch $(STAMP) $(NATIVE)
	@$(BIN)/eg2scope --version

# The native core (Rust, native/) is built by pip through setuptools-rust when cargo is on the
# PATH; without a Rust toolchain the install goes on in pure Python (eg2scope --version says
# which). Rebuilt here when its sources change; `make native` forces it, and first writes the
# crate's tables from the Python ones (native/codegen.py: plain Python, no cargo needed).
$(NATIVE): $(STAMP) $(NATIVE_SRC)
	$(BIN)/python native/codegen.py
	@rm -f analyzer/_native*.so  # a failed build must not leave the old core in place
	$(BIN)/python -m pip install --quiet --no-deps -e .
	@# with cargo present a build error must stop here (setuptools-rust would go on without it)
	@if command -v cargo >/dev/null 2>&1 && ! $(BIN)/python -c "import analyzer._native"; then \
		echo "the native core did not build: run '$(BIN)/python -m pip install -v --no-deps -e .' to see why" >&2; \
		exit 1; fi
	@touch $(NATIVE)
	@$(BIN)/eg2scope --version

native: $(STAMP)
	@rm -f $(NATIVE)
	@$(MAKE) --no-print-directory $(NATIVE)

# the TUI on a terminal; today's text output when stdout is not one (CI, pipes); the grip
# cycles tour every outcome (caught, missed, slipping, stalled, unanswered, bus-off on CAN)
DEMO_SCENARIO = --scenario tour
demo: venv
	@if [ -t 1 ]; then $(BIN)/eg2scope tui --demo $(DEMO_SCENARIO); else $(BIN)/eg2scope demo $(DEMO_SCENARIO); fi

lint: venv
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: venv
	$(BIN)/mypy

unit: venv
	$(BIN)/python -m pytest

# the native crate's own checks, where a Rust toolchain is installed (else said and skipped)
rust: venv
	@if command -v cargo >/dev/null 2>&1; then \
		cd native && cargo fmt --check && cargo clippy --release --all-targets --all-features -- -D warnings \
			&& cargo test --release --quiet; \
	else echo "no Rust toolchain: the native crate's checks are skipped"; fi

test: lint typecheck rust unit

# issue 10's figures: both engines and tshark on 1M frames per protocol, then Parquet
bench: venv
	$(BIN)/python tests/benchmarks/bench_decode.py
	$(BIN)/python tests/benchmarks/bench_parquet.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache native/target \
		analyzer/_native*.so
