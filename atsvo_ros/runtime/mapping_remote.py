"""Tracking and mapping in two processes: the mapping port that sends requests as bytes, and the server side.

:class:`RemoteMapping` is the :class:`~atsvo_ros.core.mapping.ports.MappingPort` of a tracking process
whose mapper runs elsewhere: keyframe requests leave through ``send`` (the tracking node publishes the
bytes), snapshots come back through :meth:`RemoteMapping.on_message` (its subscription). The
temporary event map is built in the tracking process: the very next frame needs it, it takes about
a millisecond, and a round trip through another process would add the transport to every fast frame.
:class:`MappingServer` is the mapping process's side: one :class:`~atsvo_ros.core.mapping.mapper.Mapper` per
tracking session, requests in, encoded snapshots out. Both are ROS-free (atsvo_ros.nodes wires them
to topics); the bytes are the format of :mod:`atsvo_ros.io.wire`.
"""
from __future__ import annotations

import hashlib
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass

from atsvo_ros.config import AtsvoConfig, flatten
from atsvo_ros.core.mapping.map import MapSnapshot
from atsvo_ros.core.mapping.mapper import KeyframeRequest, Mapper
from atsvo_ros.core.mapping.ports import EventMapBuilder, EventMapsAhead
from atsvo_ros.core.tracking.window import window_refiner
from atsvo_ros.io.wire import (
    PinholeLevels,
    decode_keyframe_request,
    decode_map_snapshot,
    encode_keyframe_request,
    encode_map_snapshot,
)

Logger = Callable[[str, str], None]  # (level, text)


def _no_log(level: str, text: str) -> None:
    del level, text


def mapping_digest(config: AtsvoConfig) -> str:
    """A short hash of the settings the mapper reads (mapping, selection, rig): both processes must agree."""
    keys = sorted(k for k in flatten(config) if k.split(".")[0] in ("mapping", "rgb_selection", "rig")
                  and k != "mapping.synchronous")
    flat = flatten(config)
    return hashlib.sha256(repr([(k, flat[k]) for k in keys]).encode()).hexdigest()[:12]


