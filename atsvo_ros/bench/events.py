"""``atsvo-bench events``: event decoding and time-surface speed, measured side by side in one run.

* Decoding: events/s of :meth:`~atsvo_ros.io.decode.EventDecoder.decode_raw` (serialized bytes ->
  EventBatch, one call per message, as the node and the replay decode) for every EventPacket
  encoding and for dvs EventArray (ROS 2 CDR and ROS 1), against rosbags' generic
  path on the same messages (``deserialize_cdr``/``deserialize_ros1``, then the fields turned into
  arrays: for dvs one Python object per event; for EventPacket rosbags stops at the payload bytes,
  so its figure is deserialization alone, a lower bound of any rosbags-based decoder). Plus the
  real recordings of ``../shared/realdata`` when present.
* Time surfaces: update rate (events/s) of the ATS, the constant-tau TS and the speed-invariant TS
  against dv-processing's ``TimeSurface.accept`` / ``SpeedInvariantTimeSurface.accept`` (C++) on
  the same events; render time (median ms) at 320x240 and 346x260 against dv's ``generateFrame``.
"""
from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from atsvo_ros.config import AtsConfig
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.time_surface import make_time_surface
from atsvo_ros.io.decode import EventDecoder
from atsvo_ros.io.encode import serialize_dvs_event_array, serialize_event_packet
from atsvo_ros.io.event_files import open_events
from atsvo_ros.io.msgtypes import typestore

PACKET = "event_camera_msgs/msg/EventPacket"
DVS = "dvs_msgs/msg/EventArray"
REALDATA = Path(__file__).resolve().parents[2].parent / "shared" / "realdata"


def _best_rate(fn: Callable[[], int], repeats: int, min_time_s: float = 0.2) -> float:
    """Best events/s over ``repeats`` runs of ``fn`` (which returns the number of events handled)."""
    best = 0.0
    for _ in range(repeats):
        n = 0
        t0 = time.perf_counter()
        while True:
            n += fn()
            dt = time.perf_counter() - t0
            if dt >= min_time_s:
                break
        best = max(best, n / dt)
    return best


