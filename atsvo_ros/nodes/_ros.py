"""What the nodes share: QoS profiles, message helpers, diagnostics, and the process entry point.

QoS (documented in the README): sensor inputs use ROS's sensor-data profile (best effort, volatile;
images keep the last 10, events and IMU the last 200), which matches both best-effort and reliable publishers
(realsense2_camera and ``ros2 bag play`` publish reliable); camera-sized images between processes
need the Fast DDS profile ``config/fastdds_shm.xml`` (64 MiB shared memory) in *both* processes, or
a best-effort reader loses most frames. Outputs (odometry, status) are reliable keep-last 10, the
map and the mapping snapshots reliable + transient local (a late subscriber gets the latest),
keyframe requests reliable keep-last 8.
"""
from __future__ import annotations

import array
import faulthandler
import importlib
import logging
import os
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from atsvo_ros.config import NodeConfig, TopicsConfig
from atsvo_ros.errors import AtsvoError
from atsvo_ros.runtime.cpu_priority import raise_cpu_priority

#: Seconds the clean-up after Ctrl-C may take (closing the worker, the executor, DDS) before the process dumps
#: its threads' stacks to the log and ends with 1 (measured: well under 2 s on this machine).
SHUTDOWN_LIMIT_S = 15.0

SENSOR_QOS = qos_profile_sensor_data
#: Image inputs: sensor-data QoS with a reader history of 30 (1 s at 30 Hz) instead of 5. A Python executor
#: stalled for a few frames (GIL, a loaded machine: 6 frames in a row were lost with 10 on a busy CI run)
#: catches up from the history and the frames too many are
#: dropped, counted, by the node's drop-oldest queue; a full DDS history overwrites its oldest sample without
#: any notice (Fast DDS raises no message-lost event for it), so those frames would vanish uncounted.
IMAGE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=30, reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)
#: The same for the fast streams (events ~1 kHz packets, IMU 200-400 Hz): 1 s of reader history, so a
#: callback that waits for the GIL does not lose packets.
STREAM_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)
#: ``node.sensor_qos: reliable``: every message of a reliable publisher arrives. Keep-all on both ends, so a
#: reader that falls behind holds back its acknowledgements and the writer waits (lossless back-pressure)
#: where keep-last would overwrite unread samples.
RELIABLE_INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.VOLATILE)
OUTPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
REQUEST_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=8, reliability=ReliabilityPolicy.RELIABLE)
TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)



def input_qos(sensor_qos: str, best_effort: QoSProfile) -> QoSProfile:
    """The QoS of a sensor subscription under ``node.sensor_qos`` (``best_effort`` -> the given profile)."""
    if sensor_qos == "reliable":
        return RELIABLE_INPUT_QOS
    if sensor_qos == "best_effort":
        return best_effort
    raise ValueError(f"node.sensor_qos must be best_effort or reliable, got {sensor_qos!r}")


OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


def event_message_class(msgtype: str) -> tuple[Any, str]:
    """The rclpy class of an event message type, or ``(None, why)`` when its package is not installed."""
    pkg, _, name = msgtype.partition("/msg/")
    try:
        module = importlib.import_module(f"{pkg}.msg")
    except ImportError:
        return None, (f"{pkg} is not installed (ROS: apt install ros-jazzy-{pkg.replace('_', '-')}; pip route: "
                      "source .ci/ros_env.sh)")
    cls = getattr(module, name, None)
    if cls is None:
        return None, f"{pkg} has no message {name}"
    return cls, ""


def stamp_msg(stamp_ns: int) -> Any:
    """builtin_interfaces/Time from int64 ns."""
    from builtin_interfaces.msg import Time

    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return Time(sec=int(sec), nanosec=int(nanosec))


def uint8_array(data: bytes | np.ndarray) -> Any:
    """What an rclpy ``uint8[]`` field takes without a per-byte Python check."""

    out = array.array("B")
    out.frombytes(data.tobytes() if isinstance(data, np.ndarray) else bytes(data))
    return out


def key_values(values: dict[str, Any]) -> list[Any]:
    """diagnostic_msgs/KeyValue list (numbers with a sensible precision)."""
    out = []
    for k, v in values.items():
        if isinstance(v, float):
            v = f"{v:.4g}"
        out.append(KeyValue(key=str(k), value=str(v)))
    return out


