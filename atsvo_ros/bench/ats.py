"""``atsvo-bench ats-basin``: how far off an initial guess the ATS term alone still converges, per decay rule.

The fusion tracks the ATS rendered at a frame stamp against patches of the previous frame's ATS; that
term's basin of convergence depends on how the surface decays behind a moving edge. For each rule
(the default ``fire_age``, the old ``mean_age``, ``eq2_printed``, the constant-tau and the speed-invariant
surfaces) this measures, with one :class:`~atsvo_ros.core.tracking.residuals.photometric.PhotometricBlock`
(ATS pattern, zero-mean patches, no affine brightness) and the :class:`~atsvo_ros.core.tracking.tracker.Tracker`:

* ``synthetic``: a camera window translating over a 2-D scene -- ``sparse`` (isolated shapes) or
  ``dense`` (many small discs) -- at 300 / 1000 / 3000 px/s, events from the simulator's DVS model
  (threshold mismatch, refractory period, noise). Reference = the ATS at ``t``, current = the ATS
  33 ms later, truth = the 2-D motion; the guess starts ``d`` px off the truth in eight directions,
  reported over all of them and over the three against the motion (``lag``: the patches land in
  the trails) and along it (``lead``). Success: median point error < 0.5 px.
* ``sim``: the simulator's legged-robot sequences (default backflip and bound, 3 s, seed 1; event
  camera made pinhole), ATS pairs 33 ms apart, map points back-projected with the rendered depth,
  the guess rotated by ``d`` degrees about six axes in the image plane. Success: median
  reprojection error < 1 px (the two surfaces are not identical, so some error remains). Pairs
  that do not converge even when started at the truth (event floods where every surface whites
  out, too few points) are counted apart (``converged_from_truth``); the basin is over the others.
* ``real``: the real DVXplorer recording ``../shared/realdata/tonic_samples/sample.aedat4`` (a person,
  no depth or ground truth): the same surface shifted by ``d`` px in eight directions (points on a
  plane, so a shift is a camera translation). Success: median point error < 0.5 px.

The basin is the largest tested offset at which at least 80 % of the trials (and of every smaller
offset) succeed; ``levels`` 1 is the surface on its own, the default pyramid (4 levels at 320x240)
is what the tracker uses. A benchmark, not a test: a run takes several minutes.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from atsvo_ros.config import AtsConfig, EventSelectionConfig, TrackerConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.selection import select_event_pixels
from atsvo_ros.core.events.time_surface import TimeSurface, make_time_surface
from atsvo_ros.core.geometry import se3_exp, se3_inv, transform_points
from atsvo_ros.core.image.frontend import usable_levels
from atsvo_ros.core.image.photometric import ATS_PATTERN, extract_patches
from atsvo_ros.core.image.pyramid import build_pyramid, image_pyramid_with_gradients, pyramid_cameras
from atsvo_ros.core.tracking.residuals.photometric import PhotometricBlock
from atsvo_ros.core.tracking.tracker import Tracker
from atsvo_ros.errors import ConfigError, TrackingError
from atsvo_ros.io.event_files import open_events
from atsvo_ros.sim.events import EventModel, EventSensor
from atsvo_ros.sim.render import Renderer
from atsvo_ros.sim.sequence import SequenceSpec, make_simulation

REALDATA = Path(__file__).resolve().parents[2].parent / "shared" / "realdata"
RULES = ("fire_age", "mean_age", "eq2_printed", "constant", "sits")
FRAME_NS = 33_333_333
SUCCESS_SHARE = 0.8


def make_surface(rule: str, width: int, height: int, cfg: AtsConfig) -> TimeSurface:
    """A surface by rule name: an ATS ``tau_mode`` or ``constant`` / ``sits``."""
    if rule in ("constant", "sits"):
        return make_time_surface(rule, width, height, cfg)
    return make_time_surface("ats", width, height, dataclasses.replace(cfg, tau_mode=rule))


class SurfaceSet:
    """One surface per rule fed from the same event stream, rendered at given times (events streamed once)."""

    def __init__(self, rules: Iterable[str], width: int, height: int, cfg: AtsConfig, keep_ns: int) -> None:
        self.surfaces = {r: make_surface(r, width, height, cfg) for r in rules}
        self.keep_ns = keep_ns
        self._recent: list[EventBatch] = []
        self.width, self.height = width, height

    def feed(self, batch: EventBatch) -> None:
        if len(batch) == 0:
            return
        for s in self.surfaces.values():
            s.update(batch)
        self._recent.append(batch)
        t_end = int(batch.t[-1])
        while len(self._recent) > 1 and int(self._recent[1].t[-1]) < t_end - self.keep_ns:
            self._recent.pop(0)

    def recent(self) -> EventBatch:
        """Events of (at least) the last ``keep_ns``."""
        if not self._recent:
            return EventBatch.empty(self.width, self.height)
        return EventBatch.concatenate(self._recent) if len(self._recent) > 1 else self._recent[0]

    def render(self, t_ns: int) -> dict[str, np.ndarray]:
        return {r: s.render(t_ns) for r, s in self.surfaces.items()}


def stream_until(batches: Iterator[EventBatch], surfaces: SurfaceSet, t_ns: int,
                 pending: list[EventBatch]) -> None:
    """Feed every event up to ``t_ns`` (a batch crossing it is split; the rest waits in ``pending``)."""
    while True:
        b = pending.pop() if pending else next(batches, None)
        if b is None:
            return
        if len(b) == 0:
            continue
        if int(b.t[-1]) <= t_ns:
            surfaces.feed(b)
            continue
        cut = int(np.searchsorted(b.t, t_ns, side="right"))
        surfaces.feed(b.select(slice(0, cut)))
        pending.append(b.select(slice(cut, None)))
        return


@dataclasses.dataclass
class Pair:
    """A reference ATS with its map points and the current ATS with the true pose."""

    ref: np.ndarray
    cur: np.ndarray
    uv: np.ndarray  # (N, 2) selected pixels of the reference
    points_w: np.ndarray  # (N, 3)
    T_cur_w: np.ndarray  # true pose of the current camera


def select(ats: np.ndarray, events: EventBatch, t_ns: int) -> np.ndarray:
    """Eq. 3 pixel selection on the reference ATS (the window of the default ATS)."""

    window_ns = int(round(AtsConfig().tau_u_s * 1e9))
    return select_event_pixels(ats, events, t_ns, window_ns, EventSelectionConfig()).astype(np.float64)


def point_errors(pair: Pair, camera: CameraModel, levels: int, T0: np.ndarray, tcfg: TrackerConfig) -> float:
    """Median image distance (px) between the points projected with the estimate and with the truth."""

    patches = extract_patches(build_pyramid(pair.ref, levels), pair.uv, ATS_PATTERN)
    block = PhotometricBlock("ats", pair.points_w, patches, ATS_PATTERN,
                             image_pyramid_with_gradients(build_pyramid(pair.cur, levels)),
                             pyramid_cameras(camera, levels), sigma=tcfg.photometric_sigma, huber=tcfg.huber_delta,
                             outlier=tcfg.outlier_threshold, gradient_weight=tcfg.gradient_weight,
                             estimate_affine=False, zero_mean=True, coarse_points=tcfg.coarse_level_points)
    try:
        res = Tracker(tcfg).track([block], [T0])
    except TrackingError:
        return float("inf")
    est, _ = camera.project(transform_points(res.T_rgb_w, pair.points_w))
    true, _ = camera.project(transform_points(pair.T_cur_w, pair.points_w))
    err = np.linalg.norm(est - true, axis=1)
    return float(np.median(err)) if len(err) else float("inf")


def basin(offsets: list[float], success: list[float], share: float = SUCCESS_SHARE) -> float:
    """Largest offset whose success share (and every smaller offset's) reaches ``share``; 0 if the first fails."""
    out = 0.0
    for off, s in zip(offsets, success):
        if s < share:
            break
        out = off
    return out


def _translation(shift_px: np.ndarray, camera: CameraModel, depth_m: float = 1.0) -> np.ndarray:
    """Camera pose moving points at ``depth_m`` by ``shift_px`` in the image."""
    T = np.eye(4)
    T[0, 3] = shift_px[0] * depth_m / camera.fx
    T[1, 3] = shift_px[1] * depth_m / camera.fy
    return T


def _rotation(axis: np.ndarray, deg: float) -> np.ndarray:
    xi = np.zeros(6)
    xi[3:] = np.asarray(axis, dtype=np.float64) * np.radians(deg)
    return se3_exp(xi)


# ---------------------------------------------------------------------------- synthetic 2-D scenes


def scene_canvas(kind: str, size: int = 1024, seed: int = 0) -> np.ndarray:
    """Irradiance canvas: ``sparse`` (80 shapes on a dark ground) or ``dense`` (2500 small discs)."""

    rng = np.random.default_rng(seed)
    img = np.full((size, size), 0.15, np.float32)
    if kind == "sparse":
        for _ in range(80):
            c = (int(rng.integers(0, size)), int(rng.integers(0, size)))
            if rng.random() < 0.5:
                cv2.circle(img, c, int(rng.integers(15, 60)), float(rng.uniform(0.6, 1.0)), -1, cv2.LINE_AA)
            else:
                a = rng.integers(20, 90, 2)
                box = cv2.boxPoints((c, (int(a[0]), int(a[1])), float(rng.uniform(0, 180)))).astype(np.int32)
                cv2.fillConvexPoly(img, box, float(rng.uniform(0.6, 1.0)), cv2.LINE_AA)
    else:
        for _ in range(2500):
            c = (int(rng.integers(0, size)), int(rng.integers(0, size)))
            cv2.circle(img, c, int(rng.integers(3, 12)), float(rng.uniform(0.1, 1.0)), -1, cv2.LINE_AA)
    return cv2.GaussianBlur(img, (0, 0), 0.7)


def translating_events(kind: str, speed_px_s: float, angle_rad: float, duration_s: float, seed: int,
                       width: int = 320, height: int = 240,
                       canvas: np.ndarray | None = None) -> tuple[EventBatch, np.ndarray]:
    """Events of a window moving over :func:`scene_canvas` (content moves at ``speed_px_s`` along the angle).

    ``canvas`` replaces the scene of ``kind`` (e.g. a mixed dense/sparse one).
    """
    canvas = scene_canvas(kind, seed=seed) if canvas is None else canvas
    size = canvas.shape[0]
    vel = speed_px_s * np.array([np.cos(angle_rad), np.sin(angle_rad)])
    origin = np.array([size / 2 - width / 2, size / 2 - height / 2]) - vel * duration_s / 2

    def render(t_s: float) -> np.ndarray:
        o = origin - vel * t_s
        M = np.array([[1, 0, o[0]], [0, 1, o[1]]], np.float32)
        return cv2.warpAffine(canvas, M, (width, height), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_WRAP)

    n = max(int(np.ceil(speed_px_s * duration_s / 0.25)), int(duration_s / 0.001)) + 1
    sensor = EventSensor(EventModel(), width, height, np.random.default_rng(seed + 1))
    sensor.reset(render(0.0), 0)
    parts = [sensor.step(render(t), int(round(t * 1e9))) for t in np.linspace(0.0, duration_s, n + 1)[1:]]
    return EventBatch.concatenate([p for p in parts if len(p)]), vel


def surfaces_at(events: EventBatch, rules: list[str], t_ref: int
                ) -> tuple[dict[str, np.ndarray], EventBatch, dict[str, np.ndarray]]:
    """Each rule's 320x240 surface at ``t_ref`` and one frame later, and the events of the frame before ``t_ref``."""
    surfaces = SurfaceSet(rules, 320, 240, AtsConfig(), keep_ns=FRAME_NS)
    it, pending = iter([events]), []
    stream_until(it, surfaces, t_ref, pending)
    ref, recent = surfaces.render(t_ref), surfaces.recent()
    stream_until(it, surfaces, t_ref + FRAME_NS, pending)
    return ref, recent, surfaces.render(t_ref + FRAME_NS)


def bench_synthetic(rules: list[str], levels_list: list[int], kinds: list[str], speeds: list[float], reps: int,
                    offsets: list[float], tcfg: TrackerConfig, progress: bool) -> list[dict[str, Any]]:
    """Part ``synthetic``: one row per (scene, speed, rule, levels), see :func:`_synthetic_row`."""
    camera = CameraModel(320, 240, 270.0, 270.0, 159.5, 119.5)
    rows = []
    duration_s = 0.3
    t_ref = int((duration_s - 0.06) * 1e9)
    for kind in kinds:
        for speed in speeds:
            pairs: dict[str, list[tuple[Pair, np.ndarray]]] = {r: [] for r in rules}
            for rep in range(reps):
                angle = float(np.random.default_rng(rep).uniform(0, 2 * np.pi))
                events, vel = translating_events(kind, speed, angle, duration_s, seed=rep)
                ref, recent, cur = surfaces_at(events, rules, t_ref)
                shift = vel * FRAME_NS * 1e-9
                for r in rules:
                    uv = select(ref[r], recent, t_ref)
                    if len(uv) >= 20:
                        p = camera.backproject(uv, np.ones(len(uv)))
                        pairs[r].append((Pair(ref[r], cur[r], uv, p, _translation(shift, camera)), vel))
            for r in rules:
                for levels in levels_list:
                    rows.append(_synthetic_row(pairs[r], kind, speed, r, levels, offsets, camera, tcfg, progress))
    return rows


def _synthetic_row(pairs: list[tuple[Pair, np.ndarray]], kind: str, speed: float, rule: str, levels: int,
                   offsets: list[float], camera: CameraModel, tcfg: TrackerConfig, progress: bool) -> dict[str, Any]:
    """Success shares per offset over eight directions relative to the motion: all of them, the three against
    it (``lag``: the patches land in the trails), the three along it (``lead``)."""
    t0 = time.perf_counter()
    angles = np.arange(8) * np.pi / 4  # 0 = along the motion
    groups = {"all": list(range(8)), "lag": [3, 4, 5], "lead": [7, 0, 1]}
    ok = np.zeros((len(pairs), len(offsets), 8), bool)
    for k, (pair, vel) in enumerate(pairs):
        shift = vel * FRAME_NS * 1e-9
        c, s_ = vel / np.linalg.norm(vel)
        for i, off in enumerate(offsets):
            for j, a in enumerate(angles):
                d = np.array([c * np.cos(a) - s_ * np.sin(a), s_ * np.cos(a) + c * np.sin(a)])
                ok[k, i, j] = point_errors(pair, camera, levels, _translation(shift + off * d, camera), tcfg) < 0.5
    row: dict[str, Any] = {"part": "synthetic", "scene": kind, "speed_px_s": speed, "rule": rule, "levels": levels,
                           "pairs": len(pairs), "offsets_px": offsets}
    for name, js in groups.items():
        share = ok[:, :, js].mean(axis=(0, 2)) if len(pairs) else np.zeros(len(offsets))
        row[f"success_{name}"] = share.tolist()
        row[f"basin_{name}_px"] = basin(offsets, share.tolist())
    if progress:
        print(f"  {kind:6s} {speed:5.0f} px/s {rule:11s} L{levels}: basin {row['basin_all_px']:4.1f} px (against the "
              f"motion {row['basin_lag_px']:4.1f}, along {row['basin_lead_px']:4.1f})"
              f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    return row


# ---------------------------------------------------------------------------- simulator sequences (3-D)


def bench_sim(rules: list[str], levels_list: list[int], scenario: str, duration_s: float, seed: int, step: int,
              offsets_deg: list[float], tcfg: TrackerConfig, progress: bool) -> list[dict[str, Any]]:
    """Part ``sim``: frame pairs of a simulated sequence with rendered depth; one row per (rule, levels)."""

    sim = make_simulation(SequenceSpec(scenario=scenario, duration_s=duration_s, seed=seed))
    sim.rig = dataclasses.replace(sim.rig, event_camera=sim.rig.event_camera.pinhole())
    camera = sim.rig.event_camera
    renderer = Renderer(sim.scene, camera)
    t_refs = list(range(sim.t_start_ns + 200_000_000, sim.t_end_ns - FRAME_NS, step * FRAME_NS))
    surfaces = SurfaceSet(rules, camera.width, camera.height, AtsConfig(), keep_ns=FRAME_NS)
    it, pending = sim.events(), []
    pairs: dict[str, list[Pair]] = {r: [] for r in rules}
    rates = []
    t0 = time.perf_counter()
    for t_ref in t_refs:
        stream_until(it, surfaces, t_ref, pending)
        ref, recent = surfaces.render(t_ref), surfaces.recent()
        rates.append(int(np.count_nonzero(recent.t > t_ref - FRAME_NS)) / (FRAME_NS * 1e-9))
        stream_until(it, surfaces, t_ref + FRAME_NS, pending)
        cur = surfaces.render(t_ref + FRAME_NS)
        depth = renderer.render(sim.T_world_event(t_ref))[1]
        T_w_ref = sim.T_world_event(t_ref)
        T_cur_w = se3_inv(sim.T_world_event(t_ref + FRAME_NS))
        for r in rules:
            uv = select(ref[r], recent, t_ref)
            d = depth[uv[:, 1].astype(int), uv[:, 0].astype(int)] if len(uv) else np.zeros(0)
            ok = np.isfinite(d) & (d > 0.1)
            if ok.sum() >= 30:
                p_w = transform_points(T_w_ref, camera.backproject(uv[ok], d[ok]))
                pairs[r].append(Pair(ref[r], cur[r], uv[ok], p_w, T_cur_w))
    if progress:
        print(f"  {scenario}: {len(t_refs)} frame pairs simulated in {time.perf_counter() - t0:.0f} s "
              f"(event rate {np.median(rates) / 1e6:.1f} Mev/s median, {np.max(rates) / 1e6:.1f} max)", flush=True)
    axes = [np.array([np.cos(a), np.sin(a), 0.0]) for a in np.arange(6) * np.pi / 3 + 0.2]
    rows = []
    for r in rules:
        for levels in levels_list:
            t0 = time.perf_counter()
            # the basin counts the pairs that converge when started at the truth (the others -- floods, too few
            # points -- are reported apart: no starting point helps them)
            err0 = np.array([point_errors(p, camera, levels, p.T_cur_w, tcfg) for p in pairs[r]])
            good = [p for p, e in zip(pairs[r], err0) if e < 1.0]
            succ = np.zeros(len(offsets_deg))
            for pair in good:
                for i, off in enumerate(offsets_deg):
                    errs = [point_errors(pair, camera, levels, _rotation(ax, off) @ pair.T_cur_w, tcfg)
                            for ax in axes] if off > 0 else [0.0]
                    succ[i] += np.mean(np.array(errs) < 1.0) / len(good)
            row = {"part": "sim", "scenario": scenario, "rule": r, "levels": levels, "pairs": len(pairs[r]),
                   "converged_from_truth": len(good) / max(len(pairs[r]), 1),
                   "median_error_at_truth_px": float(np.median(err0)) if len(err0) else float("nan"),
                   "offsets_deg": offsets_deg, "success": succ.tolist(), "basin_deg": basin(offsets_deg, succ.tolist())}
            rows.append(row)
            if progress:
                print(f"  {scenario:8s} {r:11s} L{levels}: converged from the truth {row['converged_from_truth']:.2f} "
                      f"(median error {row['median_error_at_truth_px']:.2f} px), basin of those "
                      f"{row['basin_deg']:4.2f} deg  ({time.perf_counter() - t0:.0f} s)", flush=True)
    return rows


# ---------------------------------------------------------------------------- real recording (2-D shifts)


def bench_real(rules: list[str], levels_list: list[int], offsets: list[float], n_times: int, tcfg: TrackerConfig,
               progress: bool) -> list[dict[str, Any]]:
    """Part ``real``: the same surface shifted by known 2-D offsets, at ``n_times`` moments of the recording."""

    path = REALDATA / "tonic_samples" / "sample.aedat4"
    if not path.exists():
        if progress:
            print(f"  {path} not found: part real skipped", flush=True)
        return []
    events = open_events(path).read_all()
    camera = CameraModel(events.width, events.height, 270.0, 270.0, (events.width - 1) / 2, (events.height - 1) / 2)
    t_all = np.linspace(int(events.t[0]) + 150_000_000, int(events.t[-1]), n_times).astype(np.int64)
    surfaces = SurfaceSet(rules, events.width, events.height, AtsConfig(), keep_ns=FRAME_NS)
    it, pending = iter([events]), []
    pairs: dict[str, list[Pair]] = {r: [] for r in rules}
    for t in t_all.tolist():
        stream_until(it, surfaces, t, pending)
        imgs, recent = surfaces.render(t), surfaces.recent()
        for r in rules:
            uv = select(imgs[r], recent, t)
            if len(uv) >= 30:
                pairs[r].append(Pair(imgs[r], imgs[r], uv, camera.backproject(uv, np.ones(len(uv))), np.eye(4)))
    dirs = [np.array([np.cos(a), np.sin(a)]) for a in np.arange(8) * np.pi / 4 + 0.3]
    rows = []
    for r in rules:
        for levels in levels_list:
            succ = np.zeros(len(offsets))
            for pair in pairs[r]:
                for i, off in enumerate(offsets):
                    ok = [point_errors(pair, camera, levels, _translation(off * d, camera), tcfg) < 0.5 for d in dirs]
                    succ[i] += np.mean(ok) / max(len(pairs[r]), 1)
            row = {"part": "real", "rule": r, "levels": levels, "moments": len(pairs[r]), "offsets_px": offsets,
                   "success": succ.tolist(), "basin_px": basin(offsets, succ.tolist())}
            rows.append(row)
            if progress:
                print(f"  real       {r:11s} L{levels}: basin {row['basin_px']:4.1f} px", flush=True)
    return rows


# ---------------------------------------------------------------------------- CLI


def add_ats_basin_args(p: argparse.ArgumentParser) -> None:
    """Arguments of the ATS basin benchmark (used by the ``atsvo-bench`` front end)."""
    p.add_argument("--parts", default="synthetic,sim,real", help="comma list of synthetic, sim, real")
    p.add_argument("--rules", default=",".join(RULES), help=f"comma list of {', '.join(RULES)}")
    p.add_argument("--levels", default="1,default", help="pyramid levels to test (default = the tracker's)")
    p.add_argument("--scenarios", default="backflip,bound", help="simulator scenarios of part sim")
    p.add_argument("--duration", type=float, default=3.0, help="simulated seconds per scenario")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--step", type=int, default=3, help="part sim: one frame pair every STEP frames")
    p.add_argument("--reps", type=int, default=3, help="part synthetic: scenes (motion directions) per speed")
    p.add_argument("--json", default=None, help="also write every figure to this JSON file")


def _table(rows: list[dict[str, Any]], rules: list[str]) -> None:
    def cell(part: str, key: str, rule: str, levels: int, **match: Any) -> str:
        for r in rows:
            if r["part"] == part and r["rule"] == rule and r["levels"] == levels and all(r[k] == v for k, v in
                                                                                          match.items()):
                return f"{r[key]:g}"
        return "-"

    levels_all = sorted({r["levels"] for r in rows})
    print("\nbasin (largest offset with >= 80 % convergence); columns: rules")
    print(f"{'':44s}" + "".join(f"{r:>12s}" for r in rules))
    for levels in levels_all:
        for scene in ("sparse", "dense"):
            for speed in sorted({r["speed_px_s"] for r in rows if r["part"] == "synthetic"}):
                for d in ("all", "lag", "lead"):
                    vals = [cell("synthetic", f"basin_{d}_px", r, levels, scene=scene, speed_px_s=speed) for r in rules]
                    if any(v != "-" for v in vals):
                        print(f"  L{levels} synthetic {scene:6s} {speed:5.0f} px/s {d:4s} [px]".ljust(44)
                              + "".join(f"{v:>12s}" for v in vals))
        for scenario in sorted({r["scenario"] for r in rows if r["part"] == "sim"}):
            vals = [cell("sim", "basin_deg", r, levels, scenario=scenario) for r in rules]
            print(f"  L{levels} sim {scenario} [deg]".ljust(44) + "".join(f"{v:>12s}" for v in vals))
            vals = [cell("sim", "converged_from_truth", r, levels, scenario=scenario) for r in rules]
            print(f"  L{levels} sim {scenario} converged from truth".ljust(44)
                  + "".join(f"{float(v):>12.2f}" if v != "-" else f"{v:>12s}" for v in vals))
        vals = [cell("real", "basin_px", r, levels) for r in rules]
        if any(v != "-" for v in vals):
            print(f"  L{levels} real sample.aedat4 shift [px]".ljust(44) + "".join(f"{v:>12s}" for v in vals))


def main_ats_basin(args: argparse.Namespace) -> int:
    """Run the selected parts and print the basin table."""

    rules = [r.strip() for r in args.rules.split(",") if r.strip()]
    unknown = sorted(set(rules) - set(RULES))
    if unknown:
        raise ConfigError(f"unknown rule(s) {unknown}; choose from {', '.join(RULES)}")
    tcfg = TrackerConfig()
    default_levels = usable_levels(CameraModel(320, 240, 270.0, 270.0, 159.5, 119.5), tcfg.pyramid_levels)
    levels_list = sorted({default_levels if v.strip() == "default" else int(v) for v in args.levels.split(",")})
    parts = {p.strip() for p in args.parts.split(",")}
    rows: list[dict[str, Any]] = []
    if "synthetic" in parts:
        print("synthetic 2-D scenes (ATS at t vs t + 33 ms, known image motion)", flush=True)
        rows += bench_synthetic(rules, levels_list, ["sparse", "dense"], [300.0, 1000.0, 3000.0], args.reps,
                                [1, 2, 3, 4, 5, 6, 8, 11, 16, 22, 32, 45], tcfg, True)
    if "sim" in parts:
        print("simulated sequences (ATS at t vs t + 33 ms, rendered depth, rotated guesses)", flush=True)
        for scenario in [s.strip() for s in args.scenarios.split(",") if s.strip()]:
            rows += bench_sim(rules, levels_list, scenario, args.duration, args.seed, args.step,
                              [0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0], tcfg, True)
    if "real" in parts:
        print("real recording (same surface shifted)", flush=True)
        rows += bench_real(rules, levels_list, [1, 2, 3, 4, 5, 6, 8, 11, 16, 22, 32], 12, tcfg, True)
    _table(rows, rules)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
        print(f"wrote {args.json}")
    return 0
