"""The odometry core in a process of its own (``node.core_process``): the node's worker hands it each frame and waits.

Why: in ``atsvo_node`` the worker thread's wall time per frame is 1.4-2.7x its own CPU time. On an idle machine
the rest is the GIL, which the executor's callbacks (1 kHz event packets), the mapping thread and the event-map
builder take in turn with the worker (docs/nodes.md). In a child process the core, its mapping thread and its
event-map builder share a GIL of their own; the node process keeps DDS, decoding and the frame assembly.

:class:`CoreHost` spawns one child for the node's lifetime and waits until it has warmed up (the same synthetic
frames as the node's own warm-up). :meth:`CoreHost.new_core` gives an
:class:`~atsvo_ros.runtime.types.OdometryCore` whose calls go to a fresh
:class:`~atsvo_ros.core.odometry.odometry.Odometry` in the child. ``add_imu`` and ``add_events`` are buffered
and go with the next frame, in one message over a pipe; the frame's result comes back (or its
:class:`~atsvo_ros.errors.AtsvoError`, raised again here), after every map snapshot that mapping made before it.
A child that dies, or a bug in it, raises :class:`CoreProcessError` (an :class:`AtsvoError`) for every frame
from then on: the runtime logs and counts them (``frames_failed``), and the node's diagnostics say the child
is dead. The child is not restarted.

The images and events of a frame (about 5 MB at 640x480 during a backflip, 20 MB at its peak) do not go through
the pipe: pickled through a pipe they cost the worker 11 ms of CPU a frame and the round trip 20 ms more. Their
arrays go out of band (pickle protocol 5) into one shared-memory block that the child copies them out of; only
the small rest goes through the pipe. One block suffices because the worker waits for each frame's result
before it sends the next.
"""
from __future__ import annotations

import multiprocessing
import pickle
import threading
import traceback
from collections.abc import Callable
from multiprocessing import shared_memory
from multiprocessing.connection import Connection
from typing import Any

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.frame import OdometryResult, RgbdFrame
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.core.mapping.map import MapSnapshot
from atsvo_ros.core.mapping.ports import ThreadedMapping
from atsvo_ros.core.odometry.odometry import Odometry
from atsvo_ros.errors import AtsvoError
from atsvo_ros.runtime.warmup import warm_up


class CoreProcessError(AtsvoError):
    """The core's process died, failed to start, or hit a bug (its traceback is in the message)."""


_ALIGN = 64  # bytes: each array starts on a cache line
_MIN_BLOCK = 32 << 20  # the first shared block; a bigger message makes a new one, half as big again


