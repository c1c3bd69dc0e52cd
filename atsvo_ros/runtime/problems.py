"""Counting and rate-limited logging of the runtime's problems (bad input is counted, never fatal).

Every part of the runtime (event ingest, the IMU gate and frame release, the per-frame pipeline) reports
what it skipped through one :class:`ProblemLog`, so there is a single set of counters
(:attr:`OdometryRuntime.counters <atsvo_ros.runtime.runtime.OdometryRuntime.counters>`) and a single
rate limit per kind of problem, whichever thread (ingest or worker) reports it.
"""
from __future__ import annotations

import threading
import time
from collections import Counter

from atsvo_ros.runtime.types import Logger


def _no_log(level: str, text: str) -> None:
    del level, text


class ProblemLog:
    """Counts problems by kind; logs the first of each kind, then at most every ``interval_s`` with the count.

    Attributes:
        counters: Problem counts by kind; the runtime also counts its ordinary statistics (frames,
            events, IMU samples, ...) here.
        first_problem: The first message of each kind of problem (what :attr:`counters` counts), for summaries.
    """

    def __init__(self, logger: Logger | None = None, interval_s: float = 10.0) -> None:
        """Create an empty log.

        Args:
            logger: Called as ``logger(level, text)``; None drops the messages (they are still counted).
            interval_s: The shortest time between two messages of the same kind.
        """
        self.counters: Counter[str] = Counter()
        self.first_problem: dict[str, str] = {}
        self._log = logger or _no_log
        self._interval_s = float(interval_s)
        self._last_logged: dict[str, float] = {}
        self._logged_count: Counter[str] = Counter()
        self._lock = threading.Lock()  # problems are reported from the ingest and the worker thread

    def report(self, kind: str, text: str, level: str = "warn", count: int = 1) -> None:
        """Count a problem; log the first of each kind, then at most every ``interval_s`` with the count.

        Args:
            kind: The counter to add to (e.g. ``"images_rejected"``).
            text: What happened, for the log and :attr:`first_problem`.
            level: ``"info"``, ``"warn"`` or ``"error"``.
            count: How many occurrences this report stands for.
        """
        with self._lock:
            self.counters[kind] += count
            self.first_problem.setdefault(kind, text)
            now = time.monotonic()
            last = self._last_logged.get(kind)
            if last is None or now - last >= self._interval_s:
                extra = self.counters[kind] - self._logged_count[kind] - count
                more = f" (+{extra} more since the last report)" if extra > 0 else ""
                self._log(level, f"{text}{more}")
                self._last_logged[kind] = now
                self._logged_count[kind] = self.counters[kind]


__all__ = ["ProblemLog"]
