"""The nodes as a user runs them (console scripts in subprocesses), fed over loopback DDS at the sequence's rate.

A synthetic trot is published message by message (the recorded bytes, real time) under the Fast DDS
profile config/fastdds_shm.xml (.ci/ros_env.sh exports it): with sensor-data QoS (the default,
best effort: a starved machine may lose frames on the way, the node answers for those it got) and,
for the pose-for-pose comparison, reliable keep-all on both ends (``node.sensor_qos: reliable``,
``ros2 bag play``'s QoS: every frame arrives, whatever the load); a probe subscribes to
the odometry like a controller. Checked: one odometry per frame, the last one too (minus what the node counts as
dropped), poses equal to ``atsvo-replay`` with ``mapping.synchronous``, ATE close to
the replay's without it, the map, the per-frame status and /diagnostics arrive, the reset service
works, Ctrl-C ends every process with exit code 0.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (pip install -e '.[ros]'; docs/ros_env.md)")
pytest.importorskip("event_camera_msgs.msg", reason="event_camera_msgs not built: source .ci/ros_env.sh")


from atsvo_ros.config import load_config  # noqa: E402
from atsvo_ros.core.geometry import so3_log  # noqa: E402
from atsvo_ros.eval.metrics import EvalOptions, evaluate  # noqa: E402
from atsvo_ros.io.sources import open_source  # noqa: E402
from atsvo_ros.io.trajectory import Trajectory, read_tum  # noqa: E402
from atsvo_ros.nodes.player import (  # noqa: E402
    BagPlayer,
    NodeProcesses,
    OdometryProbe,
    Played,
    console_script,
    node_session,
)
from atsvo_ros.runtime import FrameInput, OdometryRuntime  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
PARAMS = ROOT / "config" / "synthetic.yaml"
START_TIMEOUT_S = 60.0  # node start-up: imports, numba's cache, DDS discovery (a loaded CI machine)


@pytest.fixture(scope="module")
def sequence(tmp_path_factory, trot_3s_bag):
    """A 3 s synthetic trot (160x120 colour + depth, events, IMU, ground truth) and atsvo-replay's answer."""
    base = tmp_path_factory.mktemp("nodes_dds")
    bag = trot_3s_bag
    out = base / "replay"
    done = subprocess.run([console_script("atsvo-replay"), str(bag), "--out", str(out), "--preset", "synthetic",
                           "--no-plots", "--no-progress"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    replay = read_tum(out / "trajectory.tum")
    metrics = json.loads((out / "metrics.json").read_text())
    timing = json.loads((out / "timing.json").read_text())
    assert timing["mode"] == "fused"
    return bag, replay, metrics, read_tum(out / "groundtruth.tum"), base


@dataclass
class Run:
    played: Played
    probe: OdometryProbe
    stamps: np.ndarray
    poses: np.ndarray
    diag: dict[str, str]
    statuses: list[str]
    reset_ok: bool | None
    exit_codes: list[int]
    logs: list[str]
    reliable: bool  # node.sensor_qos reliable and a reliable player: nothing may be lost on the way


def _run(sequence, scripts: list[str], synchronous: bool, queue_size: int, check_reset: bool = False,
         debug_images: bool = False, reliable: bool = False, params: tuple[str, ...] = ()) -> Run:
    bag, *_, base = sequence
    cfg = load_config("synthetic")
    args = ["--ros-args", "--params-file", str(PARAMS), "-p", f"mapping.synchronous:={str(synchronous).lower()}",
            "-p", f"node.queue_size:={queue_size}", "-p", "node.diagnostics_period_s:=0.25",
            "-p", f"node.sensor_qos:={'reliable' if reliable else 'best_effort'}"]
    for param in params:
        args += ["-p", param]
    with node_session(bag, cfg, scripts, args, base / "logs", reliable=reliable, debug_images=debug_images,
                      start_timeout_s=START_TIMEOUT_S, name="atsvo_test_probe") as session:
        player, probe, procs = session.player, session.probe, session.procs
        played = player.play(rate=1.0)
        n_frames = len(played.frame_stamps_ns)
        probe.wait_idle(n_frames, idle_s=4.0)  # the last frame goes out once the inputs fall silent
        # the tracking node's own status, twice: the mapping node's /diagnostics may have come in between
        n_diag = probe.diag_count("atsvo_tracking: odometry")
        assert probe.wait(lambda: probe.diag_count("atsvo_tracking: odometry") > n_diag + 1, 10.0), "no /diagnostics"
        diag = probe.diag("atsvo_tracking: odometry")
        stamps, poses = probe.poses()
        statuses = probe.statuses()
        reset_ok = _check_reset(player, probe) if check_reset else None
    codes = session.exit_codes
    logs = [Path(log).read_text() for log in procs.logs]
    return Run(played, probe, stamps, poses, diag, statuses, reset_ok, codes, logs, reliable)


def _delivered(run: Run) -> bool:
    """Every published frame reached the node (``rgb_received``/``depth_received``), the reset replay too."""
    n = len(run.played.frame_stamps_ns)
    if run.diag is None:
        return True  # nothing to tell; _check_common reports the missing diagnostics
    # an IMU sample later than node.imu_max_wait_s behind the images missed its frame, or (the same stall seen from
    # the frame's side) a frame went out while the IMU was that far behind and silent: delivery, not the node
    return (min(int(run.diag["rgb_received"]), int(run.diag["depth_received"])) >= n and run.reset_ok is not False
            and int(run.diag.get("count_imu_late", 0)) == 0 and int(run.diag.get("count_frames_without_imu", 0)) == 0)


def _run_delivered(sequence, scripts: list[str], **kwargs) -> Run:
    """:func:`_run`, once more when DDS lost frames before the node saw them or delivered IMU samples too late.

    The checks count on every frame arriving. On a starved machine (the in-test player measured up to
    1.1 s late, in 2 of ~6 CI runs) best-effort DDS loses bursts of frames that no loss event reports,
    and one CI run (reliable QoS) delivered 105 of 615 IMU samples more than 0.1 s behind the images (a
    stalled node's shared-memory port queue overflowed and the writer repaired the IMU ~1 s later; the
    profile's port_queue_capacity now covers ~6 s of stall: docs/ros_env.md), and another (27 Nov, the core in
    a child process) released 19 frames while the IMU was over node.imu_max_wait_s behind and silent; that
    is the transport, not the node, so such a run is repeated once (with a warning), never more.
    """
    run = _run(sequence, scripts, **kwargs)
    if not _delivered(run):
        warnings.warn(f"DDS lost frames ({run.diag['rgb_received']} of {len(run.played.frame_stamps_ns)} colour "
                      f"images arrived, {run.diag.get('count_imu_late', 0)} IMU samples too late, "
                      f"{run.diag.get('count_frames_without_imu', 0)} frames released without their IMU, reset "
                      f"replay complete: {run.reset_ok}); running once more", stacklevel=2)
        run = _run(sequence, scripts, **kwargs)
    return run


def _check_reset(player: BagPlayer, probe: OdometryProbe) -> bool:
    """Reset, replay the first second: the odometry starts over at the identity, initialising, then tracks."""
    response = probe.reset()
    assert response is not None and response.success, response
    n0 = len(probe.odometry)
    t_end = player.messages[0][0] + 1_000_000_000
    last = next(i for i, m in enumerate(player.messages) if m[0] > t_end)
    played = player.play(rate=1.0, last=last)
    probe.wait_idle(n0 + len(played.frame_stamps_ns), idle_s=3.0)
    stamps, poses = probe.poses(since=n0)
    statuses = probe.statuses(since=n0)
    # the replayed frames, from the identity of the new start
    if len(stamps) < len(played.frame_stamps_ns) - 1:
        return False  # frames lost on the way (see _run_delivered); the caller repeats the run once
    assert np.allclose(poses[0], np.eye(4)) and statuses[0] == "initialising", (poses[0], statuses[:3])
    assert statuses[-1] == "ok" and np.linalg.norm(poses[-1][:3, 3]) > 0.05  # tracking again, and moving
    return True


def _pose_errors(run: Run, ref: Trajectory) -> tuple[float, float]:
    """Largest position (m) and rotation (deg) difference to the replay, pose by pose at equal stamps."""
    index = {int(s): i for i, s in enumerate(ref.stamps_ns)}
    assert all(int(s) in index for s in run.stamps), "the node published stamps the replay does not have"
    dp = [np.linalg.norm(T[:3, 3] - ref.T_w_b[index[int(s)]][:3, 3]) for s, T in zip(run.stamps, run.poses)]
    dr = [np.degrees(np.linalg.norm(so3_log(T[:3, :3].T @ ref.T_w_b[index[int(s)]][:3, :3])))
          for s, T in zip(run.stamps, run.poses)]
    return max(dp), max(dr)


def _check_common(run: Run) -> None:
    """One odometry per frame minus counted drops, status and map and diagnostics arrived, Ctrl-C -> 0."""
    d = run.diag
    assert d is not None, "no diagnostics from the tracking node"
    n_frames = len(run.played.frame_stamps_ns)
    received = set(run.stamps.tolist())
    missing = [i for i, s in enumerate(run.played.frame_stamps_ns) if s not in received]
    why = (f"{len(run.stamps)} odometry, {n_frames} frames, none for frames {missing}; player late by up to "
           f"{max(run.played.lag_s):.3f} s; {json.dumps(d, sort_keys=True)}")
    received = int(d["rgb_received"])
    if run.reliable:  # reliable keep-all end to end: every frame reaches the node, whatever the machine's load
        assert received == int(d["depth_received"]) == n_frames, why
    elif received < n_frames:  # best effort may lose frames on a starved machine; the node answers for the rest
        warnings.warn(f"best-effort DDS lost {n_frames - received} of {n_frames} frames before the node", stacklevel=2)
    # the node's own count of images that never came (stamp gaps) never blames the transport for more than it lost
    # (a loss after the last image that arrived shows no gap; StampGaps' unit tests count interior losses exactly)
    assert 0 <= int(d["missing_rgb"]) <= n_frames - received, why
    assert int(d["missing_depth"]) <= n_frames - int(d["depth_received"]), why
    accounted = (len(run.stamps) + int(d["queue_drops"]) + int(d["sync_dropped_rgb"]) + int(d["frames_waiting"])
                 + sum(int(d.get(f"count_{k}", 0)) for k in ("frames_duplicate", "frames_out_of_order",
                                                            "frames_dropped_waiting_camera_info")))
    assert accounted == received, why
    # what the issue asks /diagnostics to carry: mode, status, tracking time, queue and decoder drops, rates
    assert {"mode", "status", "tracking_time_ms_p50", "queue_drops", "decoder_drops", "rate_rgb_hz",
            "rate_event_msgs_hz", "rate_odometry_hz"} <= set(d) and d["mode"] in ("fused", "rgbd"), d
    # the worker's own CPU is part of its wall time per frame (the rest waited for a core or the GIL)
    assert 0.0 < float(d["worker_cpu_ms_mean"]) <= float(d["worker_ms_mean"]) * 1.01 + 0.1, d
    # the warm-up compiled every kernel the run took: no frame stalled for numba (the node logs any it missed)
    assert int(d["late_kernels"]) == 0, d
    # the last frame, whose events and IMU samples past its stamp never come, went out once the inputs fell silent
    assert int(d["frames_waiting"]) == 0, why
    assert len(run.statuses) == len(run.stamps) and run.probe.maps, "per-frame status or map missing"
    cloud = run.probe.maps[-1]
    assert cloud.width > 100 and cloud.header.frame_id == "odom" and [f.name for f in cloud.fields] == \
        ["x", "y", "z", "intensity"]
    assert run.exit_codes == [0] * len(run.exit_codes), (run.exit_codes, [log[-6000:] for log in run.logs])


def _ate(run: Run, gt: Trajectory) -> float:
    return _ate_of(run.stamps, run.poses, run.statuses, gt)


def _ate_of(stamps: np.ndarray, poses: np.ndarray, statuses: list[str], gt: Trajectory) -> float:
    ev = evaluate(gt, Trajectory(stamps, poses), EvalOptions(interpolate_gt=True),
                  est_ok=np.array([s == "ok" for s in statuses]))
    return float(ev.metrics["ate_rmse_m"])


def _inline_over_the_same_frames(bag: Path, tracked_ns: np.ndarray, gt: Trajectory) -> float:
    """ATE of the replay's pipeline (mapping inline) fed only the frames the node tracked.

    A node that cannot keep up drops frames at its queue (node.queue_size) and hands their events and IMU
    samples on to the next frame (:meth:`FrameInput.after`); which frames go depends on the machine's
    load (6 to 33 of 90 on this trot, idle machine), and so does the ATE (1.1-1.6 cm here, 1.7 in one CI
    run against the full replay's 1.13). Dropping the same frames the same way in process leaves
    asynchronous mapping as the one difference.
    """
    cfg = load_config("synthetic")
    source = open_source([bag], None, cfg)
    try:
        cfg, rgb_cam, ev_cam = source.setup(cfg, [])
        runtime = OdometryRuntime(cfg, rgb_cam, ev_cam, use_events=True)
        inputs: list[FrameInput] = []
        for _ in source.feed(runtime, ("rgb", "depth", "imu", "events"), None):
            inputs.extend(runtime.pop_ready())
        inputs.extend(runtime.flush_inputs())  # the node's end of stream
    finally:
        source.close()
    kept = set(int(s) for s in tracked_ns)
    stamps, poses, statuses, carried = [], [], [], None
    for inp in inputs:
        inp = inp.after(carried) if carried is not None else inp
        if inp.stamp_ns not in kept:
            carried = inp
            continue
        carried, out = None, runtime.process(inp)
        stamps.append(out.result.stamp_ns)
        poses.append(out.result.T_odom_base)
        statuses.append(out.result.status.value)
    assert stamps == sorted(kept), "the node tracked frames the replay's pipeline does not form"
    return _ate_of(np.array(stamps, np.int64), np.stack(poses), statuses, gt)


@pytest.mark.parametrize("scripts,params", [(["atsvo_node"], ()), (["mapping_node", "tracking_node"], ()),
                                            (["atsvo_node"], ("node.core_process:=true",))],
                         ids=["atsvo_node", "split", "core_process"])
def test_synchronous_nodes_give_the_replay_poses(sequence, scripts, params):
    """Loss-free mode (reliable inputs, mapping.synchronous): node.queue_size 2 gives way to a backlog that drops
    nothing, and the node's odometry is the replay's, pose for pose (also with the core in a child process)."""
    _, replay, *_ = sequence
    run = _run_delivered(sequence, scripts, synchronous=True, queue_size=2, check_reset=scripts == ["atsvo_node"],
                         reliable=True, params=params)
    _check_common(run)
    d = run.diag
    assert d["core"].startswith("child process" if params else "in process"), d
    assert d["queue_mode"] == "loss-free", d
    assert int(d["queue_drops"]) == 0 and int(d["sync_dropped_rgb"]) == 0 and int(d["decoder_drops"]) == 0
    assert int(d["count_event_msgs"]) > 2900 and int(d.get("count_imu_late", 0)) == 0, d
    assert int(d["late_events"]) == int(d.get("count_frames_without_imu", 0)) == 0, d
    assert int(d["frames_without_events"]) <= 1, d  # the last frame: the event stream ends before its stamp
    dp, dr = _pose_errors(run, replay)
    assert dp < 1e-3 and dr < 0.05, (dp, dr, json.dumps(d, sort_keys=True))
    assert len(run.stamps) == len(replay.stamps_ns)  # the last frame too: it goes out once the inputs fall silent
    if scripts != ["atsvo_node"]:
        assert int(d["mapping_timeouts"]) == 0 and int(d["mapping_answers"]) == int(d["mapping_sent"]) > 3
    else:
        assert run.reset_ok


@pytest.mark.parametrize("scripts", [["atsvo_node"], ["mapping_node", "tracking_node"]], ids=["atsvo_node", "split"])
def test_asynchronous_nodes_are_as_accurate_as_the_replay(sequence, scripts):
    """The default (PTAM: tracking goes on while mapping works): ATE within 50 % or 5 mm of the replay's
    pipeline over the frames the node tracked (those its queue dropped left out the same way).

    Which frames track against which map depends on when keyframes come back, so the ratio is a random
    quantity: 0.81-1.35 on 27 runs of this 3 s trot, 2.13 on one (split, 2.23 against 1.05 cm). One run
    over the bound is repeated once, with a warning; a systematic loss of accuracy fails both.
    """
    bag, _, metrics, gt, _ = sequence
    for attempt in (1, 2):
        run = _run_delivered(sequence, scripts, synchronous=False, queue_size=2,
                             debug_images=scripts == ["atsvo_node"])
        _check_common(run)
        if scripts == ["atsvo_node"]:  # someone subscribes to the debug images: they come, one per frame or so
            ats, sel = run.probe.debug["ats"], run.probe.debug["selection"]
            assert len(ats) > 0.5 * len(run.stamps) and len(sel) > 0.5 * len(run.stamps)
            assert (ats[-1].encoding, sel[-1].encoding, ats[-1].width) == ("mono8", "rgb8", 80)
        ate, ref = _ate(run, gt), _inline_over_the_same_frames(bag, run.stamps, gt)
        d = run.diag
        keys = ("queue_drops", "keyframes", "mapping", "mapping_timeouts", "mapping_round_trip_ms", "worker_ms_mean",
                "worker_cpu_ms_mean")
        why = (ate, ref, metrics["ate_rmse_m"], {k: d[k] for k in keys if k in d},
               {s: run.statuses.count(s) for s in set(run.statuses)})
        if ate <= max(1.5 * ref, ref + 0.005):
            return
        if attempt == 1:
            warnings.warn(f"asynchronous run over the bound (ATE, same-frames replay, full replay, diag, statuses: "
                          f"{why}); running once more", stacklevel=2)
    raise AssertionError(why)


def test_atsvo_play_feeds_a_running_node_and_records_its_odometry(sequence, tmp_path):
    """The no-ROS-install way: atsvo_node in one process, atsvo-play BAG --reliable --tum in another (same domain).

    Both ends in the node's loss-free mode (reliable inputs, ``mapping.synchronous``), as the README tells a user who
    wants every frame: then the recorded odometry is one pose per frame and the replay's poses, whatever the load
    (best effort at real rate answered 66-91 of 91 frames here, at half rate 67: the node keeps the newest frame).
    """
    bag, replay, *_ = sequence
    procs = NodeProcesses(["atsvo_node"], ["--ros-args", "--params-file", str(PARAMS),
                                           "-p", "node.sensor_qos:=reliable", "-p", "mapping.synchronous:=true"],
                          tmp_path / "logs")
    try:
        done = subprocess.run([console_script("atsvo-play"), str(bag), "--config", "synthetic", "--reliable", "--tum",
                               str(tmp_path / "odom.tum"), "--wait-s", str(START_TIMEOUT_S)],
                              capture_output=True, text=True, timeout=300)
    finally:
        codes = procs.stop()
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"{len(replay.stamps_ns)} odometry received" in done.stdout and codes == [0], (done.stdout, codes)
    got = read_tum(tmp_path / "odom.tum")
    assert got.stamps_ns.tolist() == replay.stamps_ns.tolist()
    dp = np.linalg.norm(got.T_w_b[:, :3, 3] - replay.T_w_b[:, :3, 3], axis=1)
    assert dp.max() < 1e-3, dp.max()  # TUM text keeps 4-9 digits; the poses are the replay's


def test_a_bad_parameter_file_stops_the_node_with_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**:\n  ros__parameters:\n    tracker:\n      max_iterations: 500\n")
    for script in ("atsvo_node", "tracking_node", "mapping_node"):
        done = subprocess.run([console_script(script), "--ros-args", "--params-file", str(bad)], capture_output=True,
                              text=True, timeout=120)
        lines = [ln for ln in (done.stdout + done.stderr).splitlines() if ln.strip()]
        assert done.returncode == 1, (script, done.stdout, done.stderr)
        assert len(lines) == 1 and "tracker.max_iterations = 500" in lines[0] and "[1, 200]" in lines[0], lines


def test_without_event_messages_the_node_says_so_once_and_runs_rgbd(tmp_path):
    """The pip route without the built event messages: one line, then RGB-D (here: it starts and stops cleanly)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in env.get("PYTHONPATH", "").split(os.pathsep)
                                        if "ros_msgs" not in p)
    proc = subprocess.Popen([console_script("tracking_node"), "--ros-args", "--params-file", str(PARAMS)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline and not any("tracking: mode" in ln for ln in lines):
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
    proc.send_signal(signal.SIGINT)
    rest, _ = proc.communicate(timeout=30)
    warn = [ln for ln in lines if "event_camera_msgs" in ln and "RGB-D only" in ln]
    assert len(warn) == 1 and "not installed" in warn[0], lines
    assert any("tracking: mode rgbd" in ln for ln in lines) and proc.returncode == 0, (lines, rest)
