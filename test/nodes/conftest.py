"""DDS hygiene for the node tests: discovery on loopback only, a private domain id per session.

Fast DDS's default discovery (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET) multicasts to 239.255.0.1 out of
every interface; LOCALHOST keeps all traffic on this machine. A random domain id keeps concurrent
runs on one machine (other worktrees, CI) from seeing each other's topics. Values set by the caller
(e.g. .ci/ros_env.sh) are kept.
"""
from __future__ import annotations

import os
import random

import pytest


@pytest.fixture(autouse=True, scope="session")
def _ros_env_on_loopback():
    saved = {k: os.environ.get(k) for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID")}
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    yield
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
