"""A bounded drop-oldest queue and the worker thread that drains it (ROS-free; used by the nodes).

Sensor callbacks must return at once, so the tracking node puts each complete frame into a
:class:`DropOldestQueue` and a :class:`Worker` runs the odometry on it. When the tracker falls behind
(a slow frame, a burst of input) the queue is full and the *oldest* frame is dropped, so the
published pose stays as fresh as possible and latency stays bounded by the queue length; every drop
is counted. A ``merge`` function lets the dropped item hand what must not be lost (the events and IMU
samples of a frame) to the next one.
"""
from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")


class DropOldestQueue(Generic[T]):
    """Bounded FIFO between producer threads and one consumer; a put into a full queue drops the oldest item."""

    def __init__(self, maxsize: int, merge: Callable[[T, T], T] | None = None) -> None:
        """``merge(dropped, next_oldest)`` returns what replaces ``next_oldest`` when ``dropped`` is dropped."""
        if maxsize < 1:
            raise ValueError(f"maxsize must be at least 1, got {maxsize}")
        self.maxsize = int(maxsize)
        self._merge = merge
        self._items: deque[T] = deque()
        self._cond = threading.Condition()
        self._closed = False
        #: items put, items dropped (oldest first), the most items ever waiting
        self.n_put = 0
        self.n_dropped = 0
        self.high_water = 0

    def __len__(self) -> int:
        with self._cond:
            return len(self._items)

    def put(self, item: T) -> int:
        """Append ``item``; returns how many items were dropped to make room (0 or 1)."""
        with self._cond:
            if self._closed:
                return 0
            self._items.append(item)
            self.n_put += 1
            dropped = 0
            while len(self._items) > self.maxsize:
                old = self._items.popleft()
                if self._merge is not None:
                    self._items[0] = self._merge(old, self._items[0])
                dropped += 1
            self.n_dropped += dropped
            self.high_water = max(self.high_water, len(self._items))
            self._cond.notify()
            return dropped

    def get(self, timeout: float | None = None) -> T | None:
        """The oldest item; None when the queue is closed and empty, or after ``timeout`` seconds without one."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._items or self._closed, timeout):
                return None
            return self._items.popleft() if self._items else None

    def close(self) -> None:
        """Wake the consumer; items still queued are dropped (not counted) and later puts are ignored."""
        with self._cond:
            self._closed = True
            self._items.clear()
            self._cond.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed


class Worker(Generic[T]):
    """A thread that hands each item of a :class:`DropOldestQueue` to ``handle``, in order.

    :meth:`call` runs a function in the worker's thread before the next item (e.g. a reset that must
    not race with the item being processed). An exception escaping ``handle`` is a bug: it ends the
    worker and goes to ``on_error`` (the node logs it and shuts down), it is never swallowed.
    """

    def __init__(self, queue: DropOldestQueue[T], handle: Callable[[T], None], name: str = "atsvo-worker",
                 on_error: Callable[[BaseException], None] | None = None) -> None:
        self.queue = queue
        self._handle = handle
        self._on_error = on_error
        self._calls: deque[tuple[Callable[[], object], threading.Event]] = deque()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.error: BaseException | None = None

    def start(self) -> None:
        self._thread.start()

    def call(self, fn: Callable[[], object]) -> threading.Event:
        """Run ``fn`` in the worker thread before the next item; the returned event is set when it ran.

        After the worker has ended (stopped, or a bug), ``fn`` does not run and the event is set at once.
        """
        done = threading.Event()
        if self._thread.ident is not None and not self._thread.is_alive():
            done.set()
            return done
        self._calls.append((fn, done))
        with self.queue._cond:  # wake the worker if it waits for an item
            self.queue._cond.notify_all()
        return done

    def stop(self, timeout: float = 5.0) -> None:
        """Close the queue and wait (up to ``timeout``) for the item in progress to finish."""
        self.queue.close()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _run_calls(self) -> None:
        while self._calls:
            fn, done = self._calls.popleft()
            try:
                fn()
            finally:
                done.set()

    def _run(self) -> None:
        try:
            while True:
                self._run_calls()
                with self.queue._cond:
                    self.queue._cond.wait_for(lambda: self.queue._items or self.queue._closed or self._calls)
                if self._calls:
                    continue
                item = self.queue.get(timeout=0.0)
                if item is None:
                    if self.queue.closed:
                        return
                    continue
                self._handle(item)
        except BaseException as exc:  # a bug in the handler: reported, never swallowed
            self.error = exc
            if self._on_error is not None:
                self._on_error(exc)
        finally:
            # nobody may wait forever for a call that will not run
            for _, done in self._calls:
                done.set()


__all__ = ["DropOldestQueue", "Worker"]
