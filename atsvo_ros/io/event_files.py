"""Open any supported event recording and iterate its events as :class:`EventBatch` chunks.

Supported: ROS 1 ``.bag``; ROS 2 bag directories (sqlite3 or mcap, including directories whose
``metadata.yaml`` lacks the storage identifier) and bare ``.db3`` / ``.mcap`` files; AEDAT 4
(``.aedat4``); Prophesee RAW (``.raw``, EVT 2.0 / 3.0); MVSEC HDF5 (``.h5``/``.hdf5``, through
:mod:`atsvo_ros.io.mvsec` when installed). Bags are read with rosbags' low-level readers and the
event messages decoded from their raw bytes, so unknown message definitions in a bag do not matter.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from rosbags import rosbag1, rosbag2

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import BagError, DecodeError
from atsvo_ros.io.aedat import aedat4_event_stream, iter_aedat4
from atsvo_ros.io.decode import DVS_TYPES, PACKET_TYPES, DecodeStats, EventDecoder, normalize_msgtype
from atsvo_ros.io.decode.prophesee_raw import read_prophesee_raw
from atsvo_ros.io.mvsec import MvsecReader
from atsvo_ros.io.read_report import ReadReport, container_errors, describe, iter_messages

EVENT_TYPES = PACKET_TYPES | DVS_TYPES


@dataclass
class EventSource:
    """One event stream in a file: iterate it for batches; ``stats`` fills in while reading.

    Unreadable records (a corrupt chunk, page or packet) are skipped and counted in ``report``
    (:class:`~atsvo_ros.io.read_report.ReadReport`): after iterating, ``report.clean`` tells
    whether the batches hold the whole recording.
    """

    path: Path
    kind: str                  # "bag1", "bag2", "aedat4", "raw", "mvsec"
    topic: str = ""
    msgtype: str = ""
    width: int = 0
    height: int = 0
    encoding: str = ""
    n_messages: int = 0
    stats: DecodeStats = field(default_factory=DecodeStats)
    decoder_options: dict = field(default_factory=dict)
    report: ReadReport | None = None
    _storage: Path | None = None

    def __iter__(self) -> Iterator[EventBatch]:
        if self.kind in ("bag1", "bag2"):
            yield from self._iter_bag()
        elif self.kind == "aedat4":
            self.report = ReadReport(str(self.path))
            for b in iter_aedat4(self.path, self.report):
                self._count(b)
                yield b
        elif self.kind == "raw":
            b, head = read_prophesee_raw(self.path)
            self.encoding = f"evt{head.evt[0]}"
            self._count(b)
            yield b
        elif self.kind == "mvsec":
            yield from self._iter_mvsec()

    def read_all(self) -> EventBatch:
        """Every event of the stream in one batch."""
        batches = list(self)
        if not batches:
            return EventBatch.empty(self.width, self.height)
        b = EventBatch.concatenate(batches)
        return EventBatch(b.x, b.y, b.t, b.p, self.width or b.width, self.height or b.height)

    def raw_messages(self) -> Iterator[bytes]:
        """Serialized messages of the event topic, in bag order (bags only; decode with :class:`EventDecoder`).

        Unreadable records are skipped and counted in ``report`` (a new one per call).
        """
        if self.kind not in ("bag1", "bag2"):
            raise DecodeError(f"{self.path}: raw messages exist only in bags, this is a {self.kind} file")
        self.report = ReadReport(str(self.path))
        reader = self._open_reader()
        try:
            conns = [c for c in reader.connections if c.topic == self.topic]
            for _conn, _t, raw in iter_messages(reader, conns, self.report):
                yield raw
        finally:
            reader.close()

    # ----------------------------------------------------------------- internals

    def _count(self, b: EventBatch) -> None:
        self.stats.n_messages += 1
        self.stats.n_events += len(b)
        self.width, self.height = self.width or b.width, self.height or b.height
        self.stats.width, self.stats.height, self.stats.encoding = self.width, self.height, self.encoding

    def _reader(self):
        reader = rosbag1.Reader if self.kind == "bag1" else rosbag2.Reader
        return reader(self._storage or self.path)

    def _open_reader(self):
        """The opened low-level reader (close it); BagError naming the file when it cannot be opened."""
        try:
            reader = self._reader()
            reader.open()
        except container_errors() as exc:
            raise BagError(f"{self.path}: cannot open bag ({describe(exc)})") from None
        return reader

    def _iter_bag(self, chunk_bytes: int = 1 << 21, chunk_messages: int = 512) -> Iterator[EventBatch]:
        """Batches of several messages each (decoded together: the per-message cost would dominate)."""
        opts = {"strict": False, **self.decoder_options}
        dec = EventDecoder(self.msgtype, 1 if self.kind == "bag1" else 2, **opts)
        self.stats = dec.stats
        chunk: list[bytes] = []
        size = 0
        for raw in self.raw_messages():
            chunk.append(raw)
            size += len(raw)
            if size >= chunk_bytes or len(chunk) >= chunk_messages:
                yield self._decode_chunk(dec, chunk)
                chunk, size = [], 0
        if chunk:
            yield self._decode_chunk(dec, chunk)

    def _decode_chunk(self, dec: EventDecoder, chunk: list[bytes]) -> EventBatch:
        b = dec.decode_raw_many(chunk)
        self.width, self.height, self.encoding = dec.stats.width, dec.stats.height, dec.stats.encoding
        return b

    def _iter_mvsec(self) -> Iterator[EventBatch]:
        with MvsecReader(self.path) as reader:
            if not reader.has("events"):
                raise DecodeError(f"{self.path}: no davis/left/events dataset in this MVSEC file")
            for item in reader.stream(("events",)):
                b = item.data
                self._count(b)
                yield b


def _rosbag2_storage(path: Path) -> Path | None:
    """The storage file to open directly when metadata.yaml cannot be trusted (empty identifier)."""
    meta = path / "metadata.yaml"
    if not meta.is_file():
        files = sorted(list(path.glob("*.mcap")) + list(path.glob("*.db3")))
        if len(files) == 1:
            return files[0]
        raise BagError(f"{path}: no metadata.yaml and not exactly one .mcap/.db3 file inside")
    try:
        info = yaml.safe_load(meta.read_bytes().decode("utf-8"))["rosbag2_bagfile_information"]
        info.get("storage_identifier")
    except UnicodeDecodeError as exc:
        raise BagError(f"{meta}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset {exc.start})") from None
    except (yaml.YAMLError, KeyError, TypeError, AttributeError) as exc:
        raise BagError(f"{meta}: not a rosbag2 metadata file ({describe(exc)})") from None
    if info.get("storage_identifier"):
        return None
    files = [path / f for f in info.get("relative_file_paths", [])]
    if len(files) != 1:
        raise BagError(f"{path}: metadata.yaml has no storage_identifier and {len(files)} files; "
                       "set storage_identifier to 'mcap' or 'sqlite3'")
    return files[0]


def _bag_topics(src: EventSource) -> list[tuple[str, str, int]]:
    reader = src._open_reader()
    try:
        counts: dict[tuple[str, str], int] = {}
        for c in reader.connections:
            key = (c.topic, normalize_msgtype(c.msgtype))
            counts[key] = counts.get(key, 0) + int(getattr(c, "msgcount", 0) or 0)
    finally:
        reader.close()
    return [(t, m, n) for (t, m), n in counts.items()]


def open_events(path: str | Path, topic: str | None = None, **decoder_options) -> EventSource:
    """Open an event recording; in a bag pick ``topic`` or else the only event topic.

    ``decoder_options`` go to :class:`EventDecoder` (e.g. ``drop_backwards=False`` for checksums).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(str(p))
    suffix = p.suffix.lower()
    if p.is_dir() or suffix in (".bag", ".db3", ".mcap"):
        kind = "bag1" if suffix == ".bag" else "bag2"
        src = EventSource(p, kind, decoder_options=decoder_options)
        if p.is_dir():
            src._storage = _rosbag2_storage(p)
        topics = _bag_topics(src)
        events = [(t, m, n) for t, m, n in topics if m in EVENT_TYPES]
        if topic is not None:
            chosen = [x for x in topics if x[0] == topic]
            if not chosen:
                raise BagError(f"{p}: no topic {topic!r}; event topics: {[t for t, _, _ in events] or 'none'}")
            if chosen[0][1] not in EVENT_TYPES:
                raise BagError(f"{p}: topic {topic!r} has type {chosen[0][1]}, not an event message")
        elif len(events) == 1:
            chosen = events
        else:
            raise BagError(f"{p}: {'no' if not events else 'several'} event topics "
                           f"({[t for t, _, _ in events]}); choose one with --topic")
        src.topic, src.msgtype, src.n_messages = chosen[0]
        return src
    if suffix == ".aedat4":
        _, w, h = aedat4_event_stream(p)
        return EventSource(p, "aedat4", width=w, height=h, encoding="aedat4")
    if suffix == ".raw":
        return EventSource(p, "raw", encoding="evt")
    if suffix in (".h5", ".hdf5"):
        return EventSource(p, "mvsec", encoding="mvsec_hdf5")
    raise DecodeError(f"{p}: unsupported event file type {suffix or '(none)'}; "
                      "supported: ROS 1/2 bags, .mcap, .db3, .aedat4, .raw (Prophesee), MVSEC .hdf5")


__all__ = ["EVENT_TYPES", "EventSource", "open_events"]
