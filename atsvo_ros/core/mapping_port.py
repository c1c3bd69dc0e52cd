"""How tracking talks to mapping: in line (one thread, the replay), in a thread of its own, or elsewhere.

Tracking sends :class:`~atsvo_ros.core.mapper.KeyframeRequest` s and
:class:`~atsvo_ros.core.mapper.EventMapRequest` s and reads back immutable
:class:`~atsvo_ros.core.map.MapSnapshot` s and temporary event maps. :class:`InlineMapping` answers at
once (deterministic: what ``atsvo-replay`` runs); :class:`ThreadedMapping` runs the mapper in a worker
thread, so tracking keeps tracking against its last snapshot while a keyframe is inserted (the PTAM
split; ``synchronous=True`` makes it wait for each answer instead, which equals the inline results);
the ROS nodes add a port that exchanges the same requests over topics.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol

from atsvo_ros.core.map import MapSnapshot, TemporaryEventMap
from atsvo_ros.core.mapper import EventMapRequest, KeyframeRequest, Mapper


class MappingPort(Protocol):
    """The mapping side as tracking sees it."""

    @property
    def n_keyframes(self) -> int:
        """Keyframes mapping inserted so far."""
        ...

    def insert(self, request: KeyframeRequest, wait: bool = False) -> MapSnapshot | None:
        """Ask for a keyframe; the new snapshot if it is ready now (always with ``wait``), else None."""
        ...

    def event_map(self, request: EventMapRequest) -> TemporaryEventMap | None:
        """The temporary event map of a frame (None when mapping could not answer in time)."""
        ...

    def latest(self) -> MapSnapshot | None:
        """A snapshot newer than the last one handed out, or None."""
        ...

    def busy(self) -> bool:
        """A keyframe request is still being worked on (tracking sends no other meanwhile)."""
        ...

    def close(self) -> None:
        """Stop any worker."""
        ...


class InlineMapping:
    """Mapping in the caller's thread: every answer is immediate and deterministic."""

    def __init__(self, mapper: Mapper) -> None:
        self.mapper = mapper

    @property
    def n_keyframes(self) -> int:
        return self.mapper.n_keyframes

    def insert(self, request: KeyframeRequest, wait: bool = False) -> MapSnapshot | None:
        return self.mapper.insert(request)

    def event_map(self, request: EventMapRequest) -> TemporaryEventMap | None:
        return self.mapper.build_event_map(request)

    def latest(self) -> MapSnapshot | None:
        return None

    def busy(self) -> bool:
        return False

    def close(self) -> None:
        pass


class ThreadedMapping:
    """Mapping in a worker thread (one keyframe request at a time; event maps are built in the caller's).

    The temporary event map is needed by the very next frame and takes a millisecond or two, so it is
    built at once; keyframe insertion (selection, back-projection, patches on every level) runs beside
    tracking. ``on_snapshot`` (optional) is called from the worker with each new snapshot, e.g. to
    publish the map.
    """

    def __init__(self, mapper: Mapper, synchronous: bool = False,
                 on_snapshot: Callable[[MapSnapshot], None] | None = None) -> None:
        self.mapper = mapper
        self.synchronous = synchronous
        self._on_snapshot = on_snapshot
        self._lock = threading.Condition()
        self._pending: KeyframeRequest | None = None
        self._ready: MapSnapshot | None = None
        self._working = False
        self._stop = False
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="atsvo-mapping", daemon=True)
        self._thread.start()

    @property
    def n_keyframes(self) -> int:
        return self.mapper.n_keyframes

    def insert(self, request: KeyframeRequest, wait: bool = False) -> MapSnapshot | None:
        with self._lock:
            self._raise()
            self._pending = request
            self._lock.notify_all()
            if not (wait or self.synchronous or request.reset):
                return None
            while self._pending is not None or self._working:
                self._lock.wait()
                self._raise()
            ready, self._ready = self._ready, None
            return ready

    def event_map(self, request: EventMapRequest) -> TemporaryEventMap | None:
        return self.mapper.build_event_map(request)

    def latest(self) -> MapSnapshot | None:
        with self._lock:
            self._raise()
            ready, self._ready = self._ready, None
            return ready

    def busy(self) -> bool:
        with self._lock:
            return self._pending is not None or self._working

    def close(self) -> None:
        with self._lock:
            self._stop = True
            self._lock.notify_all()
        self._thread.join(timeout=5.0)

    def _raise(self) -> None:
        if self._error is not None:
            err, self._error = self._error, None
            raise err

    def _run(self) -> None:
        while True:
            with self._lock:
                while self._pending is None and not self._stop:
                    self._lock.wait()
                if self._stop:
                    return
                request, self._pending = self._pending, None
                self._working = True
            try:
                snap = self.mapper.insert(request)
            except BaseException as exc:  # handed to the tracking thread, which raises it
                with self._lock:
                    self._error = exc
                    self._working = False
                    self._lock.notify_all()
                continue
            if self._on_snapshot is not None:
                self._on_snapshot(snap)
            with self._lock:
                self._ready = snap
                self._working = False
                self._lock.notify_all()


__all__ = ["InlineMapping", "MappingPort", "ThreadedMapping"]
