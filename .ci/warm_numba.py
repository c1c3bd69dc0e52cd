"""Compile the numba kernels the test suite uses into numba's on-disk cache, once, before pytest starts.

Every pytest-xdist worker would otherwise compile the same kernels itself on a clean clone (~60-90 s each on two
cores, both cores busy); run in the background while CI installs the test extra, the workers then load them.
Covers the odometry (RGB-D and fused, the event decoders) through the nodes' warm-up and the simulator (render,
active stereo, colour and event sensors, IMU) through a short sequence. A kernel missed here is compiled by
whichever test uses it first, as before: this only saves time.
"""
from __future__ import annotations

import sys
import time

from atsvo_ros.config import load_config
from atsvo_ros.runtime.warmup import warm_up
from atsvo_ros.sim.sequence import SequenceSpec, iter_sequence


def main() -> int:
    t0 = time.perf_counter()
    warm_up(load_config("synthetic"))
    t1 = time.perf_counter()
    n = sum(1 for _ in iter_sequence(SequenceSpec(scenario="trot", duration_s=0.2, seed=0, width=160, height=120)))
    print(f"warm_numba: odometry {t1 - t0:.0f} s, simulator {time.perf_counter() - t1:.0f} s ({n} items)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
