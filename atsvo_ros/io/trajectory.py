"""Trajectories: stamped poses in memory and the TUM text format (``t tx ty tz qx qy qz qw``)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from atsvo_ros.core.geometry import pose_from_tq, tq_from_pose
from atsvo_ros.errors import TrajectoryError


@dataclass(frozen=True)
class Trajectory:
    """Poses ``T_w_b`` (N, 4, 4) at strictly increasing int64 nanosecond ``stamps_ns`` (N,)."""

    stamps_ns: np.ndarray
    T_w_b: np.ndarray

    def __post_init__(self) -> None:
        stamps = np.asarray(self.stamps_ns, dtype=np.int64).reshape(-1)
        poses = np.asarray(self.T_w_b, dtype=np.float64).reshape(-1, 4, 4)
        if len(stamps) != len(poses):
            raise TrajectoryError(f"{len(stamps)} stamps but {len(poses)} poses")
        if not np.all(np.isfinite(poses)):
            raise TrajectoryError("trajectory contains NaN or inf poses")
        object.__setattr__(self, "stamps_ns", stamps)
        object.__setattr__(self, "T_w_b", poses)

    def __len__(self) -> int:
        return len(self.stamps_ns)

    @property
    def positions_m(self) -> np.ndarray:
        return self.T_w_b[:, :3, 3]

    @property
    def duration_s(self) -> float:
        return float(self.stamps_ns[-1] - self.stamps_ns[0]) * 1e-9 if len(self) else 0.0

    def sorted_unique(self) -> Trajectory:
        """Sorted by time with duplicate stamps removed (the first pose of each stamp kept)."""
        order = np.argsort(self.stamps_ns, kind="stable")
        s = self.stamps_ns[order]
        keep = np.concatenate([[True], np.diff(s) > 0]) if len(s) else np.zeros(0, bool)
        return Trajectory(s[keep], self.T_w_b[order][keep])

    def transformed(self, T_left: np.ndarray | None = None, T_right: np.ndarray | None = None) -> Trajectory:
        """``T_left @ T_w_b @ T_right`` for every pose (change of world frame / of body frame)."""
        P = self.T_w_b
        if T_left is not None:
            P = np.asarray(T_left) @ P
        if T_right is not None:
            P = P @ np.asarray(T_right)
        return Trajectory(self.stamps_ns, P)


def _seconds_to_ns(text: str) -> int:
    """Exact conversion of a decimal seconds string to int64 ns (no float round-off)."""
    whole, _, frac = text.strip().partition(".")
    if whole.startswith("-"):
        return -_seconds_to_ns(text.strip()[1:])
    frac = (frac + "000000000")[:9]
    return int(whole or "0") * 1_000_000_000 + int(frac)


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM file; comments (#) and blank lines are skipped, stamps parsed exactly."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise TrajectoryError(f"cannot read trajectory {path}: {exc.strerror or exc}") from None
    stamps, values = [], []
    for lineno, line in enumerate(lines, 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.replace(",", " ").split()
        if len(parts) != 8:
            raise TrajectoryError(f"{path}:{lineno}: expected 8 columns (t tx ty tz qx qy qz qw), got {len(parts)}")
        try:
            stamps.append(_seconds_to_ns(parts[0]) if "e" not in parts[0].lower()
                          else int(round(float(parts[0]) * 1e9)))
            values.append([float(v) for v in parts[1:]])
        except ValueError:
            raise TrajectoryError(f"{path}:{lineno}: not a number in {line!r}") from None
    if not stamps:
        raise TrajectoryError(f"{path} holds no poses")
    v = np.asarray(values)
    if np.any(np.linalg.norm(v[:, 3:], axis=1) < 1e-9):
        raise TrajectoryError(f"{path}: a quaternion has zero norm")
    return Trajectory(np.asarray(stamps, dtype=np.int64), pose_from_tq(v[:, :3], v[:, 3:]))


def format_stamp(stamp_ns: int) -> str:
    """Seconds with 9 decimals from int64 ns, exact."""
    sign = "-" if stamp_ns < 0 else ""
    s, ns = divmod(abs(int(stamp_ns)), 1_000_000_000)
    return f"{sign}{s}.{ns:09d}"


def write_tum(path: str | Path, traj: Trajectory, header: str | None = None) -> None:
    """Write a TUM file (stamps with ns precision, 9 significant decimals for poses)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    t, q = tq_from_pose(traj.T_w_b)
    with path.open("w") as f:
        if header:
            for line in header.splitlines():
                f.write(f"# {line}\n")
        for s, tt, qq in zip(traj.stamps_ns, t, q):
            f.write(f"{format_stamp(s)} {tt[0]:.9f} {tt[1]:.9f} {tt[2]:.9f} "
                    f"{qq[0]:.9f} {qq[1]:.9f} {qq[2]:.9f} {qq[3]:.9f}\n")