class RemoteMapping(EventMapsAhead):
    """A mapping port whose mapper is in another process (see the module docstring).

    One instance per odometry core, with its own session id: answers to another session's requests
    (a previous core, another tracking process) are ignored. ``connected()`` says whether a mapper
    listens; without one, requests are not sent (counted as ``unavailable``) and tracking reports no map.
    A request unanswered after ``timeout_s`` is given up (counted in ``timeouts``).
    """

    def __init__(self, mapper: Mapper, send: Callable[[bytes], None], connected: Callable[[], bool], *,
                 synchronous: bool = False, timeout_s: float = 5.0, config_digest: str = "",
                 logger: Logger | None = None) -> None:
        self.mapper = mapper  # builds the event maps here (on a helper thread); its own map stays empty
        self._event_maps = EventMapBuilder(mapper, background=True)
        self.session = uuid.uuid4().hex[:12]
        self.synchronous = bool(synchronous)
        self.timeout_s = float(timeout_s)
        self._send = send
        self._connected = connected
        self._digest = config_digest
        self._log = logger or _no_log
        c = mapper.camera
        self._camera = PinholeLevels(int(c.width), int(c.height), float(c.fx), float(c.fy), float(c.cx), float(c.cy),
                                     int(mapper.n_levels))
        self._cond = threading.Condition()
        self._seq = 0
        self._pending: tuple[int, float] | None = None  # (seq, monotonic time sent)
        self._ready: MapSnapshot | None = None
        self._answered = 0
        self._n_keyframes = 0
        self._closed = False
        #: requests sent, answers used, requests not sent (no mapper), requests given up, foreign answers
        self.stats = {"sent": 0, "answers": 0, "unavailable": 0, "timeouts": 0, "ignored": 0}
        self.last_round_trip_s: float | None = None

    # ------------------------------------------------------------------ MappingPort
    @property
    def n_keyframes(self) -> int:
        return self._n_keyframes

    def insert(self, request: KeyframeRequest, wait: bool = False) -> MapSnapshot | None:
        if not self._connected():
            self.stats["unavailable"] += 1
            if self.stats["unavailable"] == 1:
                self._log("warn", "no mapping node is listening: no keyframe can be inserted (start mapping_node, "
                                  "or run atsvo_node)")
            return None
        with self._cond:
            self._seq += 1
            seq = self._seq
            self._pending = (seq, time.monotonic())
        self._send(encode_keyframe_request(self.session, seq, request, self._camera, self._digest))
        self.stats["sent"] += 1
        if not (wait or self.synchronous or request.reset):
            return None
        return self.await_pending()

    def latest(self) -> MapSnapshot | None:
        with self._cond:
            ready, self._ready = self._ready, None
            return ready

    def busy(self) -> bool:
        with self._cond:
            if self._pending is None:
                return False
            seq, sent = self._pending
            if time.monotonic() - sent > self.timeout_s:
                self._give_up(seq)
                return False
            return True

    def await_pending(self) -> MapSnapshot | None:
        with self._cond:
            while self._pending is not None and not self._closed:
                seq, sent = self._pending
                left = sent + self.timeout_s - time.monotonic()
                if left <= 0:
                    self._give_up(seq)
                    break
                self._cond.wait(left)
            ready, self._ready = self._ready, None
            return ready

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._event_maps.close()

    # ------------------------------------------------------------------ answers
    def on_message(self, payload: bytes | bytearray | memoryview) -> bool:
        """An encoded snapshot from the mapper (any session); True when it answered this port's request.

        Raises :class:`~atsvo_ros.errors.WireError` for bytes that are not a snapshot.
        """
        ans = decode_map_snapshot(payload)
        with self._cond:
            if ans.session != self.session or ans.seq <= self._answered:
                self.stats["ignored"] += 1
                return False
            self._answered = ans.seq
            self._ready = ans.snapshot
            self._n_keyframes = ans.n_keyframes
            if self._pending is not None and self._pending[0] <= ans.seq:
                self.last_round_trip_s = time.monotonic() - self._pending[1]
                self._pending = None
            self.stats["answers"] += 1
            self._cond.notify_all()
            return True

    def _give_up(self, seq: int) -> None:
        """Called with the lock held: request ``seq`` is not waited for any more."""
        if self._pending is not None and self._pending[0] == seq:
            self._pending = None
            self.stats["timeouts"] += 1
            self._log("warn", f"mapping did not answer keyframe request {seq} within {self.timeout_s:g} s: "
                              "tracking goes on with its last map")


@dataclass(frozen=True)
class ServedRequest:
    """What :meth:`MappingServer.handle` did with one request."""

    answer: bytes
    snapshot: MapSnapshot
    insert_time_s: float
    reset: bool
    session: str


class MappingServer:
    """The mapping process's side: one mapper per tracking session; requests in, encoded snapshots out."""

    def __init__(self, config: AtsvoConfig, logger: Logger | None = None) -> None:
        self.config = config
        self._log = logger or _no_log
        self._digest = mapping_digest(config)
        self.mapper: Mapper | None = None
        self.session: str | None = None
        self._camera: PinholeLevels | None = None
        self._warned_digest = False
        self.n_requests = 0
        self.n_sessions = 0

    def handle(self, payload: bytes | bytearray | memoryview) -> ServedRequest:
        """Insert the keyframe of one encoded request; raises :class:`~atsvo_ros.errors.WireError` for bad bytes."""
        wire = decode_keyframe_request(payload)
        if wire.config_digest and wire.config_digest != self._digest and not self._warned_digest:
            self._warned_digest = True
            self._log("warn", "the tracking process runs other mapping/rgb_selection/rig parameters than this "
                              "mapping process: load the same parameter file in both")
        if self.mapper is None or wire.session != self.session or wire.camera != self._camera:
            cameras = wire.camera.cameras()
            self.mapper = Mapper(self.config, cameras, refiner=window_refiner(self.config, cameras))
            self.session, self._camera = wire.session, wire.camera
            self.n_sessions += 1
        t0 = time.perf_counter()
        snap = self.mapper.insert(wire.request)
        dt = time.perf_counter() - t0
        self.n_requests += 1
        answer = encode_map_snapshot(wire.session, wire.seq, snap, self.mapper.n_keyframes)
        return ServedRequest(answer, snap, dt, wire.request.reset, wire.session)


__all__ = ["MappingServer", "RemoteMapping", "ServedRequest", "mapping_digest"]
