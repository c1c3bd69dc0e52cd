"""Damaged recordings: read past unreadable records, count them per topic, report in one line.

The damage is made here from the real recordings (a record header overwritten in a ROS 1 chunk,
random bytes over an sqlite3 page and an mcap chunk, truncated / overwritten AEDAT4), so each test
reproduces a reported probe: before, these ended in a traceback (``ReaderError``,
``AssertionError``, ``apsw.CorruptError``, ``RuntimeError``) or in silently fewer messages.
"""
from __future__ import annotations

import json
import random
import struct
from pathlib import Path

import pytest

from atsvo_ros.errors import BagError
from atsvo_ros.io.event_files import open_events
from atsvo_ros.io.read_report import ReadReport, describe, iter_messages
from atsvo_ros.tools.events import main as events_main

BAGS = "event_camera_py_bags"


def _overwrite(src: Path, dst: Path, pos: int, data: bytes) -> Path:
    raw = bytearray(src.read_bytes())
    raw[pos:pos + len(data)] = data
    dst.write_bytes(bytes(raw))
    return dst


def _random_overwrite(src: Path, dst: Path, seed: int, size: int = 1000) -> Path:
    """``size`` random bytes at a random place in the middle half of the file (deterministic per seed)."""
    n = src.stat().st_size
    rng = random.Random(seed)
    pos = rng.randrange(n // 4, 3 * n // 4)
    return _overwrite(src, dst, pos, rng.randbytes(size))


def _ros1_with_broken_chunk(realdata: Path, tmp_path: Path) -> Path:
    from rosbags.rosbag1 import Reader

    src = realdata / BAGS / "test_events_1.bag"
    with Reader(src) as r:
        pos = r.chunks[r.chunk_infos[1].pos].datapos  # the first record header of the middle chunk
    return _overwrite(src, tmp_path / "broken.bag", pos, b"\xff" * 64)


def _stats(capsys, path: Path) -> tuple[int, str, list[str]]:
    rc = events_main(["stats", str(path)])
    out = capsys.readouterr()
    return rc, out.out, [line for line in out.err.splitlines() if "error" in line]


def test_ros1_chunk_with_a_broken_record_header(realdata, tmp_path, capsys):
    path = _ros1_with_broken_chunk(realdata, tmp_path)
    src = open_events(path, drop_backwards=False)
    b = src.read_all()
    rep = src.report
    counts = rep.topics["/event_camera/events"]
    assert counts.expected == 517 and 0 < counts.skipped < 20 and counts.read == 517 - counts.skipped
    assert rep.finished and rep.n_errors >= 1 and "ReaderError" in rep.errors[0]
    assert 300_000 < len(b) < 343_474  # the events of the readable records, not the whole file
    rc, out, err = _stats(capsys, path)
    assert rc == 1 and "events:" in out  # what could be read is printed ...
    assert len(err) == 1 and str(path) in err[0] and "/event_camera/events" in err[0]  # ... then one error line
    assert f"{counts.skipped} of 517 unreadable" in err[0]


def test_sqlite3_corrupt_page_mid_stream(realdata, tmp_path, capsys):
    # seed 10 puts 1000 random bytes on a b-tree page in the middle: apsw.CorruptError while reading
    path = _random_overwrite(realdata / BAGS / "test_events_1" / "test_events_1.db3", tmp_path / "broken.db3", 10)
    rc, out, err = _stats(capsys, path)
    assert rc == 1 and "events:" in out
    assert len(err) == 1 and "CorruptError" in err[0] and "unreadable" in err[0] and str(path) in err[0]


def test_mcap_chunk_overwritten_loses_messages_and_says_so(realdata, tmp_path, capsys):
    # seed 47: rosbags reads the damaged chunk without an error but delivers 3 messages fewer
    path = _random_overwrite(realdata / BAGS / "test_events_2" / "test_events_2_0.mcap", tmp_path / "broken.mcap", 47)
    src = open_events(path)
    src.read_all()
    assert src.report.topics["/event_camera/events"].skipped == 3 and src.report.n_errors == 0
    rc, _, err = _stats(capsys, path)
    assert rc == 1 and "3 of 100 unreadable" in err[0]


def test_intact_bag_reads_clean(realdata):
    src = open_events(realdata / BAGS / "test_events_2")
    src.read_all()
    assert src.report.clean and src.report.topics["/event_camera/events"].read == 100


@pytest.mark.parametrize("damage", ["truncate", "overwrite"])
def test_aedat4_damaged_mid_file(realdata, tmp_path, capsys, damage):
    pytest.importorskip("aedat", reason="the aedat package is not installed")
    src = realdata / "tonic_samples" / "sample.aedat4"
    data = src.read_bytes()
    path = tmp_path / "broken.aedat4"
    if damage == "truncate":
        path.write_bytes(data[: len(data) // 2])
    else:
        _overwrite(src, path, len(data) // 2, bytes(1000))
    rc, out, err = _stats(capsys, path)
    assert rc == 1 and "events:" in out
    assert len(err) == 1 and str(path) in err[0] and "RuntimeError" in err[0]
    if damage == "truncate":
        assert "ends early" in err[0]
    n = int(out.split("events:")[1].split("(")[0].replace(",", ""))
    assert 0 < n < 111_954


def test_unopenable_bag_is_one_line_naming_the_file(realdata, tmp_path, capsys):
    src = realdata / BAGS / "test_events_2" / "test_events_2_0.mcap"
    path = tmp_path / "cut.mcap"
    path.write_bytes(src.read_bytes()[:100_000])
    rc, out, err = _stats(capsys, path)
    assert rc == 1 and out == "" and len(err) == 1 and str(path) in err[0]


def test_memory_error_in_rosbags_gives_type_and_reason(realdata, tmp_path):
    """A huge length field in the mcap summary makes rosbags raise MemoryError (was: an empty reason)."""
    from atsvo_ros.io.bags import Bag

    raw = bytearray((realdata / BAGS / "test_events_2" / "test_events_2_0.mcap").read_bytes())
    footer = len(raw) - 8 - 29
    _, summary_start, _, _ = struct.unpack_from("<QQQI", raw, footer + 1)
    struct.pack_into("<Q", raw, summary_start + 1, 1 << 46)  # length of the first summary record
    path = tmp_path / "huge.mcap"
    path.write_bytes(bytes(raw))
    with pytest.raises(BagError) as info:
        Bag(path)
    msg = str(info.value)
    assert str(path) in msg and "MemoryError" in msg and "corrupt" in msg and "\n" not in msg


def test_describe_never_empty():
    assert describe(AssertionError()).startswith("AssertionError: ")
    assert len(describe(AssertionError())) > len("AssertionError: ")
    assert describe(KeyError(536870912)) == "KeyError: 536870912"
    assert "not UTF-8" in describe(b"\xf4".decode("utf-8", errors="strict") if False else
                                   UnicodeDecodeError("utf-8", b"\xf4", 0, 1, "invalid continuation byte"))


class _FlakyReader:
    """A reader whose messages fail at given times (like a corrupt chunk), supporting ``start``."""

    def __init__(self, times: list[int], bad: set[int]) -> None:
        self.times, self.bad = times, bad
        self.start_time, self.end_time = times[0], times[-1]

    def messages(self, connections, start=None):
        conn = connections[0]
        for t in self.times:
            if start is not None and t < start:
                continue
            if t in self.bad:
                raise AssertionError
            yield conn, t, b""


class _Conn:
    topic = "/x"
    msgcount = 100


def test_iter_messages_resumes_past_each_bad_record_and_counts():
    times = [1_000_000_000 + 1_000_000 * i for i in range(100)]  # 1 kHz
    bad = {times[i] for i in (10, 50, 99)}  # isolated bad records: every readable one is read
    report = ReadReport("flaky")
    got = [t for _, t, _ in iter_messages(_FlakyReader(times, bad), [_Conn()], report)]
    assert got == [t for t in times if t not in bad]  # nothing readable lost, nothing twice
    assert report.topics["/x"].skipped == len(bad) and report.finished
    assert report.n_errors >= 3 and not report.clean
    doc = report.as_dict()
    assert json.loads(json.dumps(doc))["topics"]["/x"] == {"role": "", "expected": 100, "read": 97, "skipped": 3,
                                                           "undecodable": 0}


def test_iter_messages_past_a_run_of_bad_records_counts_exactly():
    times = [1_000_000_000 + 1_000_000 * i for i in range(100)]
    bad = {times[i] for i in range(20, 30)}  # a whole bad chunk
    report = ReadReport("flaky")
    got = [t for _, t, _ in iter_messages(_FlakyReader(times, bad), [_Conn()], report)]
    assert got == sorted(set(got)) and not set(got) & bad
    assert got[:20] == times[:20] and got[-60:] == times[-60:]  # at most a message next to the run is lost
    assert report.topics["/x"].read == len(got) and report.topics["/x"].skipped == 100 - len(got)
