"""EventBatch: a struct-of-arrays container for DVS events (never one Python object per event)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from atsvo_ros.errors import DecodeError


@dataclass(frozen=True)
class EventBatch:
    """Events as parallel arrays: ``x``, ``y`` (uint16 px), ``t`` (int64 ns), ``p`` (uint8, ON = 1).

    ``width``/``height`` give the sensor size when known (0 = unknown). Batches are normally
    time-ordered; :meth:`is_sorted` checks it and decoders count what they had to drop.
    """

    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    p: np.ndarray
    width: int = 0
    height: int = 0

    def __post_init__(self) -> None:
        n = len(self.t)
        if not (len(self.x) == len(self.y) == len(self.p) == n):
            raise DecodeError(f"event arrays differ in length: x={len(self.x)} y={len(self.y)} "
                              f"t={n} p={len(self.p)}")
        object.__setattr__(self, "x", np.asarray(self.x, dtype=np.uint16))
        object.__setattr__(self, "y", np.asarray(self.y, dtype=np.uint16))
        object.__setattr__(self, "t", np.asarray(self.t, dtype=np.int64))
        object.__setattr__(self, "p", np.asarray(self.p, dtype=np.uint8))

    @classmethod
    def empty(cls, width: int = 0, height: int = 0) -> EventBatch:
        """A batch with no events."""
        z = np.zeros(0)
        return cls(z, z, z, z, width, height)

    @classmethod
    def concatenate(cls, batches: list[EventBatch]) -> EventBatch:
        """Join batches in the given order; sensor size taken from the first that knows it."""
        if not batches:
            return cls.empty()
        width = next((b.width for b in batches if b.width), 0)
        height = next((b.height for b in batches if b.height), 0)
        return cls(np.concatenate([b.x for b in batches]), np.concatenate([b.y for b in batches]),
                   np.concatenate([b.t for b in batches]), np.concatenate([b.p for b in batches]),
                   width, height)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def t_first_ns(self) -> int:
        return int(self.t[0]) if len(self.t) else 0

    @property
    def t_last_ns(self) -> int:
        return int(self.t[-1]) if len(self.t) else 0

    def is_sorted(self) -> bool:
        """True when timestamps never decrease."""
        return bool(len(self.t) < 2 or np.all(np.diff(self.t) >= 0))

    def select(self, mask: np.ndarray | slice) -> EventBatch:
        """Sub-batch by boolean mask, index array or slice."""
        return EventBatch(self.x[mask], self.y[mask], self.t[mask], self.p[mask], self.width, self.height)

    def shifted(self, dt_ns: int) -> EventBatch:
        """The same events ``dt_ns`` later (onto another clock)."""
        return EventBatch(self.x, self.y, self.t + np.int64(dt_ns), self.p, self.width, self.height)

    def time_slice(self, t_start_ns: int, t_end_ns: int) -> EventBatch:
        """Events with ``t_start_ns <= t < t_end_ns`` (binary search, so the batch must be sorted)."""
        i0, i1 = np.searchsorted(self.t, [t_start_ns, t_end_ns], side="left")
        return self.select(slice(int(i0), int(i1)))

    def in_bounds(self) -> np.ndarray:
        """Mask of events inside the sensor (all True when the size is unknown)."""
        if not (self.width and self.height):
            return np.ones(len(self), dtype=bool)
        return (self.x < self.width) & (self.y < self.height)


__all__ = ["EventBatch"]
