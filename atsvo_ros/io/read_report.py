"""Reading recordings past corrupt records, and saying what was lost.

rosbags stops a message iterator at the first record it cannot read (``ReaderError``, a failed
assertion, an sqlite ``CorruptError``, a decompression error, even a ``MemoryError`` for a garbage
length field) and, for some damage (an overwritten mcap chunk), silently yields fewer messages.
:func:`iter_messages` resumes after an unreadable record (by time, just past the last message
read, stepping further while the same region keeps failing) and :class:`ReadReport` counts, per
topic, what the index promised, what was read and what could not be decoded, so the loss is
reported instead of changing results quietly.
"""
from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from rosbags.highlevel import AnyReaderError
from rosbags.rosbag1 import ReaderError as Reader1Error
from rosbags.rosbag2 import ReaderError as Reader2Error
from rosbags.serde import SerdeError
from rosbags.typesys import TypesysError

#: most errors kept verbatim in a report (the count goes on)
MAX_ERRORS = 20


def container_errors() -> tuple[type[BaseException], ...]:
    """Exception types rosbags and its storage libraries raise on damaged files.

    Only ever caught around calls into those libraries, never around our own code.
    """

    errors: list[type[BaseException]] = [AnyReaderError, Reader1Error, Reader2Error, TypesysError,
                                         AssertionError, KeyError, IndexError, ValueError, struct.error, EOFError,
                                         OSError, OverflowError, MemoryError,
                                         RuntimeError]  # lz4 raises RuntimeError
    try:
        import apsw

        errors.append(apsw.Error)
    except ImportError:  # pragma: no cover - rosbags' sqlite3 storage needs it
        pass
    try:
        import zstandard

        errors.append(zstandard.ZstdError)
    except ImportError:  # pragma: no cover
        pass
    errors.append(SerdeError)
    return tuple(errors)


def describe(exc: BaseException, limit: int = 300) -> str:
    """One line naming the exception type and a reason, never empty."""
    if isinstance(exc, MemoryError):
        return "MemoryError: a length field asks for more memory than there is (the file is probably corrupt)"
    text = " ".join(str(exc).split())
    if isinstance(exc, UnicodeDecodeError):
        text = f"bytes that are not UTF-8 text where text was expected ({text})"
    elif isinstance(exc, AssertionError) and not text:
        text = "a record failed the reader's consistency check (corrupt data)"
    elif not text:
        text = "(no message)"
    line = f"{type(exc).__name__}: {text}"
    return line if len(line) <= limit else line[: limit - 3] + "..."


@dataclass
class TopicCounts:
    """What one topic should have had and what was actually delivered."""

    topic: str
    role: str = ""
    expected: int | None = None   # from the bag's index / metadata (None: unknown)
    read: int = 0                 # records the container delivered
    undecodable: int = 0          # delivered but could not be decoded / deserialized

    @property
    def skipped(self) -> int:
        """Records the index lists but the container did not deliver (unreadable or silently lost)."""
        return max(0, self.expected - self.read) if self.expected is not None else 0

    def as_dict(self) -> dict[str, Any]:
        return {"role": self.role, "expected": self.expected, "read": self.read, "skipped": self.skipped,
                "undecodable": self.undecodable}


@dataclass
class ReadReport:
    """Per-topic counts and the read errors of one pass over a recording."""

    path: str
    topics: dict[str, TopicCounts] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    n_errors: int = 0
    stopped: str | None = None    # why reading ended before the end, if it did
    finished: bool = False        # the pass reached its end (counts of skipped records are final)

    def add_error(self, text: str) -> None:
        self.n_errors += 1
        if len(self.errors) < MAX_ERRORS:
            self.errors.append(text)

    def topic(self, name: str) -> TopicCounts:
        if name not in self.topics:
            self.topics[name] = TopicCounts(name)
        return self.topics[name]

    @property
    def skipped(self) -> int:
        return sum(c.skipped for c in self.topics.values())

    @property
    def undecodable(self) -> int:
        return sum(c.undecodable for c in self.topics.values())

    @property
    def clean(self) -> bool:
        """Nothing skipped, nothing undecodable, no read error."""
        return not (self.n_errors or self.skipped or self.undecodable or self.stopped)

    def summary(self) -> str:
        """One line: what was lost, per topic (role), and the first error."""
        if self.clean:
            return f"{self.path}: every record read"
        parts = []
        for c in self.topics.values():
            bits = []
            if c.skipped:
                bits.append(f"{c.skipped} of {c.expected} unreadable")
            if c.undecodable:
                bits.append(f"{c.undecodable} undecodable")
            if bits:
                parts.append(f"{c.topic}{f' ({c.role})' if c.role else ''}: {', '.join(bits)}")
        text = f"{self.path}: " + ("; ".join(parts) if parts else "records lost")
        if self.n_errors:
            text += f"; {self.n_errors} read error(s), first: {self.errors[0]}"
        if self.stopped:
            text += f"; stopped early: {self.stopped}"
        return text

    def as_dict(self) -> dict[str, Any]:
        return {"path": self.path, "clean": self.clean, "skipped": self.skipped, "undecodable": self.undecodable,
                "n_errors": self.n_errors, "errors": list(self.errors), "stopped": self.stopped,
                "topics": {t: c.as_dict() for t, c in self.topics.items()}}


def iter_messages(reader: Any, connections: list[Any], report: ReadReport, max_restarts: int = 1000,
                  ) -> Iterator[tuple[Any, int, Any]]:
    """``reader.messages(connections)`` that goes on after unreadable records, counting in ``report``.

    After a read error it restarts just past the last message read (``start = t + 1``); while a
    restart fails again before yielding anything, the start moves on by doubling steps (1, 2, 4 ns,
    ...), so it gets past a bad record after about log2(distance) restarts and overshoots by less
    than the distance from the last good message to the bad one (a readable message right after a
    bad one can be lost when messages are unevenly spaced). Whatever is not read shows as
    ``skipped`` (index count minus read) once the pass has finished, so the report is exact.
    """
    errors = container_errors()
    expected: dict[str, int | None] = {}
    for c in connections:
        n = getattr(c, "msgcount", None)
        before = expected.get(c.topic, 0)
        expected[c.topic] = None if n is None or before is None else before + int(n)
    for topic, n in expected.items():
        report.topic(topic).expected = n
    end_ns = int(getattr(reader, "end_time", 0) or 0)
    start: int | None = None
    last_t: int | None = None
    step = 1
    restarts = 0
    while True:
        progressed = False
        try:
            it = reader.messages(connections=connections, start=start)
            for conn, t_ns, raw in it:
                progressed = True
                last_t = t_ns
                report.topic(conn.topic).read += 1
                yield conn, t_ns, raw
            report.finished = True
            return
        except errors as exc:
            where = f"after t={last_t * 1e-9:.6f} s" if last_t is not None else "before the first message"
            report.add_error(f"{where}: {describe(exc)}")
        restarts += 1
        if restarts > max_restarts:
            report.stopped = f"gave up after {max_restarts} restarts past unreadable records"
            return
        if progressed or start is None:
            step = 1
            start = (last_t if last_t is not None else int(getattr(reader, "start_time", 0) or 0) - 1) + 1
        else:
            start += step
            step *= 2
        if end_ns and start > end_ns:
            report.finished = True
            return
