"""Shared fixtures: the real recordings in ../shared/realdata (skipped when absent)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REALDATA = Path(os.environ.get("ATSVO_REALDATA", ROOT.parent / "shared" / "realdata"))


@pytest.fixture(scope="session")
def realdata() -> Path:
    """Path of ../shared/realdata; skips the test when the folder is not there (a user's clone)."""
    if not REALDATA.is_dir():
        pytest.skip(f"real recordings not found at {REALDATA} (set ATSVO_REALDATA)")
    return REALDATA
