"""Fuzzing every decoder and file reader: only the package's own errors (AtsvoError) may escape.

Inputs are random bytes and mutated real inputs (truncated, bits flipped, byte ranges overwritten
or removed), from ../shared/realdata where present and from files written here otherwise. Seeds
are fixed and the number of cases per reader is small, so the suite stays deterministic and each
reader takes a few seconds. The stateful EventDecoder must not raise at all (it counts broken
messages), and its one-call fast path must agree with the Python parser on which messages are
well-formed.
"""
from __future__ import annotations

import random
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import AtsvoError, DecodeError
from atsvo_ros.io.decode import EventDecoder, decode_raw
from atsvo_ros.io.decode import _kernels as kern
from atsvo_ros.io.decode import _msg_kernels as mkern
from atsvo_ros.io.decode.packet import ENCODINGS, check_time_base
from atsvo_ros.io.decode.packet_msg import parse_packet_raw
from atsvo_ros.io.encode import serialize_dvs_event_array, serialize_event_packet

PACKET = "event_camera_msgs/msg/EventPacket"
DVS = "dvs_msgs/msg/EventArray"
T0 = 1_700_000_000_000_000_000


def mutate(data: bytes, rng: random.Random, kinds: tuple[int, ...] = (0, 1, 2, 3, 4, 5)) -> bytes:
    """One random damage: truncate, flip bits, overwrite or cut a range, or replace everything."""
    n = len(data)
    kind = rng.choice(kinds)
    if kind == 0 or n < 2:
        return data[: rng.randrange(max(n, 1))]
    buf = bytearray(data)
    if kind == 1:
        for _ in range(rng.randint(1, 16)):
            i = rng.randrange(n)
            buf[i] ^= 1 << rng.randrange(8)
    elif kind == 2:
        i = rng.randrange(n)
        size = rng.randint(1, min(2000, n - i))
        fill = rng.choice([b"\x00", b"\xff", None])
        buf[i:i + size] = rng.randbytes(size) if fill is None else fill * size
    elif kind == 3:
        i = rng.randrange(n)
        del buf[i:i + rng.randint(1, 64)]
    elif kind == 4:  # a header field set to an extreme value
        i = rng.randrange(min(n, 96))
        buf[i:i + 8] = rng.choice([b"\xff" * 8, b"\x00" * 7 + b"\x80", b"\xff\xff\xff\x7f"])
    else:
        return rng.randbytes(rng.randrange(2 * n + 1))
    return bytes(buf)


def mutations(data: bytes, seed: int, n: int, kinds: tuple[int, ...] = (0, 1, 2, 3, 4, 5)) -> Iterator[bytes]:
    rng = random.Random(seed)
    for _ in range(n):
        yield mutate(data, rng, kinds)


def only_atsvo_errors(fn: Callable[[], object], what: str) -> None:
    try:
        fn()
    except AtsvoError:
        pass
    except Exception as exc:
        pytest.fail(f"{what}: {type(exc).__name__}: {exc} escaped (not an AtsvoError)")


# ------------------------------------------------------------------ event messages


def _synthetic_messages() -> list[tuple[str, int, bytes]]:
    rng = np.random.default_rng(0)
    n = 200
    t = T0 + np.sort(rng.integers(0, 3_000_000, n)) * 1000  # within every encoding's packet span
    b = EventBatch(rng.integers(0, 320, n), rng.integers(0, 240, n), t, rng.integers(0, 2, n), 320, 240)
    out = []
    for rv in (1, 2):
        for enc in ENCODINGS:
            part = b if enc != "evt3" else EventBatch(b.x, b.y, b.t - T0, b.p, 320, 240)
            out.append((PACKET, rv, serialize_event_packet(part, enc, ros_version=rv)))
        out.append((DVS, rv, serialize_dvs_event_array(b, ros_version=rv)))
    return out


