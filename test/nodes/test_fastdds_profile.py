"""config/fastdds_shm.xml: a valid Fast DDS profile that gives each process a 64 MiB shared-memory segment and a
receiving port queue that holds seconds of the robot's topics."""
from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PROFILE = ROOT / "config" / "fastdds_shm.xml"
NS = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
RGB8_640x480_BYTES = 640 * 480 * 3


def test_profile_is_the_default_participant_with_a_large_shm_segment_and_udp():
    root = ET.parse(PROFILE).getroot()
    descriptors = {d.findtext("f:transport_id", namespaces=NS): d
                   for d in root.iterfind("f:profiles/f:transport_descriptors/f:transport_descriptor", NS)}
    kinds = {tid: d.findtext("f:type", namespaces=NS) for tid, d in descriptors.items()}
    assert sorted(kinds.values()) == ["SHM", "UDPv4"]  # same host via SHM, other hosts still via UDP
    shm = next(d for d in descriptors.values() if d.findtext("f:type", namespaces=NS) == "SHM")
    assert int(shm.findtext("f:segment_size", namespaces=NS)) >= 16 * RGB8_640x480_BYTES
    # ~1,300 messages/s on the robot (1 kHz event packets, 200 Hz IMU, images): a stalled node must not overflow
    assert int(shm.findtext("f:port_queue_capacity", namespaces=NS)) >= 4 * 1300
    participant = root.find("f:profiles/f:participant", NS)
    assert participant.get("is_default_profile") == "true"
    used = [t.text for t in participant.iterfind("f:rtps/f:userTransports/f:transport_id", NS)]
    assert sorted(used) == sorted(descriptors)
    assert participant.findtext("f:rtps/f:useBuiltinTransports", namespaces=NS) == "false"


SEGMENTS = """
import rclpy
rclpy.init()
node = rclpy.create_node("profile_check")
sizes = []
with open("/proc/self/maps") as maps:
    for line in maps:
        path = line.split()[-1]
        if path.startswith("/dev/shm/fastrtps_") and "port" not in path:
            lo, hi = line.split()[0].split("-")
            sizes.append(int(hi, 16) - int(lo, 16))
print(max(sizes, default=0))
node.destroy_node()
rclpy.shutdown()
"""


def _largest_shm_segment(profile: Path | None) -> tuple[int, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE", "ROS_STATIC_PEERS")}
    # No discovery: a participant maps the segment of every peer it hears from over shared memory, and a peer's
    # 64 MiB segment (our profile; which peer is not known) twice showed up as the default's largest in CI with the
    # suite on two workers. Alone, the largest segment it maps is its own.
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "OFF"
    if profile is not None:
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile)
    out = subprocess.run([sys.executable, "-c", SEGMENTS], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return int(out.stdout.split()[-1]), out.stderr


def test_fast_dds_loads_the_profile_through_fastrtps_default_profiles_file():
    pytest.importorskip("rclpy", reason="rclpy is not installed (pip install -e '.[ros]')")
    if not Path("/proc/self/maps").is_file():
        pytest.skip("needs Linux /proc to see the shared-memory segments")
    default_size, _ = _largest_shm_segment(None)
    ours_size, stderr = _largest_shm_segment(PROFILE)
    assert "XMLPARSER Error" not in stderr, stderr
    assert default_size < RGB8_640x480_BYTES  # Fast DDS default (512 KiB): a colour frame does not fit
    assert ours_size >= 16 * 2**20
    # The port queue's size is not checked here: a port is a file in /dev/shm shared by every process of the
    # domain, sized by whichever process created it first (measured on fresh ports: 204 KiB with the profile,
    # 52 KiB without; a later run without the profile opened the 204 KiB ones).
