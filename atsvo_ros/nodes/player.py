"""Publish a recorded sequence over DDS at its own rate (or faster) and watch what the odometry nodes answer.

What the node tests and ``atsvo-bench nodes`` use in place of a camera driver and a controller:
:class:`BagPlayer` publishes a bag's messages as they were recorded (the serialized bytes, no
re-encoding) with sensor-data QoS, at ``rate`` times real time, and records when each frame's
images went out; :class:`OdometryProbe` subscribes to the odometry (reliable, like a controller),
the per-frame status, the map, the diagnostics and calls the reset service; :class:`NodeProcesses`
starts the nodes as a user does (console scripts), samples their memory and stops them with Ctrl-C.
"""
from __future__ import annotations

import importlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.highlevel import AnyReader

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.geometry import pose_from_tq
from atsvo_ros.errors import AtsvoError
from atsvo_ros.io.decode import EventDecoder
from atsvo_ros.io.encode import serialize_event_packet
from atsvo_ros.io.msgtypes import register_event_types, typestore
from atsvo_ros.io.restamp import cdr_stamp_ns, restamp_event_packet, restamp_header
from atsvo_ros.nodes._ros import LATCHED_QOS, OUTPUT_QOS, RELIABLE_INPUT_QOS, SENSOR_QOS


