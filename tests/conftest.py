"""Shared test set-up: helpers (``protocol_vectors``) importable from every test folder, and
one Hypothesis profile.

Property tests assert behaviour, not speed (speed lives in tests/benchmarks/): no per-example
deadline, so a loaded CI machine cannot turn a slow example into a failure.
"""

import sys
from pathlib import Path

from hypothesis import settings

sys.path.insert(0, str(Path(__file__).resolve().parent))

settings.register_profile("eg2scope", deadline=None, print_blob=True)
settings.load_profile("eg2scope")
