"""The fleet folder the batch tests decode: every kind of capture (tests/fleet_folder.py), the
mixed three-bus recording of ``eg2scope record --demo`` among them; made once per run."""

from __future__ import annotations

from pathlib import Path

import pytest
from fleet_folder import make_fleet


@pytest.fixture(scope="session")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return make_fleet(tmp_path_factory.mktemp("fleet"), frames=1500, demo=True)
