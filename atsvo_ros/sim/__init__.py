"""Synthetic legged-robot sequences: scenes, gaits, RGB-D and event sensor models, bag writer.

The in-memory API (:mod:`atsvo_ros.sim.sequence`) feeds tests and accuracy runs; ``atsvo-sim``
writes the same data as a ROS 1 / ROS 2 bag with the robot's (or MVSEC's) topics.
"""
from __future__ import annotations

from atsvo_ros.sim.sequence import SequenceSpec, Simulation, iter_sequence, make_simulation
from atsvo_ros.sim.writer import write_sequence

__all__ = ["SequenceSpec", "Simulation", "iter_sequence", "make_simulation", "write_sequence"]
