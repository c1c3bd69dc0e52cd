"""LateKernels: the node names every numba kernel compiled after its warm-up (a frame stalled for it)."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import types

from atsvo_ros.runtime.kernel_watch import LateKernels, kernel_signatures


def test_a_kernel_compiled_after_ready_is_named_once(monkeypatch):
    module = types.ModuleType("kwatch_probe")
    exec(textwrap.dedent("""
        from numba import njit
        @njit
        def twice(x):
            return 2 * x
    """), module.__dict__)
    monkeypatch.setitem(sys.modules, "kwatch_probe", module)
    module.twice(1)
    watch = LateKernels("kwatch_probe")
    assert watch.new() == [] and watch.count == 0
    module.twice(2)  # the same signature: nothing compiled
    assert watch.new() == []
    module.twice(2.5)  # float64: a second signature
    assert watch.new() == ["kwatch_probe.twice"] and watch.count == 1
    module.twice(1j)
    assert watch.new() == [] and watch.count == 1  # named once
    assert kernel_signatures("kwatch_probe") == {"kwatch_probe.twice": 3}


def test_the_warm_up_covers_a_fused_replay(trot_1s_bags, tmp_path):
    """In a fresh process (no kernel compiled by other tests): after the nodes' warm-up, replaying a simulated trot
    (events, IMU, keyframes) compiles nothing more."""
    code = textwrap.dedent(f"""
        from atsvo_ros.config import load_config
        from atsvo_ros.runtime.kernel_watch import LateKernels
        from atsvo_ros.runtime.warmup import warm_up
        from atsvo_ros.tools.replay import replay
        cfg = load_config("synthetic")
        warm_up(cfg)
        watch = LateKernels()
        res = replay({str(trot_1s_bags["mcap"])!r}, {str(tmp_path / "out")!r}, cfg, plots=False, progress=False)
        assert set(res.statuses) <= {{"initialising", "ok"}}, res.statuses
        print("LATE", ",".join(watch.new()))
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert run.returncode == 0, run.stderr[-3000:]
    late = [line for line in run.stdout.splitlines() if line.startswith("LATE")]
    assert late == ["LATE "], late
