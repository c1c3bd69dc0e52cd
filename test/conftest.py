"""Shared fixtures: the real recordings in ../shared/realdata (skipped when absent), simulated trots."""
from __future__ import annotations

import fcntl
import os
import shutil
from collections.abc import Callable
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


def made_once(tmp_path_factory, name: str, make: Callable[[Path], None]) -> Path:
    """A folder ``make`` fills once per test run, whatever the number of pytest-xdist workers.

    Under xdist every worker has its own session, so a session fixture would run once per worker; the folder goes
    into the run's temporary root that the workers share instead, and the first worker to take the lock makes it
    while the others wait for it.
    """
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    folder = root / f"once_{name}"
    with open(root / f"once_{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / ".made").is_file():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            make(folder)
            (folder / ".made").touch()
    return folder


@pytest.fixture(scope="session")
def trot_3s_bag(tmp_path_factory) -> Path:
    """:data:`TROT_3S_ARGS` written once per test run by atsvo-sim (~35-60 s on 2 cores)."""
    from atsvo_ros.tools.sim import main as sim_main

    def make(folder: Path) -> None:
        assert sim_main([*TROT_3S_ARGS, "--out", str(folder / "bag")]) == 0

    return made_once(tmp_path_factory, "trot_3s", make) / "bag"


#: The 1 s synthetic trot that the replay's end-to-end tests write in every container.
TROT_1S_ARGS = ["--scenario", "trot", "--duration", "1.0", "--seed", "0", "--width", "160", "--height", "120",
                "--event-scale", "0.25", "--quiet"]
BAG_FORMATS = ("ros1", "sqlite3", "mcap")


def _simulated_once(iter_sequence):
    """``iter_sequence`` that simulates each spec once and hands the same items (and stats) to every later call."""
    done: dict[str, tuple[list, dict]] = {}

    def again(spec, scene=None, stats=None):
        key = repr(spec)
        if key not in done:
            first: dict = {}
            done[key] = (list(iter_sequence(spec, scene, stats=first)), first)
        items, first = done[key]
        if stats is not None:
            stats.update(first)
        yield from items

    return again


@pytest.fixture(scope="session")
def trot_1s_bags(tmp_path_factory) -> dict[str, Path]:
    """:data:`TROT_1S_ARGS` written once per test run in each of :data:`BAG_FORMATS`: format -> the path readers take.

    atsvo-sim simulates the sequence once and writes that one simulation into the three containers (the simulator's
    determinism per seed is tested in test/sim/test_sequence.py; here the containers are what is compared).
    """
    from atsvo_ros.sim import writer
    from atsvo_ros.tools.sim import main as sim_main

    def make(root: Path) -> None:
        mp = pytest.MonkeyPatch()
        mp.setattr(writer, "iter_sequence", _simulated_once(writer.iter_sequence))
        try:
            for fmt in BAG_FORMATS:
                assert sim_main([*TROT_1S_ARGS, "--out", str(root / fmt), "--format", fmt]) == 0
        finally:
            mp.undo()

    root = made_once(tmp_path_factory, "trot_1s", make)
    return {fmt: root / fmt / "sequence.bag" if fmt == "ros1" else root / fmt for fmt in BAG_FORMATS}
