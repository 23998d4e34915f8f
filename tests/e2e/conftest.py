"""Fixtures of the end-to-end matrix: every input kind made once per test session
(``e2e_inputs``), and each one's reference decode (``decode --format jsonl --engine python``, a
real process), reference state samples (a Python-engine session), and where a cell needs them
its grip cycles (``cycles --format jsonl --engine python``) and ``stats --format json``, real
processes too, which every cell is compared with."""

from __future__ import annotations

import os
from typing import Any

import orjson
import pytest

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from e2e_checks import Decoded, eg2scope, python_samples
from e2e_inputs import InputFolder

from analyzer.model import StateSample


@pytest.fixture(scope="session")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> InputFolder:
    return InputFolder(tmp_path_factory.mktemp("e2e-inputs"))


class References:
    """Each input's decode and state samples, made the first time a cell asks."""

    def __init__(self, inputs: InputFolder) -> None:
        self.inputs = inputs
        self._decoded: dict[str, Decoded] = {}
        self._samples: dict[str, list[StateSample]] = {}
        self._cycles: dict[str, list[dict[str, Any]]] = {}
        self._stats: dict[str, dict[str, Any]] = {}

    def decoded(self, kind: str) -> Decoded:
        if kind not in self._decoded:
            path = self.inputs[kind]
            proc = eg2scope("decode", str(path), "--format", "jsonl", "--engine", "python",
                            cwd=path.parent)  # fmt: skip
            assert proc.returncode == 0, proc.stderr.decode()
            self._decoded[kind] = Decoded.parse(proc.stdout)
        return self._decoded[kind]

    def samples(self, kind: str) -> list[StateSample]:
        if kind not in self._samples:
            self._samples[kind] = python_samples(self.inputs[kind])
        return self._samples[kind]

    def cycles(self, kind: str) -> list[dict[str, Any]]:
        if kind not in self._cycles:
            path = self.inputs[kind]
            proc = eg2scope("cycles", str(path), "--format", "jsonl", "--engine", "python",
                            cwd=path.parent)  # fmt: skip
            assert proc.returncode == 0, proc.stderr.decode()
            self._cycles[kind] = [orjson.loads(line) for line in proc.stdout.splitlines()]
        return self._cycles[kind]

    def stats(self, kind: str) -> dict[str, Any]:
        if kind not in self._stats:
            path = self.inputs[kind]
            proc = eg2scope("stats", str(path), "--format", "json", cwd=path.parent)
            assert proc.returncode in (0, 3), proc.stderr.decode()
            self._stats[kind] = orjson.loads(proc.stdout)
        return self._stats[kind]


@pytest.fixture(scope="session")
def reference(inputs: InputFolder) -> References:
    return References(inputs)
