"""What a replay keeps per frame and per ground-truth pose, packed so memory stays flat over a long bag.

A replay must hold the trajectory and the ground truth until the end (the evaluation aligns them as a
whole), but not the core's result objects: each carries three matrices, a dict and a dataclass
(~1.6 KiB), and a ground-truth sample kept as ``(int, 4x4 array)`` costs ~330 B at 100-200 Hz. Here a
frame costs ~200 B (pose, numbers, references to interned strings) and a ground-truth pose 136 B,
in arrays allocated a chunk at a time.
"""
from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from atsvo_ros.io.trajectory import Trajectory

#: the per-frame numbers kept (besides the pose and the strings)
_FIELDS = [("stamp_ns", np.int64), ("tracking_time_s", np.float64), ("n_points", np.int32),
           ("n_inliers", np.int32), ("inliers", np.int32, (6,)), ("keyframe", np.bool_), ("n_events", np.int64),
           ("event_map_time_s", np.float64)]


class _Growing:
    """A numpy array appended to one row at a time, in chunks of ``CHUNK`` rows (no copies, one chunk of slack)."""

    CHUNK = 2048

    def __init__(self, row_shape: tuple[int, ...], dtype: Any) -> None:
        self._row_shape, self._dtype = row_shape, dtype
        self._chunks: list[np.ndarray] = []
        self.n = 0

    def append(self, row: Any) -> None:
        k = self.n % self.CHUNK
        if k == 0:
            self._chunks.append(np.zeros((self.CHUNK, *self._row_shape), self._dtype))
        self._chunks[-1][k] = row
        self.n += 1

    def first(self) -> Any:
        """Row 0 (IndexError when empty)."""
        if not self.n:
            raise IndexError("no rows yet")
        return self._chunks[0][0]

    @property
    def values(self) -> np.ndarray:
        """All rows (a new array)."""
        if not self._chunks:
            return np.zeros((0, *self._row_shape), self._dtype)
        return np.concatenate(self._chunks)[:self.n]


class PoseLog:
    """Ground-truth samples ``(stamp_ns, T_w_b)`` as the sources append them; a list's ``append``/``extend``."""

    def __init__(self) -> None:
        self._stamps: _Growing | None = _Growing((), np.int64)
        self._poses: _Growing | None = _Growing((4, 4), np.float64)
        self._done: Trajectory | None = None

    def append(self, sample: tuple[int, np.ndarray]) -> None:
        if self._done is not None:
            raise ValueError("the ground truth was already handed out as a trajectory")
        self._stamps.append(int(sample[0]))
        self._poses.append(sample[1])

    def extend(self, samples: Iterable[tuple[int, np.ndarray]]) -> None:
        for s in samples:
            self.append(s)

    def __len__(self) -> int:
        return self._stamps.n if self._done is None else len(self._done.stamps_ns)

    def trajectory(self) -> Trajectory:
        """The samples as a time-sorted trajectory without repeated stamps (built once; the chunks are then
        freed, so the end of a long run holds one copy of the ground truth, not three)."""
        if self._done is None:
            self._done = Trajectory(self._stamps.values, self._poses.values).sorted_unique()
            self._stamps = self._poses = None
        return self._done


class FrameLog:
    """The replay's per-frame record: pose in the chosen frame, status, timing and counts."""

    def __init__(self, frame: str) -> None:
        self.frame = frame
        self._nums = _Growing((), np.dtype(_FIELDS))
        self._poses = _Growing((4, 4), np.float64)
        self.statuses: list[str] = []
        self.modes: list[str] = []
        self.reasons: list[str | None] = []
        self._inlier_keys: list[tuple[str, ...]] = []  # one shared tuple per distinct set of residual blocks
        self._key_sets: dict[tuple[str, ...], tuple[str, ...]] = {}

    def append(self, output: Any) -> None:
        """Keep what the outputs need of one :class:`~atsvo_ros.runtime.types.RuntimeOutput`."""
        r = output.result
        keys = tuple(r.inliers)
        keys = self._key_sets.setdefault(keys, keys)
        counts = np.zeros(6, np.int32)
        counts[:len(keys)] = [r.inliers[k] for k in keys]
        self._nums.append((r.stamp_ns, r.tracking_time_s, r.n_points, r.n_inliers, counts, r.keyframe_inserted,
                           output.n_events, r.event_map_time_s))
        self._inlier_keys.append(keys)
        self._poses.append(r.T_odom_base if self.frame == "base" else r.T_odom_camera)
        self.statuses.append(r.status.value)
        self.modes.append(r.mode)
        self.reasons.append(r.reason)

    def __len__(self) -> int:
        return self._nums.n

    @property
    def first_stamp_ns(self) -> int:
        """The first frame's stamp (cheap: for a progress bar's rate)."""
        return int(self._nums.first()["stamp_ns"])

    def __getitem__(self, name: str) -> np.ndarray:
        """One numeric column (a name of ``_FIELDS``), as a new array."""
        return self._nums.values[name].copy()

    @property
    def poses(self) -> np.ndarray:
        return self._poses.values

    def frames_info(self) -> list[dict[str, Any]]:
        """Per-frame dicts for timing.json."""
        return list(self.iter_frames_info())

    def iter_frames_info(self) -> Iterator[dict[str, Any]]:
        """:meth:`frames_info` one frame at a time."""
        v = self._nums.values
        yield from ({"stamp_ns": int(x["stamp_ns"]), "tracking_time_s": float(x["tracking_time_s"]), "mode": mode,
                 "status": status, "reason": reason, "n_points": int(x["n_points"]), "n_inliers": int(x["n_inliers"]),
                 "inliers": {k: int(c) for k, c in zip(keys, x["inliers"])},
                 "keyframe": bool(x["keyframe"]), "n_events": int(x["n_events"]),
                 "event_map_time_s": float(x["event_map_time_s"])}
                for x, mode, status, reason, keys in zip(v, self.modes, self.statuses, self.reasons,
                                                         self._inlier_keys))

    def write_json(self, path: Path, doc: dict[str, Any], key: str) -> None:
        """``doc`` as JSON with the per-frame dicts under ``key``, written a frame at a time (a long bag's
        frames as one list of dicts and one string cost tens of MiB at the end of the run)."""
        head = json.dumps(doc, indent=1)
        with open(path, "w") as f:
            f.write(head[:-2] if doc else "{")  # drop the closing "\n}"
            f.write(f',\n "{key}": [' if doc else f'\n "{key}": [')
            for i, frame in enumerate(self.iter_frames_info()):
                f.write(("\n  " if i == 0 else ",\n  ") + json.dumps(frame))
            f.write("\n ]\n}\n")


__all__ = ["FrameLog", "PoseLog"]