def diagnostic_array(node: Node, statuses: list[tuple[str, int, str, dict[str, Any]]],
                     stamp: Any = None) -> DiagnosticArray:
    """DiagnosticArray of ``(name, level, message, values)`` statuses, stamped now unless ``stamp`` is given."""
    arr = DiagnosticArray()
    arr.header.stamp = stamp if stamp is not None else node.get_clock().now().to_msg()
    for name, level, message, values in statuses:
        arr.status.append(DiagnosticStatus(level=bytes([level]) if isinstance(level, int) else level, name=name,
                                           message=message, hardware_id="atsvo_ros", values=key_values(values)))
    return arr


class RateMeter:
    """Counts per stream since the last report (messages, and e.g. events): rates for the diagnostics."""

    def __init__(self) -> None:
        self._counts: dict[str, float] = {}
        self._since = time.monotonic()
        self._lock = threading.Lock()

    def add(self, name: str, n: float = 1.0) -> None:
        with self._lock:
            self._counts[name] = self._counts.get(name, 0.0) + n

    def rates(self) -> dict[str, float]:
        """Per-second rates since the last call, and restart."""
        with self._lock:
            now = time.monotonic()
            dt = max(now - self._since, 1e-9)
            out = {k: v / dt for k, v in self._counts.items()}
            self._counts = {k: 0.0 for k in self._counts}
            self._since = now
            return out


class Window:
    """The last values of a measurement (latency, tracking time) for percentiles in the diagnostics."""

    def __init__(self, maxlen: int = 300) -> None:
        self._v: deque[float] = deque(maxlen=maxlen)

    def add(self, v: float) -> None:
        self._v.append(float(v))

    def percentile(self, q: float) -> float:
        return float(np.percentile(np.fromiter(self._v, float), q)) if self._v else float("nan")

    def mean(self) -> float:
        return float(np.mean(np.fromiter(self._v, float))) if self._v else float("nan")


def set_cpu_priority(node: Node, nc: NodeConfig) -> None:
    """``node.nice`` / ``node.realtime_priority`` on every thread of the process, said in the node's log (one line;
    a warning when refused). Call it before the node starts threads of its own: they inherit it."""
    priority = raise_cpu_priority(nc.nice, nc.realtime_priority)
    if priority is not None:
        (node.get_logger().info if priority.applied else node.get_logger().warn)(priority.describe())


def make_executor(kind: str, threads: int = 2) -> Any:
    """The executor named by ``node.executor`` (events, multi_threaded, single_threaded)."""
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    if kind == "multi_threaded":
        return MultiThreadedExecutor(num_threads=max(2, threads))
    return SingleThreadedExecutor()


_HELP = """usage: {prog} [--ros-args [--params-file FILE] [-p NAME:=VALUE] [-r FROM:=TO] ...]

{what}

Parameters are the configuration's keys (e.g. -p ats.tau_u_s:=0.05, -p topics.rgb:=/my/image); a
parameter file is ROS's YAML (/**: ros__parameters: ...). Bundled files: config/mini_cheetah.yaml
(the robot), config/synthetic.yaml (atsvo-sim's bags), config/mvsec.yaml, config/tum_fr1-3.yaml.
Inputs (defaults): colour {rgb}
depth {depth}, events {events}, IMU {imu}
Output: nav_msgs/Odometry on {odometry}.
Without ROS: atsvo-play BAG feeds recorded topics; atsvo-replay BAG runs the same pipeline offline.
Docs: docs/nodes.md.
"""


def _preflight(prog: str, what: str, argv: Sequence[str]) -> int | None:
    """``--help`` before ``--ros-args`` prints the usage; a missing ``--params-file`` is one line. None: go on."""
    argv = list(argv)
    user = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    if "-h" in user or "--help" in user:
        t = TopicsConfig()
        print(_HELP.format(prog=prog, what=what, rgb=t.rgb, depth=t.depth, events=t.events, imu=t.imu,
                           odometry=t.odometry))
        return 0
    for i, a in enumerate(argv[:-1]):
        if a == "--params-file" and not os.path.isfile(argv[i + 1]):
            print(f"{prog}: error: --params-file {argv[i + 1]}: no such file", file=sys.stderr)
            return 1
    return None


def _stack_file() -> Any:
    """Where thread stacks go (the process's standard error, file descriptor 2); None without one.

    ``sys.__stderr__``, not ``sys.stderr``: a test harness's replacement of the latter has no file descriptor.
    """
    err = sys.__stderr__
    try:
        return err if err is not None and err.fileno() >= 0 else None
    except (OSError, ValueError):  # closed, or not a file: no stacks, the node runs as before
        return None


