"""How tracking talks to mapping: in line (one thread, the replay), in a thread of its own, or elsewhere.

Tracking sends :class:`~atsvo_ros.core.mapping.mapper.KeyframeRequest` s and
:class:`~atsvo_ros.core.mapping.mapper.EventMapRequest` s and reads back immutable
:class:`~atsvo_ros.core.mapping.map.MapSnapshot` s and temporary event maps. :class:`InlineMapping` answers at
once (deterministic: what ``atsvo-replay`` runs); :class:`ThreadedMapping` runs the mapper in a worker
thread, so tracking keeps tracking against its last snapshot while a keyframe is inserted (the PTAM
split; ``synchronous=True`` makes it wait for each answer instead, which equals the inline results);
the ROS nodes add a port that exchanges the same requests over topics.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Protocol

from atsvo_ros.core.events.event_map import TemporaryEventMap
from atsvo_ros.core.mapping.map import MapSnapshot
from atsvo_ros.core.mapping.mapper import EventMapRequest, KeyframeRequest, Mapper


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
        """The temporary event map of a frame (None when mapping could not answer in time).

        For the request last given to :meth:`prepare_event_map` this is the map built meanwhile.
        """
        ...

    def prepare_event_map(self, request: EventMapRequest) -> None:
        """Start building the event map the next frame will probably ask for (after this frame's pose is out)."""
        ...

    def latest(self) -> MapSnapshot | None:
        """A snapshot newer than the last one handed out, or None."""
        ...

    def busy(self) -> bool:
        """A keyframe request is still being worked on (tracking sends no other meanwhile)."""
        ...

    def await_pending(self) -> MapSnapshot | None:
        """Wait for the keyframe request in progress: its snapshot (None when none is ready or it timed out).

        Tracking calls it when a frame fails against a map that mapping is still extending: the camera has
        outrun the map, and waiting for the keyframe beats relocalising against the old one.
        """
        ...

    def close(self) -> None:
        """Stop any worker."""
        ...


class EventMapBuilder:
    """Builds temporary event maps now or ahead of time, in line or on a helper thread.

    The next frame needs the event map of the frame just tracked (when the motion is fast). Tracking
    asks for it as soon as that frame's pose is out (:meth:`prepare`), so the build (event pixel
    selection, z-buffered depth, patches) overlaps the wait for the next frame instead of adding to
    its latency; :meth:`get` with the same request returns it (waiting if it is not done yet), any
    other request is built at once. ``background=False`` builds in the caller's thread at
    :meth:`prepare` (the replay: same maps, same order, one thread).
    """

    def __init__(self, mapper: Mapper, background: bool) -> None:
        self.mapper = mapper
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="atsvo-event-map") if background else None
        self._ahead: tuple[EventMapRequest, Future | TemporaryEventMap] | None = None

    def prepare(self, request: EventMapRequest) -> None:
        if self._pool is None:
            self._ahead = (request, self.mapper.build_event_map(request))
        else:
            self._ahead = (request, self._pool.submit(self.mapper.build_event_map, request))

    def get(self, request: EventMapRequest) -> TemporaryEventMap:
        ahead, self._ahead = self._ahead, None
        if ahead is None or ahead[0] is not request:
            return self.mapper.build_event_map(request)
        return ahead[1].result() if isinstance(ahead[1], Future) else ahead[1]

    def close(self) -> None:
        self._ahead = None
        if self._pool is not None:
            self._pool.shutdown(wait=True)


class EventMapsAhead:
    """The event-map half of :class:`MappingPort`, for ports that hold an :class:`EventMapBuilder`."""

    _event_maps: EventMapBuilder

    def event_map(self, request: EventMapRequest) -> TemporaryEventMap | None:
        return self._event_maps.get(request)

    def prepare_event_map(self, request: EventMapRequest) -> None:
        self._event_maps.prepare(request)


class InlineMapping(EventMapsAhead):
    """Mapping in the caller's thread: every answer is immediate and deterministic."""

    def __init__(self, mapper: Mapper) -> None:
        self.mapper = mapper
        self._event_maps = EventMapBuilder(mapper, background=False)

    @property
    def n_keyframes(self) -> int:
        return self.mapper.n_keyframes

    def insert(self, request: KeyframeRequest, wait: bool = False) -> MapSnapshot | None:
        return self.mapper.insert(request)

    def latest(self) -> MapSnapshot | None:
        return None

    def busy(self) -> bool:
        return False

    def await_pending(self) -> MapSnapshot | None:
        return None

    def close(self) -> None:
        self._event_maps.close()


class ThreadedMapping(EventMapsAhead):
    """Mapping in worker threads: keyframe insertion (one request at a time) and event maps.

    Keyframe insertion (selection, back-projection, patches on every level) runs beside tracking; the
    temporary event map, needed by the very next frame, is built on a second thread while tracking
    waits for that frame (:class:`EventMapBuilder`). ``on_snapshot`` (optional) is called from the
    worker with each new snapshot, e.g. to publish the map.
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
        self._event_maps = EventMapBuilder(mapper, background=True)
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
            return self.await_pending()

    def latest(self) -> MapSnapshot | None:
        with self._lock:
            self._raise()
            ready, self._ready = self._ready, None
            return ready

    def busy(self) -> bool:
        with self._lock:
            return self._pending is not None or self._working

    def await_pending(self) -> MapSnapshot | None:
        with self._lock:
            while self._pending is not None or self._working:
                self._lock.wait()
                self._raise()
            ready, self._ready = self._ready, None
            return ready

    def close(self) -> None:
        with self._lock:
            self._stop = True
            self._lock.notify_all()
        self._thread.join(timeout=5.0)
        self._event_maps.close()

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


__all__ = ["EventMapBuilder", "EventMapsAhead", "InlineMapping", "MappingPort", "ThreadedMapping"]
