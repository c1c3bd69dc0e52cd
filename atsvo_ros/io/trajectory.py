"""Trajectories: stamped poses in memory and the TUM text format (``t tx ty tz qx qy qz qw``)."""
from __future__ import annotations

import codecs
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


_INT64_MAX = (1 << 63) - 1


def _seconds_to_ns(text: str) -> int:
    """Exact conversion of a decimal seconds string to int64 ns (no float round-off).

    Raises ValueError for anything but a finite number of seconds that fits int64 nanoseconds.
    """
    text = text.strip()
    if "e" in text.lower():  # exponent notation: float, then checked
        value = float(text)
        if not np.isfinite(value):
            raise ValueError(f"stamp {text!r} is not finite")
        ns = int(round(value * 1e9))
    else:
        negative = text.startswith("-")
        whole, _, frac = text.lstrip("+-").partition(".")
        if not (whole or frac) or not (whole or "0").isdigit() or not (frac or "0").isdigit():
            raise ValueError(f"stamp {text!r} is not a number of seconds")
        ns = int(whole or "0") * 1_000_000_000 + int((frac + "000000000")[:9])
        ns = -ns if negative else ns
    if not -_INT64_MAX <= ns <= _INT64_MAX:
        raise ValueError(f"stamp {text!r} s does not fit int64 nanoseconds")
    return ns


STAMP_ORDERS = ("any", "nondecreasing", "increasing")


def read_tum(path: str | Path, *, order: str = "any") -> Trajectory:
    """Read a TUM file; comments (#) and blank lines are skipped, stamps parsed exactly.

    Every problem raises :class:`TrajectoryError` naming ``file:line``: a wrong column count, a
    value that is not a number, NaN/inf, a zero-norm quaternion, text that is not UTF-8.
    Quaternions are normalised (files often carry slightly non-unit ones). A UTF-8 byte-order
    mark (Windows editors write one) is skipped.

    Args:
        path: the file.
        order: what the stamps must do from line to line, checked here because only here the
            line is known. ``any`` (lines as in the file; the caller sorts), ``nondecreasing``
            (never back in time; a repeated stamp is allowed: motion-capture ground truth
            repeats a sample now and then, e.g. TUM fr2/desk's line 10863) or ``increasing``
            (strictly: an estimate with a repeated stamp would be matched twice and halve its
            RPE). A file that goes back in time is a concatenation or a clock reset, which
            sorting would interleave silently, so it is an error, not sorted.

    Raises:
        TrajectoryError: as above, and for a stamp that breaks ``order`` (naming both lines).
    """
    if order not in STAMP_ORDERS:
        raise TrajectoryError(f"unknown stamp order {order!r} (choose one of {', '.join(STAMP_ORDERS)})")
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise TrajectoryError(f"cannot read trajectory {path}: {exc.strerror or exc}") from None
    bom = len(codecs.BOM_UTF8) if data.startswith(codecs.BOM_UTF8) else 0
    try:
        text = data[bom:].decode("utf-8")
    except UnicodeDecodeError as exc:
        at = exc.start + bom
        line = data.count(b"\n", 0, at) + 1
        raise TrajectoryError(f"{path}:{line}: not UTF-8 text (byte 0x{data[at]:02x} at offset "
                              f"{at}); expected a TUM trajectory 't tx ty tz qx qy qz qw'") from None
    stamps, values = [], []
    prev_line = 0
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.replace(",", " ").split()
        if len(parts) != 8:
            raise TrajectoryError(f"{path}:{lineno}: expected 8 columns (t tx ty tz qx qy qz qw), got {len(parts)}")
        try:
            stamp = _seconds_to_ns(parts[0])
            v = [float(x) for x in parts[1:]]
        except ValueError as exc:
            raise TrajectoryError(f"{path}:{lineno}: not a number in {line!r} ({exc})") from None
        bad = [name for name, x in zip(("tx", "ty", "tz", "qx", "qy", "qz", "qw"), v) if not np.isfinite(x)]
        if bad:
            raise TrajectoryError(f"{path}:{lineno}: {', '.join(bad)} not finite in {line!r}")
        if float(np.linalg.norm(v[3:])) < 1e-9:
            raise TrajectoryError(f"{path}:{lineno}: the quaternion (qx qy qz qw) has zero norm in {line!r}")
        if order != "any" and stamps and (stamp < stamps[-1] or (stamp == stamps[-1] and order == "increasing")):
            what = "repeats the stamp of" if stamp == stamps[-1] else "goes back in time from"
            raise TrajectoryError(f"{path}:{lineno}: stamp {format_stamp(stamp)} {what} line {prev_line} "
                                  f"({format_stamp(stamps[-1])}); the stamps of a trajectory must "
                                  f"{'increase' if order == 'increasing' else 'not decrease'} line by line")
        stamps.append(stamp)
        values.append(v)
        prev_line = lineno
    if not stamps:
        raise TrajectoryError(f"{path} holds no poses")
    v = np.asarray(values)
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


__all__ = ["STAMP_ORDERS", "Trajectory", "format_stamp", "read_tum", "write_tum"]