def message_class(msgtype: str) -> Any:
    """``pkg/msg/Name`` -> the rclpy class."""
    pkg, _, name = msgtype.partition("/msg/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


@dataclass
class Played:
    """What a :class:`BagPlayer` sent."""

    frame_stamps_ns: list[int] = field(default_factory=list)  # colour image stamps, in publishing order
    frame_sent_s: dict[int, float] = field(default_factory=dict)  # stamp -> monotonic time both images were out
    scheduled_s: dict[int, float] = field(default_factory=dict)  # stamp -> monotonic time it was due
    n_messages: int = 0
    n_event_msgs: int = 0
    lag_s: list[float] = field(default_factory=list)  # how late each message went out


class BagPlayer:
    """Publishes a ROS 2 bag's messages on their topics (see the module docstring)."""

    def __init__(self, node: Node, bag: str | Path, topics: Iterable[str], rgb_topic: str, depth_topic: str,
                 events_topic: str | None = None, reliable: bool = False) -> None:
        """``reliable``: publish reliable keep-all (like ``ros2 bag play``) instead of sensor-data QoS."""


        self.node = node
        self.rgb_topic, self.depth_topic, self.events_topic = rgb_topic, depth_topic, events_topic
        self._events_msgtype: str | None = None
        self._events_all = None
        self._repacketized: dict[int, list[tuple[int, str, bytes, int | None]]] = {}  # packet ns -> messages
        wanted = set(topics)
        self.messages: list[tuple[int, str, bytes, int | None]] = []  # (log time, topic, cdr, header stamp)
        self.publishers: dict[str, Any] = {}
        qos = RELIABLE_INPUT_QOS if reliable else SENSOR_QOS
        with AnyReader([Path(bag)]) as reader:
            register_event_types(reader.typestore, 2)
            conns = [c for c in reader.connections if c.topic in wanted]
            for c in conns:
                if c.topic not in self.publishers:
                    self.publishers[c.topic] = node.create_publisher(message_class(c.msgtype), c.topic, qos)
            for c in conns:
                if c.topic == events_topic:
                    self._events_msgtype = c.msgtype
            for conn, t, raw in reader.messages(connections=conns):
                raw = bytes(raw)
                stamp = cdr_stamp_ns(raw) if conn.topic in (rgb_topic, depth_topic) else None
                self.messages.append((int(t), conn.topic, raw, stamp))

    @property
    def n_frames(self) -> int:
        return sum(1 for m in self.messages if m[1] == self.rgb_topic)

    def wait_for_subscribers(self, timeout_s: float = 20.0, topics: Iterable[str] | None = None) -> bool:
        """True once every publisher (or those of ``topics``) is matched by a subscriber."""
        pubs = [self.publishers[t] for t in (topics or self.publishers)]
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() > 0 for p in pubs):
                return True
            time.sleep(0.05)
        return False

    def repacketized(self, packet_s: float) -> list[tuple[int, str, bytes, int | None]]:
        """The messages with the event stream cut into packets of ``packet_s`` of recording time.

        A camera driver publishes event packets at a fixed wall-clock rate (about 1 kHz), so a recording
        played ``rate`` times faster should arrive in packets of ``rate`` ms, not ``rate`` times as many
        1 ms packets. EventPacket streams only (re-encoded in their own encoding). Kept per ``packet_s``:
        cutting and re-encoding takes seconds of CPU that must not fall inside a timed run (call it first).
        """

        if self.events_topic is None or not (self._events_msgtype or "").endswith("EventPacket"):
            raise ValueError("re-packetizing needs an EventPacket events topic")
        if self._events_all is None:
            dec = EventDecoder(self._events_msgtype, 2)
            raws = [m[2] for m in self.messages if m[1] == self.events_topic]
            self._events_all = (EventBatch.concatenate([dec.decode_raw(r) for r in raws]), dec.stats.encoding)
        events, encoding = self._events_all
        rest = [m for m in self.messages if m[1] != self.events_topic]
        if not len(events):
            return rest
        step = max(1, int(round(packet_s * 1e9)))
        if step in self._repacketized:
            return self._repacketized[step]
        edges = np.arange(events.t_first_ns, events.t_last_ns + step, step, dtype=np.int64)
        cuts = np.searchsorted(events.t, edges, side="left")
        packets = []
        for a, b in zip(cuts[:-1], cuts[1:]):
            if b > a:
                batch = events.select(slice(int(a), int(b)))
                packets.append((batch.t_last_ns, self.events_topic, serialize_event_packet(batch, encoding), None))
        self._repacketized[step] = sorted(rest + packets, key=lambda m: m[0])
        return self._repacketized[step]

    def play(self, rate: float = 1.0, first: int = 0, last: int | None = None,
             event_packet_wall_s: float | None = None, repeat: int = 1) -> Played:
        """Publish messages ``first:last`` at ``rate`` x their recorded timing; blocks until done.

        ``event_packet_wall_s``: re-cut the event stream so packets go out at this wall-clock period
        whatever the rate (see :meth:`repacketized`). ``repeat``: play the messages that many times
        back to back, each pass with its stamps and event times moved on by the length of the
        recording, so time keeps running (a long run from a short bag; the scene jumps back at each
        loop as if the robot were carried to its start).
        """
        base = self.repacketized(event_packet_wall_s * rate) if event_packet_wall_s else self.messages
        if repeat < 1:
            raise ValueError(f"repeat must be >= 1, got {repeat}")
        msgs = base[first:last]
        out = Played()
        if not msgs:
            return out
        restamp = self._restamper() if repeat > 1 else None
        stamps = [m[3] for m in msgs if m[1] == self.rgb_topic]
        loop_ns = (stamps[-1] - stamps[0]) * len(stamps) // max(len(stamps) - 1, 1) if len(stamps) > 1 else 0
        t_bag0 = msgs[0][0]
        t0 = time.monotonic() + 0.05
        pending: dict[int, int] = {}
        for k in range(repeat):
            shift = k * loop_ns
            for t, topic, raw, stamp in msgs:
                due = t0 + (t + shift - t_bag0) * 1e-9 / rate
                wait = due - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                self.publishers[topic].publish(restamp(topic, raw, shift) if shift else raw)
                now = time.monotonic()
                if topic == self.events_topic:
                    out.n_event_msgs += 1
                out.lag_s.append(now - due)
                out.n_messages += 1
                if stamp is not None:
                    stamp += shift
                    if topic == self.rgb_topic:
                        out.frame_stamps_ns.append(stamp)
                        out.scheduled_s[stamp] = t0 + (stamp - t_bag0) * 1e-9 / rate
                    pending[stamp] = pending.get(stamp, 0) + 1
                    if pending[stamp] == 2:
                        out.frame_sent_s[stamp] = now
        return out

    def _restamper(self) -> Callable[[str, bytes, int], bytes]:
        """``(topic, raw, shift_ns) -> raw`` moved in time, for every topic this player publishes."""

        encoding = None
        if self.events_topic in self.publishers:
            if not (self._events_msgtype or "").endswith("EventPacket"):
                raise ValueError(f"cannot loop {self._events_msgtype}: per-event stamps (EventPacket only)")
            first = next(m[2] for m in self.messages if m[1] == self.events_topic)
            encoding = typestore().deserialize_cdr(first, self._events_msgtype).encoding

        def restamp(topic: str, raw: bytes, shift_ns: int) -> bytes:
            if topic == self.events_topic:
                return restamp_event_packet(raw, shift_ns, encoding)
            return restamp_header(raw, shift_ns)

        return restamp


