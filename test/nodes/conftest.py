"""DDS hygiene for the node tests: discovery on loopback only, a private domain id per session.

With ``ATSVO_REQUIRE_ROS=1`` (set by .ci/run) a missing rclpy or message package is an error, not a
skip: CI must run these tests.

Fast DDS's default discovery (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET) multicasts to 239.255.0.1 out of
every interface; LOCALHOST keeps all traffic on this machine (a discovery range set by the caller is
kept). The session (each pytest-xdist worker) always takes a random domain id of its own, whatever the
shell has: concurrent runs on one machine (other worktrees, CI, the other workers) and a user's own nodes
on the shell's domain never see the tests' topics. ``ATSVO_TEST_ROS_DOMAIN_ID`` pins it (to watch a test's
topics from another shell).
"""
from __future__ import annotations

import os
import random

import pytest

if os.environ.get("ATSVO_REQUIRE_ROS") == "1":
    import event_camera_msgs.msg  # noqa: F401  (.ci/build_ros_msgs.sh)
    import rclpy  # noqa: F401  (the `ros` extra)
    import tf2_msgs.msg  # noqa: F401


@pytest.fixture(autouse=True, scope="session")
def _ros_env_on_loopback():
    saved = {k: os.environ.get(k) for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID")}
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    # pytest-xdist workers (gw0, gw1, ...) take consecutive domains from one random base (the run's id seeds it):
    # one worker's nodes never discover another's
    worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:] or 0)
    base = random.Random(os.environ.get("PYTEST_XDIST_TESTRUNUID")).randint(1, 90)
    os.environ["ROS_DOMAIN_ID"] = os.environ.get("ATSVO_TEST_ROS_DOMAIN_ID") or str(base + worker)
    yield
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
