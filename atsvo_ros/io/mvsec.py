"""MVSEC HDF5 files (``*_data.hdf5`` and ``*_gt.hdf5``) -> the replay's time-ordered stream.

Layout (per camera, ``davis/left`` by default): ``events`` (N, 4) float64 rows ``[x, y, t_s, p]``
with p in {-1, 1}; ``image_raw`` (N, H, W) uint8 with ``image_raw_ts`` (s); in the gt file
``depth_image_raw`` (N, H, W) float32 metres (NaN = no depth) with ``depth_image_raw_ts`` and
``pose`` (N, 4, 4) with ``pose_ts``. Datasets are read in slices (h5py), so memory does not
depend on the sequence length. Needs the ``mvsec`` extra (h5py).
"""
from __future__ import annotations

import heapq
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import BagError
from atsvo_ros.io.trajectory import Trajectory


@dataclass(frozen=True)
class MvsecItem:
    """One element of the stream: ``role`` rgb / depth (``data`` an image) or events (an EventBatch)."""

    role: str
    stamp_ns: int
    data: Any


def _ns(t_s: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(t_s, dtype=np.float64) * 1e9).astype(np.int64)


class MvsecReader:
    """Reader over one or two MVSEC files (data and ground truth); use as a context manager.

    Args:
        data_path: ``*_data.hdf5`` (events, grey images); may also hold depth and pose.
        gt_path: ``*_gt.hdf5`` (depth, pose); optional.
        camera: ``left`` or ``right``.
        events_per_chunk: events read per slice.
    """

    def __init__(self, data_path: str | Path, gt_path: str | Path | None = None, camera: str = "left",
                 events_per_chunk: int = 200_000) -> None:
        try:
            import h5py
        except ImportError as exc:
            raise BagError("reading MVSEC HDF5 needs h5py: pip install 'atsvo_ros[mvsec]'") from exc
        self.files = []
        for p in (data_path, gt_path):
            if p is None:
                continue
            if not Path(p).is_file():
                raise BagError(f"MVSEC file {p} does not exist")
            try:
                self.files.append(h5py.File(p, "r"))
            except OSError as exc:
                raise BagError(f"cannot open MVSEC file {p}: {exc}") from None
        self.prefix = f"davis/{camera}"
        self.chunk = int(events_per_chunk)
        self.width = self.height = 0
        img = self._get("image_raw")
        if img is not None:
            self.height, self.width = int(img.shape[1]), int(img.shape[2])

    def _read(self, ds: Any, sel: Any = slice(None)) -> np.ndarray:
        """``ds[sel]`` as an array; BagError naming the file and dataset when HDF5 cannot read it."""
        try:
            return np.asarray(ds[sel])
        except (OSError, ValueError, KeyError) as exc:  # h5py's errors for damaged chunks / metadata
            raise BagError(f"MVSEC file {ds.file.filename}: cannot read {ds.name}: "
                           f"{type(exc).__name__}: {' '.join(str(exc).split())}") from None

    def _get(self, name: str) -> Any:
        key = f"{self.prefix}/{name}"
        for f in self.files:
            try:
                if key in f:
                    return f[key]
            except (OSError, ValueError, KeyError) as exc:  # damaged HDF5 metadata
                raise BagError(f"MVSEC file {f.filename}: cannot read {key}: {type(exc).__name__}: "
                               f"{' '.join(str(exc).split())}") from None
        return None

    def __enter__(self) -> MvsecReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        for f in self.files:
            f.close()
        self.files = []

    def has(self, role: str) -> bool:
        """Whether the files hold ``rgb``, ``depth``, ``events`` or ``ground_truth``."""
        name = {"rgb": "image_raw", "depth": "depth_image_raw", "events": "events", "ground_truth": "pose"}[role]
        return self._get(name) is not None

    def ground_truth(self):
        """The ``pose`` dataset as a :class:`~atsvo_ros.io.trajectory.Trajectory` (camera in world)."""

        pose, ts = self._get("pose"), self._get("pose_ts")
        if pose is None or ts is None:
            raise BagError(f"no {self.prefix}/pose (+ pose_ts) in the MVSEC files")
        return Trajectory(_ns(self._read(ts)), self._read(pose).astype(np.float64)).sorted_unique()

    # ------------------------------------------------------------------ streaming
    def _images(self, name: str, role: str) -> Iterator[MvsecItem]:
        data, ts = self._get(name), self._get(f"{name}_ts")
        if data is None:
            return
        if ts is None or len(ts) != len(data):
            raise BagError(f"{self.prefix}/{name} needs a matching {name}_ts dataset")
        stamps = _ns(self._read(ts))
        for i in range(len(data)):
            yield MvsecItem(role, int(stamps[i]), self._read(data, i))

    def _events(self) -> Iterator[MvsecItem]:
        ev = self._get("events")
        if ev is None:
            return
        if ev.ndim != 2 or ev.shape[1] != 4:
            raise BagError(f"{self.prefix}/events must be (N, 4) [x, y, t, p], got shape {ev.shape}")
        for i0 in range(0, len(ev), self.chunk):
            a = self._read(ev, slice(i0, i0 + self.chunk)).astype(np.float64)
            b = EventBatch(a[:, 0].astype(np.uint16), a[:, 1].astype(np.uint16), _ns(a[:, 2]),
                           (a[:, 3] > 0).astype(np.uint8), self.width, self.height)
            yield MvsecItem("events", b.t_first_ns, b)

    def stream(self, roles: tuple[str, ...] = ("rgb", "depth", "events")) -> Iterator[MvsecItem]:
        """Images, depth maps and event slices merged in time order."""
        sources = []
        if "rgb" in roles:
            sources.append(self._images("image_raw", "rgb"))
        if "depth" in roles:
            sources.append(self._images("depth_image_raw", "depth"))
        if "events" in roles:
            sources.append(self._events())
        yield from heapq.merge(*sources, key=lambda item: item.stamp_ns)


__all__ = ["MvsecItem", "MvsecReader"]