class OdometryProbe:
    """Subscribes to what the odometry nodes publish, the way a controller and a dashboard would."""

    def __init__(self, node: Node, config: Any, debug_images: bool = False) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import Image, PointCloud2

        topics = config.topics
        self.node = node
        self._lock = threading.Lock()
        self.odometry: list[tuple[float, Any]] = []  # (monotonic receipt time, msg)
        self.status: list[Any] = []
        self.maps: list[Any] = []
        self.diagnostics: dict[str, dict[str, str]] = {}  # status name -> latest values
        self.diagnostics_count = 0
        self.status_counts: dict[str, int] = {}  # status name -> messages that carried it
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        node.create_subscription(Odometry, topics.odometry, self._on_odom, reliable)
        node.create_subscription(DiagnosticArray, topics.status, self._on_status, reliable)
        node.create_subscription(PointCloud2, topics.map, self._on_map, LATCHED_QOS)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, OUTPUT_QOS)
        self.debug: dict[str, list[Any]] = {"ats": [], "selection": []}
        if debug_images:
            for key, topic in (("ats", topics.debug_ats), ("selection", topics.debug_selection)):
                node.create_subscription(Image, topic, self.debug[key].append, SENSOR_QOS)
        from std_srvs.srv import Trigger

        self.reset_client = node.create_client(Trigger, topics.reset_service)

    def _on_odom(self, msg: Any) -> None:
        with self._lock:
            self.odometry.append((time.monotonic(), msg))

    def _on_status(self, msg: Any) -> None:
        with self._lock:
            self.status.append(msg)

    def _on_map(self, msg: Any) -> None:
        with self._lock:
            self.maps.append(msg)

    def _on_diag(self, msg: Any) -> None:
        with self._lock:
            self.diagnostics_count += 1
            for s in msg.status:
                self.diagnostics[s.name] = {kv.key: kv.value for kv in s.values} | {"_message": s.message,
                                                                                     "_level": int(s.level[0])}
                self.status_counts[s.name] = self.status_counts.get(s.name, 0) + 1

    def diag_count(self, name_part: str) -> int:
        """How many diagnostics messages carried the status whose name contains ``name_part``."""
        with self._lock:
            return sum(n for name, n in self.status_counts.items() if name_part in name)

    def diag(self, name_part: str) -> dict[str, str] | None:
        """The latest diagnostics values of the status whose name contains ``name_part``."""
        with self._lock:
            for name, values in self.diagnostics.items():
                if name_part in name:
                    return dict(values)
        return None

    def wait(self, predicate, timeout_s: float) -> bool:
        """Poll ``predicate()`` until it holds (True) or ``timeout_s`` passes (False)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(0.05)
        return predicate()

    def wait_idle(self, expected: int, idle_s: float = 3.0, timeout_s: float = 60.0) -> int:
        """Wait until ``expected`` odometry messages arrived or none came for ``idle_s``; how many came."""
        deadline = time.monotonic() + timeout_s
        last_n, last_change = -1, time.monotonic()
        while time.monotonic() < deadline:
            n = len(self.odometry)
            if n >= expected:
                return n
            if n != last_n:
                last_n, last_change = n, time.monotonic()
            elif time.monotonic() - last_change > idle_s:
                break
            time.sleep(0.05)
        return len(self.odometry)

    def received(self) -> list[tuple[float, Any]]:
        """A copy of the odometry received so far: ``(monotonic receipt time, msg)``."""
        with self._lock:
            return list(self.odometry)

    def statuses(self, since: int = 0) -> list[str]:
        """The per-frame status (``ok``, ``degraded``, ...) of each status message received (from ``since``)."""
        with self._lock:
            return [m.status[0].message for m in self.status[since:]]

    def poses(self, since: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Stamps (ns) and 4x4 ``T_odom_base`` of the odometry received (from index ``since``)."""

        with self._lock:
            msgs = [m for _, m in self.odometry[since:]]
        stamps = np.array([m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in msgs], np.int64)
        T = np.stack([pose_from_tq(np.array([m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z]),
                                   np.array([m.pose.pose.orientation.x, m.pose.pose.orientation.y,
                                             m.pose.pose.orientation.z, m.pose.pose.orientation.w]))
                      for m in msgs]) if msgs else np.zeros((0, 4, 4))
        return stamps, T

    def reset(self, timeout_s: float = 10.0) -> Any:
        """Call the reset service; the response (None when no answer)."""
        from std_srvs.srv import Trigger

        if not self.reset_client.wait_for_service(timeout_sec=timeout_s):
            return None
        future = self.reset_client.call_async(Trigger.Request())
        deadline = time.monotonic() + timeout_s
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.02)
        return future.result() if future.done() else None