def synthetic_events(n: int, width: int = 346, height: int = 260, rate_eps: float = 2e6, seed: int = 0) -> EventBatch:
    """Edge-like synthetic events (clustered in space, time-ordered at ``rate_eps``), microsecond stamps."""
    rng = np.random.default_rng(seed)
    t = 1_700_000_000_000_000_000 + np.sort(rng.integers(0, int(n / rate_eps * 1e6), n)) * 1000
    cx = (np.cumsum(rng.normal(0, 3, n)) % width).astype(np.int64)
    cy = (np.arange(n) * 7 // 13 % height).astype(np.int64)
    x = np.clip(cx + rng.integers(-2, 3, n), 0, width - 1)
    y = np.clip(cy + rng.integers(-2, 3, n), 0, height - 1)
    return EventBatch(x, y, t, rng.integers(0, 2, n), width, height)


def _messages(b: EventBatch, per_msg: int, kind: str, ros_version: int) -> list[bytes]:
    out = []
    for i0 in range(0, len(b), per_msg):
        part = b.select(slice(i0, i0 + per_msg))
        if kind == "dvs":
            out.append(serialize_dvs_event_array(part, ros_version=ros_version))
        else:
            if kind == "evt3":
                part = EventBatch(part.x, part.y, part.t - b.t_first_ns, part.p, part.width, part.height)
            out.append(serialize_event_packet(part, kind, ros_version=ros_version))
    return out


def _rosbags_to_arrays(msg: Any, kind: str) -> int:
    if kind == "dvs":
        ev = msg.events
        x = np.array([e.x for e in ev], np.uint16)
        np.array([e.y for e in ev], np.uint16)
        np.array([e.ts.sec * 1_000_000_000 + e.ts.nanosec for e in ev], np.int64)
        np.array([e.polarity for e in ev], np.uint8)
        return len(x)
    return 0


def bench_decode(n_events: int, per_msg: int, repeats: int) -> list[dict]:
    """Decode rate per encoding, ours vs rosbags' generic deserializer."""

    b = synthetic_events(n_events)
    rows = []
    cases = [("libcaer_cmp", 2), ("libcaer", 2), ("mono", 2), ("evt3", 2), ("dvs", 2), ("dvs", 1)]
    for kind, rv in cases:
        msgs = _messages(b, per_msg, kind, rv)
        typ = DVS if kind == "dvs" else PACKET
        store = typestore(rv)
        deser = store.deserialize_cdr if rv == 2 else store.deserialize_ros1

        def ours(msgs=msgs, typ=typ, rv=rv) -> int:
            dec = EventDecoder(typ, rv, drop_backwards=False)
            return sum(len(dec.decode_raw(m)) for m in msgs)

        def generic(msgs=msgs, typ=typ, kind=kind, deser=deser) -> int:
            for m in msgs:
                _rosbags_to_arrays(deser(m, typ), kind)
            return n_events

        n_check = ours()
        assert n_check == n_events, (kind, n_check)
        r_ours = _best_rate(ours, repeats)
        r_gen = _best_rate(generic, max(1, repeats // 2), min_time_s=0.1)
        rows.append({"encoding": kind if kind != "dvs" else f"dvs EventArray ROS {rv}", "ros_version": rv,
                     "events_per_msg": per_msg, "bytes_per_event": sum(map(len, msgs)) / n_events,
                     "ours_eps": r_ours, "rosbags_eps": r_gen,
                     "speedup": r_ours / r_gen if kind == "dvs" else None,
                     "rosbags_note": "deserialize + per-event objects to arrays" if kind == "dvs"
                     else "deserialize only: rosbags has no decoder for the payload"})
    return rows


#: real recordings decoded by the benchmark: (path under realdata, ROS version of its serialization)
REAL_BAGS = (("event_camera_py_bags/test_events_2", 2), ("event_camera_codecs_bags/test_data_libcaer_rollover", 2),
             ("event_camera_py_bags/test_events_1", 2), ("event_camera_py_bags/test_events_1.bag", 1),
             ("event_camera_codecs_bags/test_data_evt3_trigger", 2), ("event_camera_codecs_bags/test_data_mono_cd", 2))


def bench_real_decode(repeats: int) -> list[dict]:
    """Decode rate on the real bags (raw message bytes -> EventBatch, stateful decoder).

    Three figures on the same messages: ``ours_eps`` one :meth:`EventDecoder.decode_raw` call per
    message (what the node and the replay do), ``ours_many_eps`` :meth:`EventDecoder.decode_raw_many`
    over the whole recording (what offline tools do), and ``rosbags_eps`` rosbags' generic
    deserializer on the same bytes (it stops at the payload bytes: deserialization alone, a lower
    bound of the cost of any rosbags-based decoder).
    """

    rows = []
    for rel, rv in REAL_BAGS:
        path = REALDATA / rel
        if not path.exists():
            continue
        src = open_events(path)
        raws = [bytes(raw) for raw in src.raw_messages()]
        n = len(EventDecoder(src.msgtype, rv).decode_raw_many(raws))
        store = typestore(rv)
        deser = store.deserialize_cdr if rv == 2 else store.deserialize_ros1
        msgtype = src.msgtype

        def per_message(raws=raws, msgtype=msgtype, rv=rv) -> int:
            dec = EventDecoder(msgtype, rv)
            return sum(len(dec.decode_raw(r)) for r in raws)

        def many(raws=raws, msgtype=msgtype, rv=rv) -> int:
            return len(EventDecoder(msgtype, rv).decode_raw_many(raws))

        def generic(raws=raws, msgtype=msgtype, deser=deser, n=n) -> int:
            for r in raws:
                deser(r, msgtype)
            return n

        rows.append({"file": rel, "ros_version": rv, "encoding": _encoding_of(raws[0], msgtype, rv),
                     "events": n, "messages": len(raws),
                     "bytes_per_event": sum(map(len, raws)) / max(n, 1),
                     "ours_eps": _best_rate(per_message, repeats), "ours_many_eps": _best_rate(many, repeats),
                     "rosbags_eps": _best_rate(generic, max(1, repeats // 2), min_time_s=0.1)})
    return rows


def _encoding_of(raw: bytes, msgtype: str, rv: int) -> str:
    dec = EventDecoder(msgtype, rv)
    dec.decode_raw(raw)
    return dec.stats.encoding


def _dv_store(b: EventBatch):
    import dv_processing as dv

    store = dv.EventStore()
    t_us = (b.t // 1000).tolist()
    for t, x, y, p in zip(t_us, b.x.tolist(), b.y.tolist(), b.p.tolist()):
        store.push_back(int(t), int(x), int(y), bool(p))
    return store


def bench_time_surfaces(repeats: int) -> list[dict]:
    """Update rate and render time of our surfaces and dv-processing's, same events, per resolution."""

    try:
        import dv_processing as dv
    except ImportError:
        dv = None
    inputs = []
    aedat = REALDATA / "tonic_samples" / "sample.aedat4"
    davis = REALDATA / "event_camera_py_bags" / "test_events_2"

    inputs.append(("320x240 DVXplorer (real)", open_events(aedat).read_all()) if aedat.exists()
                  else ("320x240 synthetic", synthetic_events(300_000, 320, 240)))
    inputs.append(("346x260 DAVIS346 (real)", open_events(davis).read_all()) if davis.exists()
                  else ("346x260 synthetic", synthetic_events(600_000, 346, 260)))
    cfg = AtsConfig()
    rows = []
    for name, b in inputs:
        w, h = b.width, b.height
        t_q = int(b.t[-1])
        row: dict[str, Any] = {"input": name, "events": len(b)}
        for kind in ("ats", "constant", "sits"):
            surf = make_time_surface(kind, w, h, cfg)
            surf.update(b.select(slice(0, 100)))  # compile outside the timing

            def upd(surf=surf, b=b) -> int:
                surf.reset()
                surf.update(b)
                return len(b)

            row[f"{kind}_update_eps"] = _best_rate(upd, repeats, 0.3)
            times = []
            for _ in range(200):
                t0 = time.perf_counter()
                surf.render(t_q)
                times.append(time.perf_counter() - t0)
            row[f"{kind}_render_ms"] = float(np.median(times) * 1e3)
            times = []
            for _ in range(200):
                t0 = time.perf_counter()
                surf.render_raw(t_q)
                times.append(time.perf_counter() - t0)
            row[f"{kind}_render_raw_ms"] = float(np.median(times) * 1e3)
        if dv is not None:
            store = _dv_store(b)
            for label, cls in (("dv_timesurface", dv.TimeSurface), ("dv_sits", dv.SpeedInvariantTimeSurface)):
                def dv_upd(cls=cls, size=(w, h), store=store, n=row["events"]) -> int:
                    ts = cls(size)
                    ts.accept(store)
                    return n

                row[f"{label}_accept_eps"] = _best_rate(dv_upd, repeats, 0.3)
            ts = dv.TimeSurface((w, h))
            ts.accept(store)
            times = []
            for _ in range(200):
                t0 = time.perf_counter()
                ts.generateFrame()
                times.append(time.perf_counter() - t0)
            row["dv_timesurface_generateFrame_ms"] = float(np.median(times) * 1e3)
        rows.append(row)
    return rows


def add_events_args(p: argparse.ArgumentParser) -> None:
    """Arguments of the event benchmark (used by the ``atsvo-bench`` front end)."""
    p.add_argument("--events", type=int, default=2_000_000, help="synthetic events per decode case")
    p.add_argument("--per-msg", type=int, default=20_000, help="events per message (a driver packet)")
    p.add_argument("--repeats", type=int, default=3, help="best of this many timed runs")
    p.add_argument("--json", default=None, help="also write the figures to this JSON file")


def _fmt(x: float) -> str:
    return f"{x / 1e6:9.1f} M/s"


def main_events(args: argparse.Namespace) -> int:
    """Run every part of the event benchmark and print the tables."""
    print("decode (synthetic DAVIS346 events, serialized bytes -> arrays)")
    dec = bench_decode(args.events, args.per_msg, args.repeats)
    for r in dec:
        ratio = f"x{r['speedup']:7.0f}" if r["speedup"] is not None else " " * 8
        print(f"  {r['encoding']:22s} {r['bytes_per_event']:5.1f} B/ev  ours {_fmt(r['ours_eps'])}  "
              f"rosbags {_fmt(r['rosbags_eps'])} {ratio}  ({r['rosbags_note']})")
    real = bench_real_decode(args.repeats)
    if real:
        print("decode (real recordings, stateful EventDecoder: per message / whole recording at once; rosbags: "
              "deserialize only)")
        for r in real:
            print(f"  {r['file']:52s} ROS {r['ros_version']} {r['encoding']:11s} {r['events']:7d} ev "
                  f"{r['events'] / r['messages']:6.0f} ev/msg  ours {_fmt(r['ours_eps'])} / {_fmt(r['ours_many_eps'])}"
                  f"  rosbags {_fmt(r['rosbags_eps'])}")
    print("time surfaces (update: events/s; render: median ms incl. blur + median blur; raw: before them)")
    ts = bench_time_surfaces(args.repeats)
    for r in ts:
        print(f"  {r['input']} ({r['events']} events)")
        for kind in ("ats", "constant", "sits"):
            print(f"    {kind:9s} update {_fmt(r[f'{kind}_update_eps'])}  render {r[f'{kind}_render_ms']:.3f} ms  "
                  f"raw {r[f'{kind}_render_raw_ms']:.3f} ms")
        if "dv_timesurface_accept_eps" in r:
            print(f"    dv-processing TimeSurface.accept {_fmt(r['dv_timesurface_accept_eps'])}  generateFrame "
                  f"{r['dv_timesurface_generateFrame_ms']:.3f} ms; SpeedInvariantTimeSurface.accept "
                  f"{_fmt(r['dv_sits_accept_eps'])}")
        else:
            print("    dv-processing not installed (pip install 'atsvo_ros[bench]'): no comparison")
    if args.json:
        Path(args.json).write_text(json.dumps({"decode": dec, "decode_real": real, "time_surfaces": ts}, indent=2))
        print(f"wrote {args.json}")
    return 0
