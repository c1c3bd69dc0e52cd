"""CPU priority of the node process: every thread of it, before the odometry's threads start (Linux; ROS-free).

On a robot the odometry shares the computer with other software. Under Linux's fair scheduler a busy process
beside the node takes its share of a core whatever the node needs, and the node's frames queue and drop
(docs/nodes.md: one CPU hog beside the RGB-D node on 2 cores, 68-88 % of frames answered). What robot stacks do
is give the estimator a higher priority than the best-effort work: a lower nice value (a larger CFS weight: nice
-10 weighs 9.3x nice 0) or a real-time policy (SCHED_RR: runs before every normal thread; the kernel's RT
throttling still leaves 5 % to the others). Both need privileges (root, ``CAP_SYS_NICE``, or ``nice`` / ``rtprio``
limits in ``/etc/security/limits.conf``).

Linux keeps nice values and policies per thread, and a new thread inherits its creator's; so this is applied to
every thread that exists (the DDS threads rclpy started) and, called before the node starts its own, reaches
those too.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class PriorityResult:
    """What was asked and what took: ``applied`` False with ``why`` when the system refused."""

    nice: int
    realtime_priority: int
    applied: bool
    threads: int
    why: str = ""

    def describe(self) -> str:
        """One line for the node's log."""
        asked = ", ".join(p for p in (f"nice {self.nice}" if self.nice else "",
                                      f"SCHED_RR {self.realtime_priority}" if self.realtime_priority else "") if p)
        if self.applied:
            return f"CPU priority: {asked} on {self.threads} thread(s)"
        return (f"CPU priority: {asked} not applied ({self.why}); running at the priority the process was started "
                "with (needs root, CAP_SYS_NICE, or nice / rtprio limits in /etc/security/limits.conf)")


def _thread_ids() -> list[int]:
    """This process's thread ids (Linux ``/proc/self/task``); just the calling thread elsewhere."""
    tasks = Path("/proc/self/task")
    if tasks.is_dir():
        return sorted(int(p.name) for p in tasks.iterdir() if p.name.isdigit())
    return [0]


def raise_cpu_priority(nice: int = 0, realtime_priority: int = 0) -> PriorityResult | None:
    """Set ``nice`` (when not 0) and SCHED_RR at ``realtime_priority`` (when not 0) on every thread of this process.

    Returns None when nothing was asked. A refusal (no permission, no such policy on this system) is reported in
    the result, not raised: the node runs on at its normal priority and says so in one line. A thread that ends
    while this runs is skipped.
    """
    if nice == 0 and realtime_priority == 0:
        return None
    tids = _thread_ids()
    done = 0
    try:
        for tid in tids:
            try:
                if nice:
                    os.setpriority(os.PRIO_PROCESS, tid, nice)
                if realtime_priority:
                    os.sched_setscheduler(tid, os.SCHED_RR, os.sched_param(realtime_priority))
            except ProcessLookupError:  # the thread ended meanwhile
                continue
            done += 1
    except (AttributeError, OSError) as exc:  # a refusal (PermissionError); AttributeError: no SCHED_RR here
        return PriorityResult(nice, realtime_priority, False, done, why=str(exc) or type(exc).__name__)
    return PriorityResult(nice, realtime_priority, True, done)


__all__ = ["PriorityResult", "raise_cpu_priority"]