def console_script(name: str) -> str:
    """The console script ``name`` of this Python's environment (else whatever is on PATH)."""
    path = Path(sys.executable).parent / name
    return str(path) if path.exists() else name


def rss_mb(pid: int) -> float | None:
    """Resident memory of a process in MB (Linux /proc), None when it is gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def process_tree(pid: int) -> list[int]:
    """``pid`` and every process it started, directly or not (Linux /proc; e.g. ``node.core_process``'s child)."""
    parents: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        parents.setdefault(ppid, []).append(int(stat.parent.name))
    tree, todo = [], [pid]
    while todo:
        p = todo.pop()
        tree.append(p)
        todo += parents.get(p, [])
    return tree


def cpu_s(pid: int) -> float | None:
    """CPU seconds (user + system, all threads) a process has used (Linux /proc), None when it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _tree_rss_mb(pid: int) -> float | None:
    """Resident memory of a process and its children in MB, None when the process is gone."""
    own = rss_mb(pid)
    return None if own is None else own + sum(m for q in process_tree(pid)[1:] if (m := rss_mb(q)) is not None)


class NodeProcesses:
    """Node processes started from their console scripts; RSS sampled in the background; stopped with SIGINT."""

    def __init__(self, scripts: list[str], args: list[str], log_dir: str | Path, sample_s: float = 0.5) -> None:
        self.scripts = scripts
        log_dir = Path(log_dir)
        log_dir.mkdir(parents=True, exist_ok=True)
        self.logs = [log_dir / f"{s}-{os.getpid()}-{time.monotonic_ns()}.log" for s in scripts]
        self.procs = [subprocess.Popen([console_script(s), *args], stdout=open(log, "w"), stderr=subprocess.STDOUT)
                      for s, log in zip(scripts, self.logs)]
        self.rss: list[tuple[float, list[float | None]]] = []  # (monotonic time, MB per process)
        self._stop = threading.Event()
        self._sampler = threading.Thread(target=self._sample, args=(sample_s,), daemon=True)
        self._sampler.start()

    def _sample(self, period_s: float) -> None:
        while not self._stop.wait(period_s):
            self.rss.append((time.monotonic(), [_tree_rss_mb(p.pid) for p in self.procs]))

    def cpu_s(self) -> float:
        """CPU seconds used so far by all the node processes and their children (those still running)."""
        return sum(c for p in self.procs for q in process_tree(p.pid) if (c := cpu_s(q)) is not None)

    def log_tail(self, n: int = 2000) -> str:
        return " | ".join(Path(log).read_text()[-n:] for log in self.logs)

    def stop(self, timeout_s: float = 30.0) -> list[int]:
        """Ctrl-C every process; their exit codes (a process that ignores it has its thread stacks written to
        its log with SIGUSR1, then is killed: -9)."""
        self._stop.set()
        for p in self.procs:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        codes = []
        for p in self.procs:
            try:
                codes.append(p.wait(timeout=timeout_s))
            except subprocess.TimeoutExpired:
                p.send_signal(signal.SIGUSR1)
                time.sleep(1.0)
                p.kill()
                p.wait()
                codes.append(-9)
        return codes


@dataclass
class NodeSession:
    """What :func:`node_session` hands its caller; ``exit_codes`` is filled when the session ends."""

    player: BagPlayer
    probe: OdometryProbe
    procs: NodeProcesses
    exit_codes: list[int] = field(default_factory=list)


def spin_in_background(executor: Any) -> threading.Thread:
    """Spin ``executor`` on a daemon thread; stop it with :func:`stop_spinning` before the context shuts down."""
    thread = threading.Thread(target=executor.spin, name="atsvo-spin", daemon=True)
    thread.start()
    return thread


def stop_spinning(executor: Any, thread: threading.Thread | None, timeout_s: float = 5.0) -> None:
    """Shut ``executor`` down and wait for its spin thread to return.

    A process that exits while the spin thread is still inside rclpy's wait aborts ("terminate called
    without an active exception", exit code -6: seen once in five ``atsvo-play`` runs), so the thread
    is joined, not left to the interpreter's exit.
    """
    executor.shutdown(timeout_sec=timeout_s)
    if thread is not None:
        thread.join(timeout_s)


@contextmanager
def node_session(bag: str | Path, config: Any, scripts: list[str], ros_args: list[str], log_dir: str | Path, *,
                 reliable: bool = False, debug_images: bool = False, start_timeout_s: float = 60.0,
                 name: str = "atsvo_probe") -> Iterator[NodeSession]:
    """Start ``scripts`` with ``ros_args``, a player of ``bag`` and a probe; yield once both ends are matched.

    The probe spins in its own DDS context (a multi-threaded executor on a daemon thread). Raises
    :class:`AtsvoError` with the nodes' log tail when they do not subscribe (or, split, do not find
    each other) within ``start_timeout_s``. On exit the nodes get Ctrl-C and the context shuts down.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import MultiThreadedExecutor

    t = config.topics
    procs = NodeProcesses(scripts, ros_args, log_dir)
    context = Context()
    rclpy.init(context=context)
    executor = spinner = None
    session = None
    try:
        node = rclpy.create_node(name, context=context)
        player = BagPlayer(node, bag, [t.rgb, t.depth, t.rgb_info, t.event_info, t.events, t.imu], t.rgb, t.depth,
                           t.events, reliable=reliable)
        probe = OdometryProbe(node, config, debug_images=debug_images)
        executor = MultiThreadedExecutor(num_threads=2, context=context)
        executor.add_node(node)
        spinner = spin_in_background(executor)
        # an RGB-D node subscribes to no event topic: wait for the topics it takes
        wanted = None if config.mode == "fused" else [t.rgb, t.depth, t.rgb_info, t.imu]
        if not player.wait_for_subscribers(start_timeout_s, wanted):
            raise AtsvoError(f"the nodes did not subscribe within {start_timeout_s:g} s: " + procs.log_tail())
        if "tracking_node" in scripts and not probe.wait(
                lambda: (probe.diag("odometry") or {}).get("mapping") == "connected", start_timeout_s):
            raise AtsvoError(f"tracking_node did not find mapping_node: {probe.diag('odometry')} " + procs.log_tail())
        time.sleep(1.0)  # a reader can match a moment after its writer did
        session = NodeSession(player, probe, procs)
        yield session
    finally:
        codes = procs.stop()
        if session is not None:
            session.exit_codes = codes
        if executor is not None:
            stop_spinning(executor, spinner)
        rclpy.try_shutdown(context=context)


__all__ = ["BagPlayer", "NodeProcesses", "NodeSession", "OdometryProbe", "Played", "console_script", "message_class",
           "node_session", "cpu_s", "process_tree", "rss_mb", "spin_in_background", "stop_spinning"]
