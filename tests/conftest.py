"""Shared test setup: the test-only domain ``relay_v0`` (``tests/toy_relay``) is importable."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
