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
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
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
        "test": [
            "pytest>=7",
            "ruff>=0.4",
            "hypothesis>=6.80",  # property-based tests of the decoders and SE(3) utilities
            "aedat>=2.0",
            "h5py>=3.8",
            "evo>=1.20",
            "dv-processing>=2.0",
        ],
    },
    zip_safe=True,
    maintainer="atsvo_ros team",
    maintainer_email="atsvo@example.com",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "atsvo-info = atsvo_ros.tools.info:main",
            # ROS 2 executables (`ros2 run atsvo_ros tracking_node`); need rclpy at run time.
            "tracking_node = atsvo_ros.nodes.tracking_node:main",
            "atsvo-replay = atsvo_ros.tools.replay:main",
            "atsvo-eval = atsvo_ros.tools.eval:main",
            "atsvo-demo = atsvo_ros.tools.demo:main",
            "atsvo-sim = atsvo_ros.tools.sim:main",
            "atsvo-events = atsvo_ros.tools.events:main",
            "atsvo-bench = atsvo_ros.tools.bench:main",
        ],
    },
)