def spin_until_shutdown(executor: Executor, nodes: Sequence[Node]) -> None:
    """Spin until rclpy shuts down (Ctrl-C, an external shutdown) or a node reports a fatal error.

    Ctrl-C can shut the context down between the loop's ``rclpy.ok()`` and the executor building its wait set,
    which rclpy then reports as an ``RCLError`` (the context is not valid); that is a shutdown like any other. An
    ``RCLError`` while the context is still valid is a real failure and propagates.
    """
    while rclpy.ok() and not any(getattr(n, "fatal_error", None) for n in nodes):
        try:
            executor.spin_once(timeout_sec=0.2)
        except RCLError:
            if rclpy.ok():
                raise
            return


def run_nodes(prog: str, make: Callable[[], Sequence[Node]], args: list[str] | None = None,
              threads: int = 2, what: str = "") -> int:
    """Init rclpy, build the nodes, spin until Ctrl-C / shutdown, clean up; the process's exit code.

    The executor is the nodes' ``node.executor`` parameter (``threads`` for the multi-threaded one). A
    configuration error (bad parameter file) ends the process at start with one line and exit code 1;
    Ctrl-C and external shutdowns end it with 0. A bug in a worker thread (reported through
    ``node.fatal_error``) ends it with 1 after its traceback was logged. ``kill -USR1 PID`` writes every
    thread's stack to the log; a clean-up after the spin that takes longer than ``SHUTDOWN_LIMIT_S`` (a
    thread or DDS that hangs) writes them and ends the process with 1, so Ctrl-C never leaves it hanging.
    """
    argv = args if args is not None else sys.argv
    early = _preflight(prog, what, argv)
    if early is not None:
        return early
    sys.setswitchinterval(float(os.environ.get("ATSVO_SWITCH_S", sys.getswitchinterval())))
    stacks_to = _stack_file()
    if stacks_to is not None and hasattr(signal, "SIGUSR1"):
        faulthandler.register(signal.SIGUSR1, file=stacks_to, all_threads=True)
    try:
        rclpy.init(args=argv)
    except RCLError as exc:  # a ROS argument rcl cannot parse (a broken parameter file): one line, not a traceback
        print(f"{prog}: error: {str(exc).strip().splitlines()[-1]}", file=sys.stderr)
        return 1
    nodes: list[Node] = []
    executor = None
    code = 0
    try:
        try:
            nodes = list(make())
        except AtsvoError as exc:
            rclpy.logging.get_logger(prog).fatal(f"{prog}: {exc}")
            return 1
        executor = make_executor(nodes[0].config.node.executor, threads)
        for n in nodes:
            executor.add_node(n)
        try:
            spin_until_shutdown(executor, nodes)
        finally:
            if stacks_to is not None:
                faulthandler.dump_traceback_later(SHUTDOWN_LIMIT_S, exit=True, file=stacks_to)
            executor.shutdown(timeout_sec=1.0)
        if any(getattr(n, "fatal_error", None) for n in nodes):
            code = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for n in reversed(nodes):
            close = getattr(n, "close", None)
            if close is not None:
                close()
            if executor is not None:
                # rclpy's EventsExecutor aborts the process ("Destroying callback manager with callbacks remaining")
                # when it is freed while a node's entities are still registered with it: Ctrl-C during a cold
                # start's compile did that in 5 of 28 runs, 0 of 12 with the nodes taken off first
                executor.remove_node(n)
            n.destroy_node()
        try:
            rclpy.try_shutdown()
        except RCLError:  # Ctrl-C's handler shut the context down between try_shutdown's check and its call
            if rclpy.ok():
                raise
        if stacks_to is not None:
            faulthandler.cancel_dump_traceback_later()
    if executor is not None and nodes[0].config.node.executor == "events":
        _exit_without_freeing(code)
    return code


def _exit_without_freeing(code: int) -> None:
    """End the process now, without freeing rclpy's EventsExecutor: everything is closed and shut down by then.

    Freed after a Ctrl-C just after start-up, the executor still crashed the process with its nodes taken off and
    destroyed (CI: exit -6 "Destroying callback manager with callbacks remaining"; here 1 of 15 runs beside a CPU
    hog, SIGSEGV), and 1 of 30 when freed before the nodes were destroyed.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    logging.shutdown()
    os._exit(code)


__all__ = ["ERROR", "IMAGE_QOS", "LATCHED_QOS", "OK", "OUTPUT_QOS", "REQUEST_QOS", "RateMeter", "SENSOR_QOS",
           "STREAM_QOS", "TF_QOS", "WARN", "Window", "diagnostic_array", "event_message_class", "key_values",
           "make_executor", "run_nodes", "set_cpu_priority", "spin_until_shutdown", "stamp_msg", "uint8_array"]
