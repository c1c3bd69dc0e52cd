"""node.nice / node.realtime_priority: applied to every thread of the process, or refused in one clear line."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from atsvo_ros.runtime.cpu_priority import PriorityResult, raise_cpu_priority


def test_nothing_asked_changes_nothing():
    assert raise_cpu_priority(0, 0) is None


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread priorities are Linux's")
def test_every_thread_gets_the_nice_value_and_threads_started_later_inherit_it():
    # in a child process (a nice value cannot be taken back without privileges); raising it needs none
    target = min(19, os.getpriority(os.PRIO_PROCESS, 0) + 3)
    code = textwrap.dedent(f"""
        import os, threading
        from atsvo_ros.runtime.cpu_priority import raise_cpu_priority
        ready, stop = threading.Event(), threading.Event()
        seen = {{}}
        def before():
            ready.set(); stop.wait(); seen["before"] = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
        t = threading.Thread(target=before); t.start(); ready.wait()
        r = raise_cpu_priority({target}, 0)
        def after():
            seen["after"] = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
        u = threading.Thread(target=after); u.start(); u.join()
        stop.set(); t.join()
        print(r.applied, r.threads, seen["before"], seen["after"], os.getpriority(os.PRIO_PROCESS, 0))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}).stdout.split()
    assert out[0] == "True" and int(out[1]) >= 2
    assert [int(v) for v in out[2:]] == [target] * 3  # the running thread, the one before, the one after


def test_a_refusal_is_reported_not_raised(monkeypatch):
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "setpriority", refuse)
    r = raise_cpu_priority(-10, 0)
    assert isinstance(r, PriorityResult) and not r.applied
    line = r.describe()
    assert "nice -10 not applied" in line and "Operation not permitted" in line and "CAP_SYS_NICE" in line
