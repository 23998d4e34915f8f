"""Fixtures of the end-to-end matrix: every input kind made once per test session
(``e2e_inputs``), and each one's reference decode (``decode --format jsonl --engine python``, a
real process) and reference state samples (a Python-engine session), which every cell is
compared with."""

from __future__ import annotations

import os

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


@pytest.fixture(scope="session")
def reference(inputs: InputFolder) -> References:
    return References(inputs)