class _SharedSender:
    """The parent's side: a message's arrays go into a shared block, the rest (and where they are) is returned."""

    def __init__(self) -> None:
        self._shm: shared_memory.SharedMemory | None = None

    def pack(self, obj: Any) -> tuple[bytes, str, list[tuple[int, int]]]:
        buffers: list[pickle.PickleBuffer] = []
        data = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
        raws = [b.raw() for b in buffers]
        spans, offset = [], 0
        for raw in raws:
            spans.append((offset, raw.nbytes))
            offset += -(-raw.nbytes // _ALIGN) * _ALIGN
        if self._shm is None or self._shm.size < offset:
            self.close()
            self._shm = shared_memory.SharedMemory(create=True, size=max(_MIN_BLOCK, offset + offset // 2))
        buf = self._shm.buf
        for raw, (start, n) in zip(raws, spans):
            buf[start:start + n] = raw
        return data, self._shm.name, spans

    def close(self) -> None:
        if self._shm is not None:
            self._shm.close()
            self._shm.unlink()
            self._shm = None


class _SharedReceiver:
    """The child's side: rebuilds a message, copying its arrays out of the block (the parent reuses it)."""

    def __init__(self) -> None:
        self._shm: shared_memory.SharedMemory | None = None

    def unpack(self, data: bytes, name: str, spans: list[tuple[int, int]]) -> Any:
        if self._shm is None or self._shm.name != name:
            self.close()
            # attaching registers the block again with the resource tracker, which the child shares with the
            # parent (spawn hands it down): the parent's unlink clears it once for both
            self._shm = shared_memory.SharedMemory(name=name)
        buf = self._shm.buf
        return pickle.loads(data, buffers=[bytearray(buf[start:start + n]) for start, n in spans])

    def close(self) -> None:
        if self._shm is not None:
            self._shm.close()
            self._shm = None


def _serve(conn: Connection, config: AtsvoConfig, use_events: bool) -> None:
    """The child: warm up, then build cores and run frames as the parent asks, until ``stop`` or the pipe closes."""
    lock = threading.Lock()  # the mapping thread sends snapshots while the main thread may send a result

    def send(msg: tuple) -> None:
        with lock:
            conn.send(msg)

    core: Odometry | None = None
    shared = _SharedReceiver()
    try:
        warm = warm_up(config, use_events=use_events)
        send(("ready", warm.seconds))
        while True:
            try:
                msg = conn.recv()
            except EOFError:  # the parent is gone
                break
            kind = msg[0]
            if kind == "frame":
                imu, events, frame = shared.unpack(*msg[1:])
                if core is None:
                    raise RuntimeError("a frame came before any core was built")
                for batch in imu:
                    core.add_imu(batch)
                for batch in events:
                    core.add_events(batch)
                try:
                    send(("result", core.process_frame(frame)))
                except AtsvoError as exc:
                    send(("error", exc))
            elif kind == "new":
                _, cfg, rgb_camera, event_camera = msg
                if core is not None:
                    core.close()

                def port(mapper: Any, cfg: AtsvoConfig = cfg) -> ThreadedMapping:
                    return ThreadedMapping(mapper, synchronous=cfg.mapping.synchronous,
                                           on_snapshot=lambda snapshot: send(("snapshot", snapshot)))

                core = Odometry(cfg, rgb_camera, event_camera, mapping=port)
            elif kind == "drop":
                if core is not None:
                    core.close()
                core = None
            elif kind == "stop":
                break
            else:
                raise RuntimeError(f"unknown request {kind!r}")
    except BaseException:  # a bug: the parent raises it as CoreProcessError, the node stops its worker
        try:
            send(("crash", traceback.format_exc()))
        except (OSError, ValueError):
            pass
    finally:
        if core is not None:
            core.close()
        shared.close()
        conn.close()


class ProcessCore:
    """An :class:`~atsvo_ros.runtime.types.OdometryCore` whose odometry runs in the host's child process."""

    def __init__(self, host: CoreHost) -> None:
        self._host = host
        self._imu: list[ImuBatch] = []
        self._events: list[EventBatch] = []
        self._closed = False

    def add_imu(self, batch: ImuBatch) -> None:
        """Buffer IMU samples; they go to the child with the next frame."""
        self._imu.append(batch)

    def add_events(self, batch: EventBatch) -> None:
        """Buffer events; they go to the child with the next frame."""
        self._events.append(batch)

    def process_frame(self, frame: RgbdFrame) -> OdometryResult:
        """Send the frame (and what was buffered before it) to the child and wait for its result."""
        imu, events, self._imu, self._events = self._imu, self._events, [], []
        return self._host.process(imu, events, frame)

    def close(self) -> None:
        """Drop the child's core (the child itself stays for the next one)."""
        if not self._closed:
            self._closed = True
            self._host.drop()


class CoreHost:
    """The child process that runs the odometry cores of one node (see the module docstring).

    Args:
        config: The node's configuration (what the warm-up runs).
        use_events: Warm the fused path as well.
        on_snapshot: Called (in the thread that called :meth:`ProcessCore.process_frame`) with every map snapshot
            the child's mapping made, before the result of the frame it came with.
        start_timeout_s: The longest the child may take to start and warm up.
    """

    def __init__(self, config: AtsvoConfig, use_events: bool,
                 on_snapshot: Callable[[MapSnapshot], None] | None = None, start_timeout_s: float = 120.0) -> None:
        self._on_snapshot = on_snapshot
        self._shared = _SharedSender()
        ctx = multiprocessing.get_context("spawn")  # never fork a process that runs DDS threads
        self._conn, child = ctx.Pipe(duplex=True)
        self._proc = ctx.Process(target=_serve, args=(child, config, use_events), name="atsvo-core", daemon=True)
        self._proc.start()
        child.close()
        if not self._conn.poll(start_timeout_s):
            self.close()
            raise CoreProcessError(f"the core process did not warm up within {start_timeout_s:g} s")
        kind, payload = self._recv()
        if kind != "ready":
            raise CoreProcessError(f"the core process said {kind!r} instead of ready")
        self.warm_up_s = float(payload)

    @property
    def alive(self) -> bool:
        """Whether the child still runs."""
        return self._proc.is_alive()

    @property
    def pid(self) -> int | None:
        """The child's process id (None before it started)."""
        return self._proc.pid

    def new_core(self, config: AtsvoConfig, rgb_camera: CameraModel,
                 event_camera: CameraModel | None = None) -> ProcessCore:
        """A new odometry (new map, pose at the identity) in the child: the runtime's ``core_factory``."""
        self._send(("new", config, rgb_camera, event_camera))
        return ProcessCore(self)

    def process(self, imu: list[ImuBatch], events: list[EventBatch], frame: RgbdFrame) -> OdometryResult:
        """Run one frame in the child (snapshots that arrive first go to ``on_snapshot``)."""
        self._send(("frame", *self._shared.pack((imu, events, frame))))
        while True:
            kind, payload = self._recv()
            if kind == "result":
                return payload
            if kind == "snapshot":
                if self._on_snapshot is not None:
                    self._on_snapshot(payload)
            elif kind == "error":
                raise payload
            else:
                raise CoreProcessError(f"unexpected {kind!r} from the core process")

    def drop(self) -> None:
        """Drop the child's current core."""
        if self._proc.is_alive():
            self._send(("drop",))

    def close(self, timeout_s: float = 10.0) -> None:
        """Stop the child (its core and mapping thread first); killed if it does not stop in time."""
        if self._proc.is_alive():
            try:
                self._conn.send(("stop",))
            except (OSError, ValueError):
                pass
            self._proc.join(timeout_s)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(timeout_s)
        self._conn.close()
        self._shared.close()

    def _send(self, msg: tuple) -> None:
        try:
            self._conn.send(msg)
        except (OSError, ValueError) as exc:
            raise CoreProcessError(f"the core process is gone (exit code {self._proc.exitcode}): {exc}") from exc

    def _recv(self) -> tuple[str, Any]:
        try:
            kind, payload = self._conn.recv()
        except (EOFError, OSError) as exc:
            raise CoreProcessError(f"the core process died (exit code {self._proc.exitcode})") from exc
        if kind == "crash":
            raise CoreProcessError(f"the core process failed:\n{payload}")
        return kind, payload


__all__ = ["CoreHost", "CoreProcessError", "ProcessCore"]