def _real_messages(realdata: Path) -> list[tuple[str, int, bytes]]:
    from atsvo_ros.io.event_files import open_events

    out = []
    for rel, rv in (("event_camera_py_bags/test_events_2", 2), ("event_camera_py_bags/test_events_1.bag", 1),
                    ("event_camera_codecs_bags/test_data_libcaer_rollover", 2),
                    ("event_camera_codecs_bags/test_data_evt3_trigger", 2),
                    ("event_camera_codecs_bags/test_data_mono_cd", 2)):
        src = open_events(realdata / rel)
        raws = src.raw_messages()
        out += [(src.msgtype, rv, bytes(next(raws))) for _ in range(2)]
        raws.close()
    return out


def _fast_path_accepts(raw: bytes, rv: int) -> bool | None:
    """Whether the kernel's header parser takes the message (None: it hands it to the Python path)."""
    st = np.zeros(kern.STATE_SIZE, np.int64)
    err = mkern._parse_packet(np.frombuffer(raw, np.uint8), rv, st)[0]
    return None if err == kern.ERR_SLOW_PATH else err == kern.OK


def _python_accepts(raw: bytes, rv: int) -> bool:
    try:
        f = parse_packet_raw(raw, rv)
        if f.encoding not in ENCODINGS:
            return False
        check_time_base(f.encoding, f.time_base)
    except DecodeError:
        return False
    return True


def _fuzz_messages(messages: list[tuple[str, int, bytes]], seed: int, per_message: int) -> None:
    for k, (msgtype, rv, raw) in enumerate(messages):
        dec = EventDecoder(msgtype, rv, 320, 240)
        batch = []
        for i, bad in enumerate(mutations(raw, seed + k, per_message)):
            what = f"{msgtype} ROS {rv} message {k} mutation {i}"
            only_atsvo_errors(lambda bad=bad, m=msgtype, r=rv: decode_raw(bad, m, r), what)
            b = dec.decode_raw(bad)  # never raises: broken messages are counted
            assert b.is_sorted(), what
            fast = _fast_path_accepts(bad, rv) if msgtype == PACKET else None
            if fast is not None:
                assert fast == _python_accepts(bad, rv), what
            batch.append(bad)
        many = EventDecoder(msgtype, rv, 320, 240)
        many.decode_raw_many(batch)
        assert many.stats.dropped_messages == dec.stats.dropped_messages
        assert many.stats.n_events == dec.stats.n_events


def test_fuzz_event_messages_synthetic():
    _fuzz_messages(_synthetic_messages(), seed=1, per_message=150)


def test_fuzz_event_messages_real(realdata):
    _fuzz_messages(_real_messages(realdata), seed=2, per_message=80)


def test_random_bytes_as_every_message_type():
    rng = random.Random(3)
    for msgtype in (PACKET, DVS):
        for rv in (1, 2):
            dec = EventDecoder(msgtype, rv)
            for i in range(300):
                data = rng.randbytes(rng.randrange(200))
                only_atsvo_errors(lambda data=data, m=msgtype, r=rv: decode_raw(data, m, r),
                                  f"{msgtype} ROS {rv} random {i}")
                dec.decode_raw(data)


# ------------------------------------------------------------------ files


def _read_events(path: Path) -> None:
    from atsvo_ros.io.event_files import open_events

    src = open_events(path)
    src.read_all()


def _read_bag(path: Path) -> None:
    from atsvo_ros.io.bags import Bag

    with Bag(path) as bag:
        for _ in bag.messages():
            pass
        bag.read_stats.summary()


#: damage inside a file (bits, ranges, cuts) rather than at its ends, which most readers refuse at once
INSIDE = (1, 1, 2, 3, 0)


def _fuzz_file(src: Path, tmp_path: Path, seed: int, n: int, readers: list[Callable[[Path], object]],
               kinds: tuple[int, ...] = (0, 1, 2, 3, 4, 5)) -> None:
    """Each mutation of ``src`` (a file, or the storage file of a bag directory) through each reader."""
    data = src.read_bytes()
    for i, bad in enumerate(mutations(data, seed, n, kinds)):
        work = tmp_path / f"case{i}"
        if src.parent.joinpath("metadata.yaml").is_file() and src.suffix in (".mcap", ".db3"):
            shutil.copytree(src.parent, work)
            for f in work.iterdir():
                f.chmod(0o644)  # the real data is read-only
            target, path = work / src.name, work
        else:
            work.mkdir(parents=True)
            target = path = work / src.name
        target.write_bytes(bad)
        for read in readers:
            only_atsvo_errors(lambda read=read, path=path: read(path), f"{read.__name__}({src.name}) mutation {i}")
        shutil.rmtree(work)


