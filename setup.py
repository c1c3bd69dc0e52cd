"""Packaging for atsvo_ros: an ament_python ROS 2 package that also installs with plain pip."""
from __future__ import annotations

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "atsvo_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    description="Event + RGB-D direct visual odometry for agile legged robots (adaptive time surface)",
    long_description=open("README.md", encoding="utf-8").read(),
    long_description_content_type="text/markdown",
    license="Apache-2.0",
    python_requires=">=3.10",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        # Node parameters, the Fast DDS profile for camera-sized images (config/fastdds_shm.xml) and the
        # Foxglove layout for `atsvo-replay --record` bags (config/foxglove_layout.json).
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml")) + ["config/fastdds_shm.xml",
                                                                      "config/foxglove_layout.json"]),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    package_data={PACKAGE: ["config/*.yaml"]},
    include_package_data=True,
    install_requires=[
        "setuptools",
        "numpy>=1.24",
        "numba>=0.58",
        "opencv-python-headless>=4.8",
        "rosbags>=0.11",  # reads bare .mcap/.db3 files
        "pyyaml>=6",
        "matplotlib>=3.7",
        "tqdm>=4.60",
    ],
    extras_require={
        # AEDAT4 files (DVXplorer's own format).
        "aedat": ["aedat>=2.0"],
        # MVSEC HDF5 files.
        "mvsec": ["h5py>=3.8"],
        # Cross-checking metrics against evo (GPL-3.0: optional, evaluation only).
        "eval": ["evo>=1.20"],
        # Benchmarks against iniVation's C++ library (atsvo-bench events).
        "bench": ["dv-processing>=2.0"],
        # Peer RGB-D odometry on the same frames (atsvo-bench real, atsvo_ros.eval.peers). Not in "test":
        # the wheel is ~400 MB and its import needs the system library libusb-1.0 (Debian: libusb-1.0-0);
        # the lighter open3d-cpu wheel (~105 MB) provides the same module.
        "peers": ["open3d>=0.18"],
        # ORB-SLAM3 RGB-D as a peer (atsvo-bench real --orbslam3; GPL-3.0, evaluation only, never imported by
        # the odometry). Its manylinux wheel carries ORB-SLAM3 and its libraries; the ORB vocabulary it would
        # download is trained here instead (atsvo_ros.eval.orb_vocabulary).
        "orbslam3": ["pyorbslam3>=0.1.1"],
        # ROS 2 Jazzy's rclpy + messages as wheels from the package index (Fast DDS; CI and laptops). They
        # exist for CPython 3.11 on x86_64 Linux only; elsewhere (the robot's apt Jazzy on Python 3.12) the
        # extra installs nothing and the system's rclpy is used. No wheel exists for tf2_ros,
        # message_filters or launch. See docs/ros_env.md.
        "ros": [
            f"{name}; python_version == '3.11' and platform_machine == 'x86_64' and sys_platform == 'linux'"
            for name in (
                "ros-jazzy-rclpy==7.1.6",
                "ros-jazzy-rmw-fastrtps-cpp==8.4.3",
                "ros-jazzy-std-msgs==5.3.6",
                "ros-jazzy-std-srvs==5.3.6",
                "ros-jazzy-geometry-msgs==5.3.6",
                "ros-jazzy-sensor-msgs==5.3.6",
                "ros-jazzy-nav-msgs==5.3.6",
                "ros-jazzy-diagnostic-msgs==5.3.6",
            )
        ],
        "test": [
            "pytest>=7",
            "pytest-xdist>=3.5",  # the suite on every core (setup.cfg: -n auto, at most 4 workers)
            "pytest-timeout>=2.2",  # a test that hangs fails with every thread's stack (setup.cfg: timeout)
            "ruff>=0.4",
            "hypothesis>=6.80",  # property-based tests of the decoders and SE(3) utilities
            "aedat>=2.0",
            "h5py>=3.8",
            "evo>=1.20",
            "dv-processing>=2.0",
            "mcap-ros2-support>=0.5",  # reads --record bags as Foxglove does: by the schemas inside the file
            # ORB-SLAM3 tracks real frames with a vocabulary trained here (test/eval/test_orbslam3.py)
            "pyorbslam3>=0.1.1; platform_machine == 'x86_64' and sys_platform == 'linux'",
        ],
    },
    zip_safe=True,
    maintainer="atsvo_ros team",
    maintainer_email="atsvo@example.com",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "atsvo-info = atsvo_ros.tools.info:main",
            # ROS 2 executables (`ros2 run atsvo_ros atsvo_node`); need rclpy at run time (the `ros` extra).
            "atsvo_node = atsvo_ros.nodes.atsvo_node:main",
            "tracking_node = atsvo_ros.nodes.tracking_node:main",
            "mapping_node = atsvo_ros.nodes.mapping_node:main",
            "atsvo-replay = atsvo_ros.tools.replay:main",
            "atsvo-eval = atsvo_ros.tools.eval:main",
            "atsvo-demo = atsvo_ros.tools.demo:main",
            "atsvo-sim = atsvo_ros.tools.sim:main",
            "atsvo-events = atsvo_ros.tools.events:main",
            "atsvo-bench = atsvo_ros.bench.cli:main",
            "atsvo-play = atsvo_ros.nodes.play:main",
        ],
    },
)
