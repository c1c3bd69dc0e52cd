"""Shared fixtures: the real recordings in ../shared/realdata (skipped when absent), simulated trots."""
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


#: The 3 s synthetic trot (160x120 colour + depth, 80x60 events, IMU, ground truth) several modules replay.
TROT_3S_ARGS = ["--scenario", "trot", "--duration", "3", "--seed", "0", "--width", "160", "--height", "120",
                "--event-scale", "0.25", "--quiet"]


def simulate_bag(tmp_path_factory, name: str, args: list[str]) -> Path:
    """An atsvo-sim bag written with ``args`` into a fresh temporary folder (for module or session fixtures)."""
    from atsvo_ros.tools.sim import main as sim_main

    bag = tmp_path_factory.mktemp(name) / "bag"
    assert sim_main([*args, "--out", str(bag)]) == 0
    return bag


@pytest.fixture(scope="session")
def trot_3s_bag(tmp_path_factory) -> Path:
    """:data:`TROT_3S_ARGS` written once per session by atsvo-sim (~35 s on 2 cores)."""
    return simulate_bag(tmp_path_factory, "trot_3s", TROT_3S_ARGS)


#: The 1 s synthetic trot that the replay's end-to-end tests write in every container.
TROT_1S_ARGS = ["--scenario", "trot", "--duration", "1.0", "--seed", "0", "--width", "160", "--height", "120",
                "--event-scale", "0.25", "--quiet"]
BAG_FORMATS = ("ros1", "sqlite3", "mcap")


@pytest.fixture(scope="session")
def trot_1s_bags(tmp_path_factory) -> dict[str, Path]:
    """:data:`TROT_1S_ARGS` written once per session in each of :data:`BAG_FORMATS`: format -> the path readers take."""
    from atsvo_ros.tools.sim import main as sim_main

    root = tmp_path_factory.mktemp("trot_1s")
    bags = {}
    for fmt in BAG_FORMATS:
        assert sim_main([*TROT_1S_ARGS, "--out", str(root / fmt), "--format", fmt]) == 0
        bags[fmt] = root / fmt / "sequence.bag" if fmt == "ros1" else root / fmt
    return bags