@pytest.mark.parametrize("fmt", ["ros1", "sqlite3", "mcap"])
def test_fuzz_small_bags(tmp_path, fmt):
    from test.io.test_bags import write_bag

    bag = write_bag(tmp_path / "seq", fmt, n_frames=4)
    storage = bag if bag.is_file() else next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    _fuzz_file(storage, tmp_path / "fuzz", seed=4, n=40, readers=[_read_events, _read_bag])


@pytest.mark.parametrize("rel", ["event_camera_py_bags/test_events_1.bag",
                                 "event_camera_py_bags/test_events_1/test_events_1.db3",
                                 "event_camera_py_bags/test_events_2/test_events_2_0.mcap",
                                 "event_camera_codecs_bags/test_data_libcaer_rollover/libcaer_rollover_0.db3"])
def test_fuzz_real_bags(realdata, tmp_path, rel):
    _fuzz_file(realdata / rel, tmp_path, seed=5, n=6, readers=[_read_events], kinds=INSIDE)


def test_fuzz_aedat4(realdata, tmp_path):
    pytest.importorskip("aedat", reason="the aedat package is not installed")
    _fuzz_file(realdata / "tonic_samples" / "sample.aedat4", tmp_path, seed=6, n=12, readers=[_read_events],
               kinds=INSIDE)


@pytest.mark.parametrize("name", ["evt2_sample.raw", "evt3_sample.raw"])
def test_fuzz_prophesee_raw(realdata, tmp_path, name):
    src = realdata / "expelliarmus_prophesee" / name
    data = src.read_bytes()
    header_end = data.find(b"\n", data.rfind(b"\n%", 0, 4096) + 1) + 1
    head = tmp_path / "head"
    head.mkdir()
    (head / name).write_bytes(data[: header_end + 4096])  # mutations then hit the header more often
    _fuzz_file(head / name, tmp_path / "h", seed=7, n=40, readers=[_read_events])
    _fuzz_file(src, tmp_path / "b", seed=8, n=4, readers=[_read_events], kinds=INSIDE)


def test_fuzz_mvsec_hdf5(tmp_path):
    pytest.importorskip("h5py")
    import h5py

    from test.io.test_mvsec import write_mvsec

    (tmp_path / "src").mkdir()
    plain = write_mvsec(tmp_path / "src", n_img=3, n_ev=300, split=False)
    data = tmp_path / "src" / "gz_data.hdf5"  # gzip chunks, as MVSEC ships: damage then fails to inflate
    with h5py.File(plain, "r") as src, h5py.File(data, "w") as dst:
        g = dst.create_group("davis/left")
        for name, ds in src["davis/left"].items():
            g.create_dataset(name, data=ds[:], compression="gzip", chunks=True)

    def read_mvsec(path: Path) -> None:
        from atsvo_ros.io.mvsec import MvsecReader

        with MvsecReader(path) as r:
            for _ in r.stream(("rgb", "depth", "events")):
                pass
            if r.has("ground_truth"):
                r.ground_truth()

    _fuzz_file(data, tmp_path / "fuzz", seed=9, n=40, readers=[read_mvsec, _read_events], kinds=INSIDE)


def test_fuzz_tum_trajectories(realdata, tmp_path):
    from atsvo_ros.io.trajectory import read_tum

    src = realdata / "tum_rgbd_fr1_rpy_300" / "groundtruth.txt"
    small = tmp_path / "gt.txt"
    small.write_bytes(src.read_bytes()[:3000])
    _fuzz_file(small, tmp_path / "fuzz", seed=10, n=200, readers=[read_tum])


def test_fuzz_config_yaml(tmp_path):
    from atsvo_ros.config import config_dir, load_config

    _fuzz_file(config_dir() / "mini_cheetah.yaml", tmp_path, seed=11, n=200, readers=[load_config])
