"""Trajectory metrics: association, alignment, ATE, RPE per frame and per degree, divergence.

Definitions (numpy only; ``evo`` is used in the tests as an independent cross-check):

* Association: nearest stamp within ``max_diff_s`` (default 10 ms), searched from the trajectory
  with fewer poses into the longer one, ties to the earlier stamp -- the pairing of
  ``evo.core.sync.associate_trajectories``. With ``interpolate_gt`` the same pairs are kept but
  ground truth is interpolated at the estimate stamps (evo's ``SyncMethod.interpolation``); both
  CLIs (atsvo-replay, atsvo-eval) use it by default, so they print the same numbers for the same
  trajectory, because a 100 Hz ground truth is up to 5 ms away from a frame otherwise. The
  library default stays nearest (``evo``'s default; the benches' "nearest" columns rely on it).
  The association used is stored as ``extra.association`` (``interpolated`` / ``nearest``).
  Ground truth that repeats a stamp (motion capture does now and then) keeps the first pose of
  each and says so in a note; an estimate that repeats a stamp is an error (every copy would be
  matched and scored, halving the RPE).
* Alignment of the estimate onto ground truth (``align``):
  ``paper`` -- the paper's protocol (Section III): SE(3) Umeyama on the beginning frames -- the
  matched poses of the first ``align_s`` seconds (2 s) but at most ``align_fraction`` (20 %) of
  them and at least 3 -- applied to the whole estimate, then an SO(3) alignment: one constant
  rotation of the body frame (right-multiplied) that makes the first estimated orientation equal
  to ground truth's, positions untouched. When ground truth hardly moves in that window (less than
  ``min_align_spread_m`` off a straight line: Umeyama's rotation would be unobservable), the first
  pose is put onto ground truth's instead (``evo --align_origin``). ``se3`` / ``sim3`` -- Umeyama over all
  matched poses without / with scale (``evo -a`` / ``-as``). ``origin`` -- the first pose onto ground
  truth's (``evo --align_origin``): an odometry starts where the robot is, so this is the drift a controller
  sees, free of any fit (a flip's loss in flight stays in every later pose). ``none`` -- as is.
* ATE: RMSE of the position differences of the aligned matched poses.
* RPE per frame: for consecutive matched pairs, ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``; rotation
  error = angle of E (deg), translation error = norm of E's translation (cm); reported as means
  (like the paper's tables; ``evo_rpe --delta 1 --delta_unit f``) at top level and as RMSE (what
  ``evo_rpe`` prints, the benches and :func:`format_metrics`) under ``extra``.
* RPE per degree: the same error over consecutive, non-overlapping segments in which ground
  truth accumulates at least ``delta_deg`` (1) degree of rotation (``evo_rpe --delta 1
  --delta_unit d``, what the paper's deg/d and cm/d columns use); means over the segments.
  Only segments where ground truth rotates exist; with fewer than one such segment the values
  are undefined (``None`` in JSON). ``extra`` also holds the ratio form: the sum of the per-frame
  errors over the total ground-truth rotation (``*_sum_ratio``).
* Divergence: ATE > 5 m, RPE > 1 deg/d or > 20 cm/d. ``diverged_at_s`` is the first time
  (relative to the first matched ground-truth stamp) at which the running ATE RMSE or the running
  per-degree means (once ``min_segments`` segments exist) cross a limit; a diverged run is also
  scored on its matched poses before that time (``partial``).
* ``tracked_fraction``: the share of the frames the odometry was asked to track that it tracked:
  estimate poses with status ok over all estimate poses; without statuses (``est_ok`` None, a TUM
  file), estimate poses matched to ground truth over all estimate poses. ``extra.gt_span_covered``
  keeps the ground-truth view: the ground-truth time span covered by estimate poses whose status is
  ok (gaps longer than twice the median estimate period do not count), over the ground-truth span.
* ``extra.notes``: one line per thing that makes the numbers less than they seem, each starting
  with ``warning: ``: ground truth much sparser than the estimate (few poses matched), repeated
  ground-truth stamps, metrics that overflowed. Non-finite values are never written to JSON:
  :meth:`EvalResult.to_json` turns them into null (a note says which and why) and
  :func:`metrics_json` refuses NaN / Infinity outright.
"""
from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from atsvo_ros.core.geometry import interpolate_trajectory, se3_inv
from atsvo_ros.errors import EvaluationError
from atsvo_ros.io.trajectory import Trajectory, format_stamp, read_tum

ALIGN_METHODS = ("paper", "se3", "sim3", "origin", "none")


@dataclass(frozen=True)
class EvalOptions:
    """How a run is scored (defaults follow the paper and evo)."""

    align: str = "paper"
    align_s: float = 2.0
    align_fraction: float = 0.2
    min_align_poses: int = 3
    min_align_spread_m: float = 0.01
    max_diff_s: float = 0.01
    delta_deg: float = 1.0
    ate_limit_m: float = 5.0
    rpe_rot_limit_deg_per_deg: float = 1.0
    rpe_trans_limit_m_per_deg: float = 0.2
    min_segments: int = 5
    interpolate_gt: bool = False

    def __post_init__(self) -> None:
        if self.align not in ALIGN_METHODS:
            raise EvaluationError(f"unknown alignment {self.align!r} (choose one of {', '.join(ALIGN_METHODS)})")
        for ok, what, value in ((self.max_diff_s >= 0, "max_diff_s (--t-max-diff) must be >= 0", self.max_diff_s),
                                (self.align_s > 0, "align_s (--align-s) must be > 0", self.align_s),
                                (0 < self.delta_deg <= 180, "delta_deg (--delta-deg) must be in (0, 180]",
                                 self.delta_deg)):
            if not ok:  # NaN fails every comparison, so it lands here too
                raise EvaluationError(f"{what}, got {value:g}")


@dataclass
class EvalResult:
    """Everything computed for one (ground truth, estimate) pair."""

    metrics: dict[str, Any]
    stamps_ns: np.ndarray
    T_w_gt: np.ndarray
    T_w_est: np.ndarray
    position_errors_m: np.ndarray
    rpe_rot_deg: np.ndarray
    rpe_trans_m: np.ndarray
    partial: EvalResult | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The metrics.json document: the issue's keys at top level, the rest under ``extra``.

        Non-finite numbers become None (JSON null): NaN and Infinity are not JSON, and the reason is
        already in ``extra.notes`` (see :func:`evaluate`).
        """
        out = dict(self.metrics)
        extra = dict(self.extra)
        if self.partial is not None:
            extra["partial"] = {k: v for k, v in self.partial.metrics.items()
                                if k not in ("diverged", "diverged_at_s", "tracked_fraction")}
        out["extra"] = extra
        return _finite_or_none(out)


def _finite_or_none(value: Any) -> Any:
    """``value`` with every non-finite float (also nested in dicts and lists) replaced by None."""
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def _non_finite_keys(doc: dict[str, Any], prefix: str = "") -> list[str]:
    """Dotted names of the non-finite floats in ``doc`` (nested dicts followed)."""
    keys: list[str] = []
    for k, v in doc.items():
        if isinstance(v, dict):
            keys += _non_finite_keys(v, f"{prefix}{k}.")
        elif isinstance(v, (float, np.floating)) and not math.isfinite(v):
            keys.append(f"{prefix}{k}")
    return keys


def metrics_json(doc: dict[str, Any]) -> str:
    """The text of metrics.json for ``doc`` (an :meth:`EvalResult.to_json` document): indented, one
    trailing newline, strict JSON.

    Non-finite numbers left in ``doc`` are written as null (``to_json`` documents have none); the
    final dump uses ``allow_nan=False`` so NaN / Infinity, which ``jq`` and ``JSON.parse`` reject,
    can never reach the file.
    """
    return json.dumps(_finite_or_none(doc), indent=2, allow_nan=False) + "\n"


def errors_by_label(ev: EvalResult, labels: np.ndarray, names: Sequence[str]) -> dict[str, dict[str, float]]:
    """ATE RMSE and mean RPE per frame over the frames of each label (e.g. a legged robot's motion phases).

    ``labels`` holds one index into ``names`` per evaluated pose (``ev.stamps_ns``); a frame-to-frame error
    counts for the label of the pair's second frame. The poses keep the whole run's alignment, so the
    figures add up to the run's: they say where its error was made.
    """
    labels = np.asarray(labels)
    if labels.shape != ev.stamps_ns.shape:
        raise EvaluationError(f"{len(labels)} labels for {len(ev.stamps_ns)} evaluated poses")
    out: dict[str, dict[str, float]] = {}
    for i, name in enumerate(names):
        sel = labels == i
        pair = sel[1:]
        if not sel.any():
            continue
        out[name] = {"frames": int(sel.sum()),
                     "ate_rmse_cm": float(np.sqrt(np.mean(ev.position_errors_m[sel] ** 2)) * 100.0),
                     "rpe_deg_per_frame": float(np.mean(ev.rpe_rot_deg[pair])) if pair.any() else float("nan"),
                     "rpe_cm_per_frame": float(np.mean(ev.rpe_trans_m[pair]) * 100.0) if pair.any()
                     else float("nan")}
    return out


# ---------------------------------------------------------------------------- association


def associate(stamps_a_ns: np.ndarray, stamps_b_ns: np.ndarray,
              max_diff_ns: int = 10_000_000) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(ia, ib)`` of matched stamps (nearest within ``max_diff_ns``), evo's pairing.

    Each stamp of the shorter sequence gets the nearest stamp of the longer one (ties to the
    earlier); both sequences must be sorted.
    """
    a = np.asarray(stamps_a_ns, dtype=np.int64)
    b = np.asarray(stamps_b_ns, dtype=np.int64)
    if len(a) == 0 or len(b) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    swap = len(b) < len(a)  # evo starts from the shorter trajectory (the second when equal)
    short, long_ = (b, a) if swap else (a, b)
    in_range = (short >= long_[0] - max_diff_ns) & (short <= long_[-1] + max_diff_ns)
    idx = np.minimum(np.searchsorted(long_, short, side="right"), len(long_) - 1)
    diff_ub = long_[idx] - short  # negative only when clamped past the end (then idx is the match)
    diff_lb = np.where(idx > 0, short - long_[np.maximum(idx - 1, 0)], np.iinfo(np.int64).max)
    use_ub = (diff_ub <= max_diff_ns) & (diff_ub < diff_lb)
    use_lb = ~use_ub & (diff_lb <= max_diff_ns) & (diff_lb <= diff_ub)
    keep = in_range & (use_ub | use_lb)
    i_short = np.flatnonzero(keep)
    i_long = np.where(use_ub, idx, idx - 1)[keep]
    return (i_long, i_short) if swap else (i_short, i_long)


# ---------------------------------------------------------------------------- alignment


def umeyama(x: np.ndarray, y: np.ndarray, with_scale: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """``(R, t, s)`` minimising ``sum |y_i - (s R x_i + t)|^2`` for (N, 3) point sets (Umeyama 1991)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 3:
        raise EvaluationError(f"umeyama needs two (N, 3) arrays, got {x.shape} and {y.shape}")
    with np.errstate(over="ignore", invalid="ignore"):  # checked below and said in the error
        mx, my = x.mean(0), y.mean(0)
        xc, yc = x - mx, y - my
        var_x = np.sum(xc * xc) / len(x)
        cov = yc.T @ xc / len(x)
    if not np.all(np.isfinite(cov)) or (with_scale and not np.isfinite(var_x)):
        far = max(np.abs(x).max(), np.abs(y).max())
        raise EvaluationError(f"the alignment overflows: positions reach {far:.3g} m; check the trajectories for an "
                              "absurd value")
    U, d, Vt = np.linalg.svd(cov)
    if np.count_nonzero(d > np.finfo(np.float64).eps) < 2:
        raise EvaluationError(f"degenerate alignment: the {len(x)} positions used do not span a plane "
                              "(no motion?); use more poses (--align-s) or another --align")
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1.0
    R = U @ S @ Vt
    s = float(np.trace(np.diag(d) @ S) / var_x) if with_scale else 1.0
    t = my - s * R @ mx
    return R, t, s


def _apply_sim3(T: np.ndarray, R: np.ndarray, t: np.ndarray, s: float) -> np.ndarray:
    out = T.copy()
    out[:, :3, :3] = R @ T[:, :3, :3]
    out[:, :3, 3] = (s * T[:, :3, 3]) @ R.T + t
    return out


def align(T_gt: np.ndarray, T_est: np.ndarray, stamps_ns: np.ndarray, opts: EvalOptions) -> tuple[np.ndarray, dict]:
    """Aligned copy of the matched estimate poses and a description of the transform used."""
    n = len(T_est)
    if opts.align == "none":
        return T_est.copy(), {"method": "none"}
    if opts.align == "origin":
        return _onto_first(T_gt, T_est), {"method": "origin"}
    if opts.align in ("se3", "sim3"):
        if n < 3:
            raise EvaluationError(f"{opts.align} alignment needs at least 3 matched poses, got {n}")
        R, t, s = umeyama(T_est[:, :3, 3], T_gt[:, :3, 3], with_scale=opts.align == "sim3")
        return _apply_sim3(T_est, R, t, s), {"method": opts.align, "n_poses": n, "scale": s}
    # paper: SE(3) on the beginning frames, then SO(3) on the first orientation.
    t0 = stamps_ns[0]
    n_time = int(np.searchsorted(stamps_ns, t0 + int(round(opts.align_s * 1e9)), side="right"))
    n_align = min(n_time, int(np.ceil(opts.align_fraction * n)))
    n_align = min(max(n_align, opts.min_align_poses), n)
    info: dict[str, Any] = {"method": "paper", "n_poses": n_align,
                            "window_s": float((stamps_ns[n_align - 1] - t0) * 1e-9)}
    window = T_gt[:n_align, :3, 3]
    spread = np.linalg.svd(window - window.mean(0), compute_uv=False) / np.sqrt(max(n_align, 1))
    if n_align >= 3 and len(spread) > 1 and spread[1] >= opts.min_align_spread_m:
        R, t, s = umeyama(T_est[:n_align, :3, 3], window)
        out = _apply_sim3(T_est, R, t, s)
        # SO(3): a constant body-frame rotation makes the first orientation equal to ground truth's
        # (positions keep the SE(3) fit).
        C = out[0, :3, :3].T @ T_gt[0, :3, :3]
        out[:, :3, :3] = out[:, :3, :3] @ C
    else:
        # No usable motion at the start: the first pose is put onto ground truth's (evo --align_origin).
        out = _onto_first(T_gt, T_est)
        info["fallback"] = (f"first pose (ground truth moves less than {opts.min_align_spread_m} m "
                            "off a line in the alignment window)")
    return out, info


def _onto_first(T_gt: np.ndarray, T_est: np.ndarray) -> np.ndarray:
    """The estimate moved rigidly so that its first pose is ground truth's (``evo --align_origin``)."""
    return (T_gt[0] @ se3_inv(T_est[0]))[None] @ T_est


# ---------------------------------------------------------------------------- errors


def rotation_angle_deg(R: np.ndarray) -> np.ndarray:
    """Rotation angles in degrees, accurate near 0 and 180 (atan2 of sin and cos parts)."""
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    sin_t = 0.5 * np.linalg.norm(v, axis=-1)
    cos_t = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    return np.degrees(np.arctan2(sin_t, cos_t))


def relative_errors(T_gt: np.ndarray, T_est: np.ndarray, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (deg) and translation (m) of ``(Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`` for index pairs."""
    Q = se3_inv(T_gt[i]) @ T_gt[j]
    P = se3_inv(T_est[i]) @ T_est[j]
    E = se3_inv(Q) @ P
    return rotation_angle_deg(E[:, :3, :3]), np.linalg.norm(E[:, :3, 3], axis=1)


def angle_segments(T_gt: np.ndarray, delta_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Consecutive non-overlapping ``(i, j)`` over which ground truth accumulates >= ``delta_deg``."""
    if len(T_gt) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    steps = rotation_angle_deg(np.swapaxes(T_gt[:-1, :3, :3], -1, -2) @ T_gt[1:, :3, :3])
    starts, ends = [], []
    acc, start = 0.0, 0
    for k, d in enumerate(steps.tolist()):  # sequential by nature (the accumulator resets)
        acc += d
        if acc >= delta_deg:
            starts.append(start)
            ends.append(k + 1)
            acc, start = 0.0, k + 1
    return np.asarray(starts, np.int64), np.asarray(ends, np.int64)


def _ratio_per_deg(T_gt: np.ndarray, rot_f: np.ndarray, trans_f: np.ndarray) -> dict[str, float | None]:
    """Alternative per-degree figures: summed per-frame errors over the summed GT rotation."""
    if len(T_gt) < 2:
        return {"rpe_rot_deg_per_deg_sum_ratio": None, "rpe_trans_cm_per_deg_sum_ratio": None}
    gt_deg = float(np.sum(rotation_angle_deg(np.swapaxes(T_gt[:-1, :3, :3], -1, -2) @ T_gt[1:, :3, :3])))
    if gt_deg < 1e-9:
        return {"rpe_rot_deg_per_deg_sum_ratio": None, "rpe_trans_cm_per_deg_sum_ratio": None}
    return {"rpe_rot_deg_per_deg_sum_ratio": float(np.sum(rot_f) / gt_deg),
            "rpe_trans_cm_per_deg_sum_ratio": float(np.sum(trans_f) * 100.0 / gt_deg)}


def _mean(x: np.ndarray) -> float | None:
    return float(np.mean(x)) if len(x) else None


def _gt_span_covered(gt: Trajectory, stamps_ns: np.ndarray, ok: np.ndarray) -> float:
    """Share of the ground-truth span covered by ok estimate poses (gaps > 2 median periods excluded)."""
    span = gt.stamps_ns[-1] - gt.stamps_ns[0]
    s = stamps_ns[ok]
    if span <= 0 or len(s) == 0:
        return 0.0
    if len(s) == 1:
        return 0.0
    dt = np.diff(s)
    period = np.median(np.diff(stamps_ns)) if len(stamps_ns) > 1 else 0
    covered = np.sum(dt[dt <= 2 * period])
    return float(min(1.0, covered / span))


# ---------------------------------------------------------------------------- evaluation


def evaluate(gt: Trajectory, est: Trajectory, opts: EvalOptions | None = None,
             est_ok: np.ndarray | None = None, *, _check_divergence: bool = True) -> EvalResult:
    """Score ``est`` against ``gt``; ``est_ok`` marks estimate poses tracked with status ok.

    Both are sorted by time; a repeated ground-truth stamp keeps its first pose. What makes the
    numbers less than they seem (sparse ground truth, repeated ground-truth stamps, overflow) is
    listed one line each in ``extra["notes"]``, for the CLIs to print as warnings.

    Raises:
        EvaluationError: the estimate repeats a stamp (each copy would be matched and scored); a
            trajectory has fewer than 2 poses; fewer than 2 estimate poses match ground truth (the
            message gives both time ranges, to check the time bases); the alignment is degenerate.
    """
    opts = opts or EvalOptions()
    notes: list[str] = []
    if len(est) < 2:
        raise EvaluationError(_too_few("the estimate", est) + " to score it against ground truth")
    gt_unique = gt.sorted_unique()
    n_repeats = len(gt) - len(gt_unique)
    if n_repeats:
        s = np.sort(gt.stamps_ns)
        first = int(s[1:][np.diff(s) == 0][0])
        notes.append(f"warning: ground truth repeats {n_repeats} stamp{'s' if n_repeats > 1 else ''} (first "
                     f"{format_stamp(first)} s); the first pose of each is used")
    gt = gt_unique
    if len(gt) < 2:
        raise EvaluationError(_too_few("the ground truth", gt)
                              + (f" (its {n_repeats + 1} poses share that stamp)" if n_repeats else "")
                              + " to score an estimate against it")
    order = np.argsort(est.stamps_ns, kind="stable")
    est = Trajectory(est.stamps_ns[order], est.T_w_b[order])
    ok_all = np.ones(len(est), bool) if est_ok is None else np.asarray(est_ok, bool)[order]
    if len(ok_all) != len(est):
        raise EvaluationError(f"{len(ok_all)} status flags for {len(est)} estimate poses")
    repeats = np.flatnonzero(np.diff(est.stamps_ns) == 0)
    if len(repeats):
        raise EvaluationError(f"the estimate repeats {len(repeats)} stamp{'s' if len(repeats) > 1 else ''} (first "
                              f"{format_stamp(est.stamps_ns[repeats[0]])} s): one pose per stamp is needed, "
                              "every copy would be matched and scored")
    tol_ns = int(round(opts.max_diff_s * 1e9))
    ig, ie = associate(gt.stamps_ns, est.stamps_ns, tol_ns)
    if len(ig) < 2:
        raise EvaluationError(_no_match_message(gt, est, len(ig), tol_ns))
    sparse = _sparse_note(gt, est, ie, tol_ns)
    if sparse:
        notes.append(sparse)
    T_gt, stamps = gt.T_w_b[ig], est.stamps_ns[ie]
    if opts.interpolate_gt:  # same pairs, ground truth resampled at the estimate stamps (evo's interpolation sync)
        T_gt = interpolate_trajectory(gt.stamps_ns, gt.T_w_b, stamps)[0]
    T_raw = est.T_w_b[ie]
    # An absurd (finite) position overflows squares and norms: numpy's RuntimeWarnings would go to
    # stderr mid-output; the non-finite results are named in a note instead (see _score).
    with np.errstate(over="ignore", invalid="ignore"):
        T_est, info = align(T_gt, T_raw, stamps, opts)
        return _score(gt, est, T_gt, T_est, T_raw, stamps, ok_all, ie, info, opts, _check_divergence,
                      has_status=est_ok is not None, notes=notes)


# A warning when fewer than this share of the estimate poses inside the ground truth's span are matched.
SPARSE_MATCH_SHARE = 0.5


def _median_period_s(stamps_ns: np.ndarray) -> float:
    return float(np.median(np.diff(stamps_ns))) * 1e-9 if len(stamps_ns) > 1 else 0.0


def _too_few(what: str, traj: Trajectory) -> str:
    """"<what> has only 1 pose (at t s): at least 2 are needed" (or "has no poses")."""
    if len(traj) == 0:
        return f"{what} has no poses: at least 2 are needed"
    return f"{what} has only 1 pose (at {format_stamp(traj.stamps_ns[0])} s): at least 2 are needed"


def _no_match_message(gt: Trajectory, est: Trajectory, n: int, tol_ns: int) -> str:
    """Why fewer than 2 poses matched: the time ranges miss each other, or the stamps interleave too coarsely."""
    g0, g1, e0, e1 = gt.stamps_ns[0], gt.stamps_ns[-1], est.stamps_ns[0], est.stamps_ns[-1]
    head = (f"only {n} estimate poses match ground truth within {tol_ns * 1e-6:g} ms (ground truth "
            f"{g0 * 1e-9:.3f}-{g1 * 1e-9:.3f} s, estimate {e0 * 1e-9:.3f}-{e1 * 1e-9:.3f} s)")
    if e0 > g1 + tol_ns or e1 < g0 - tol_ns:
        return f"{head}: the time ranges do not overlap; check the time bases"
    return (f"{head}: ground truth has one pose every {_median_period_s(gt.stamps_ns):.3f} s and the estimate one "
            f"every {_median_period_s(est.stamps_ns):.3f} s (medians); check the time bases and the tolerance")


def _sparse_note(gt: Trajectory, est: Trajectory, ie: np.ndarray, tol_ns: int) -> str | None:
    """A warning when few estimate poses inside the ground truth's span found a ground-truth pose."""
    inside = int(np.count_nonzero((est.stamps_ns >= gt.stamps_ns[0] - tol_ns)
                                  & (est.stamps_ns <= gt.stamps_ns[-1] + tol_ns)))
    n = len(np.unique(ie))
    if n >= SPARSE_MATCH_SHARE * inside:
        return None
    gt_period = _median_period_s(gt.stamps_ns)
    cause = (f"ground truth has one pose every {gt_period:.3f} s and the estimate one every "
             f"{_median_period_s(est.stamps_ns):.3f} s, medians" if gt_period > 2 * tol_ns * 1e-9
             else "ground truth has gaps")
    return (f"warning: only {n} of the {inside} estimate poses within the ground truth's time span are within "
            f"{tol_ns * 1e-6:g} ms of a ground-truth pose ({cause}): the metrics rest on these {n} poses and "
            f"the RPE per frame spans {_median_period_s(est.stamps_ns[np.sort(ie)]):.3f} s")


def _score(gt: Trajectory, est: Trajectory, T_gt: np.ndarray, T_est: np.ndarray, T_raw: np.ndarray,
           stamps: np.ndarray, ok_all: np.ndarray, ie: np.ndarray, info: dict, opts: EvalOptions,
           check: bool, *, has_status: bool = False, notes: list[str] | None = None) -> EvalResult:
    """The metrics of matched, aligned poses; with ``check`` also tracking, divergence and the partial score."""
    n = len(stamps)
    pos_err = np.linalg.norm(T_est[:, :3, 3] - T_gt[:, :3, 3], axis=1)
    ate = float(np.sqrt(np.mean(pos_err ** 2)))
    idx = np.arange(n)
    rot_f, trans_f = relative_errors(T_gt, T_est, idx[:-1], idx[1:])
    si, sj = angle_segments(T_gt, opts.delta_deg)
    rot_d, trans_d = relative_errors(T_gt, T_est, si, sj)
    rot_dd, trans_dd = _mean(rot_d), _mean(trans_d)
    # tracked: the frames the odometry was asked to track (every estimate pose) that it tracked: status ok,
    # or, with no statuses (a TUM file), matched to ground truth.
    n_tracked = int(np.count_nonzero(ok_all)) if has_status else int(len(np.unique(ie)))
    metrics: dict[str, Any] = {
        "ate_rmse_m": ate,
        "rpe_rot_deg_per_frame": _mean(rot_f),
        "rpe_trans_cm_per_frame": None if not len(trans_f) else float(np.mean(trans_f) * 100.0),
        "rpe_rot_deg_per_deg": rot_dd,
        "rpe_trans_cm_per_deg": None if trans_dd is None else trans_dd * 100.0,
        "diverged": False,
        "diverged_at_s": None,
        "tracked_fraction": n_tracked / len(est) if check else None,
        "n_matched": int(n),
    }
    extra: dict[str, Any] = {
        "alignment": info,
        "association": "interpolated" if opts.interpolate_gt else "nearest",
        "ate_mean_m": float(np.mean(pos_err)),
        "ate_max_m": float(np.max(pos_err)),
        "rpe_rot_deg_per_frame_rmse": None if not len(rot_f) else float(np.sqrt(np.mean(rot_f ** 2))),
        "rpe_trans_cm_per_frame_rmse": None if not len(trans_f) else float(np.sqrt(np.mean(trans_f ** 2)) * 100),
        "n_segments_per_deg": len(si),
        **_ratio_per_deg(T_gt, rot_f, trans_f),
        "delta_deg": opts.delta_deg,
        "max_diff_s": opts.max_diff_s,
        "n_ok_matched": int(np.count_nonzero(ok_all[ie])),
        "duration_s": float((stamps[-1] - stamps[0]) * 1e-9),
    }
    if check:
        notes = list(notes or [])
        extra.update({"n_estimate": len(est), "n_tracked": n_tracked,
                      "tracked_by": "reported ok" if has_status else "matched to ground truth",
                      "gt_span_covered": _gt_span_covered(gt, est.stamps_ns, ok_all), "notes": notes})
        bad = _non_finite_keys({**metrics, "extra": extra})
        if bad:
            far = np.abs(T_est[:, :3, 3]).max(axis=1)
            k = int(np.argmax(far))
            why = (f": an aligned estimate position of {far[k]:.3g} m (at {(stamps[k] - stamps[0]) * 1e-9:.3f} s) "
                   "overflows their squares" if far[k] > 1e150 else "")
            notes.append(f"warning: {', '.join(bad)} not finite{why}; written as null")
    result = EvalResult(metrics, stamps, T_gt, T_est, pos_err, rot_f, trans_f, extra=extra)
    if not check:
        return result
    at = _divergence_index(pos_err, rot_d, trans_d, sj, opts)
    diverged = (ate > opts.ate_limit_m
                or (rot_dd is not None and rot_dd > opts.rpe_rot_limit_deg_per_deg)
                or (trans_dd is not None and trans_dd > opts.rpe_trans_limit_m_per_deg))
    if at is not None or diverged:
        metrics["diverged"] = True
        if at is None:  # the final value crosses a limit only by the min_segments rule
            at = n - 1
        metrics["diverged_at_s"] = float((stamps[at] - stamps[0]) * 1e-9)
        if at >= 3:  # the part before divergence, aligned on its own (diverged poses do not pull the fit)
            sub = slice(0, at)
            try:
                T_sub, info_sub = align(T_gt[sub], T_raw[sub], stamps[sub], opts)
            except EvaluationError:
                T_sub, info_sub = T_est[sub], info
            result.partial = _score(gt, est, T_gt[sub], T_sub, T_raw[sub], stamps[sub], ok_all, ie[sub], info_sub,
                                    opts, False)
    return result


def _divergence_index(pos_err: np.ndarray, rot_d: np.ndarray, trans_d: np.ndarray, seg_end: np.ndarray,
                      opts: EvalOptions) -> int | None:
    """First matched index at which a running metric crosses its divergence limit (or None)."""
    n = len(pos_err)
    running_ate = np.sqrt(np.cumsum(pos_err ** 2) / np.arange(1, n + 1))
    cand = np.flatnonzero(running_ate > opts.ate_limit_m)
    first = int(cand[0]) if len(cand) else None
    if len(rot_d):
        k = np.arange(1, len(rot_d) + 1)
        bad = ((np.cumsum(rot_d) / k > opts.rpe_rot_limit_deg_per_deg)
               | (np.cumsum(trans_d) / k > opts.rpe_trans_limit_m_per_deg)) & (k >= opts.min_segments)
        seg = np.flatnonzero(bad)
        if len(seg):
            j = int(seg_end[seg[0]])
            first = j if first is None else min(first, j)
    return first


def evaluate_files(gt_path: str, est_path: str, opts: EvalOptions | None = None) -> EvalResult:
    """:func:`evaluate` on two TUM files, read as atsvo-eval reads them.

    The estimate's stamps must increase line by line and the ground truth's must not decrease
    (:func:`~atsvo_ros.io.trajectory.read_tum` names the offending line otherwise).
    """
    return evaluate(read_tum(gt_path, order="nondecreasing"), read_tum(est_path, order="increasing"), opts)


ASSOCIATION_TEXT = {"interpolated": "ground truth interpolated at the stamps",
                    "nearest": "nearest ground-truth pose"}


def describe_alignment(info: dict[str, Any] | None) -> str:
    """How the estimate was aligned, in words (from ``extra["alignment"]``), for the line next to the ATE."""
    if not info:
        return "not recorded"
    method = info.get("method")
    if method == "none":
        return "none"
    if method == "origin":
        return "first pose onto ground truth's (the odometry's drift)"
    if method in ("se3", "sim3"):
        text = f"{'SE(3)' if method == 'se3' else 'Sim(3)'} Umeyama over all {info.get('n_poses')} matched poses"
        return text + (f", scale {info['scale']:.4f}" if method == "sim3" and info.get("scale") is not None else "")
    if "fallback" in info:
        return "first pose onto ground truth's, as ground truth hardly moves at the start"
    return (f"SE(3) Umeyama on the first {info.get('window_s', 0.0):.2f} s ({info.get('n_poses')} poses), "
            "then the first orientation")


def format_metrics(metrics: dict[str, Any]) -> str:
    """Human-readable multi-line summary of a metrics.json document (:meth:`EvalResult.to_json`).

    One vocabulary for atsvo-replay and atsvo-eval: the ATE with the alignment that produced it,
    the RPE per frame as its RMSE (``evo_rpe``'s and the benches' statistic; the mean is the JSON's
    top-level value) with the association named, so numbers printed by different tools can be
    compared. A bare ``EvalResult.metrics`` dict (no ``extra``) prints the mean RPE, labelled so.
    """
    def f(v: Any, scale: float = 1.0, fmt: str = ".4f") -> str:
        return "n/a" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v * scale, fmt)

    extra = metrics.get("extra") or {}
    if "rpe_rot_deg_per_frame_rmse" in extra:
        stat, rot_f, trans_f = "RMSE", extra["rpe_rot_deg_per_frame_rmse"], extra["rpe_trans_cm_per_frame_rmse"]
    else:
        stat, rot_f, trans_f = "mean", metrics["rpe_rot_deg_per_frame"], metrics["rpe_trans_cm_per_frame"]
    association = ASSOCIATION_TEXT.get(extra.get("association"), "association not recorded")
    matched = f"matched poses        {metrics['n_matched']}"
    if extra.get("n_estimate") is not None and extra.get("max_diff_s") is not None:
        matched += (f" of {extra['n_estimate']} estimate poses (within {extra['max_diff_s'] * 1e3:g} ms "
                    "of a ground-truth pose)")
    per_deg = "RPE per degree, mean"
    if extra.get("n_segments_per_deg") is not None and extra.get("delta_deg") is not None:
        n_seg = extra["n_segments_per_deg"]
        per_deg += f" over {n_seg} segment{'' if n_seg == 1 else 's'} of {extra['delta_deg']:g} deg"
    tracked = f"tracked fraction     {f(metrics['tracked_fraction'], 1.0, '.3f')}"
    if extra.get("n_tracked") is not None:
        tracked += f" ({extra['n_tracked']} of {extra['n_estimate']} estimate poses {extra['tracked_by']})"
    div = f"yes, at {metrics['diverged_at_s']:.2f} s" if metrics["diverged"] else "no"
    lines = [
        matched,
        f"ATE RMSE             {f(metrics['ate_rmse_m'], 100.0, '.2f')} cm "
        f"(aligned: {describe_alignment(extra.get('alignment')) if extra else 'not recorded'})",
        f"RPE per frame, {stat}, {association}: {f(rot_f)} deg/f  {f(trans_f)} cm/f",
        f"{per_deg}: {f(metrics['rpe_rot_deg_per_deg'])} deg/d  {f(metrics['rpe_trans_cm_per_deg'])} cm/d",
        tracked,
        f"diverged             {div}",
    ]
    return "\n".join(lines)


__all__ = ["ALIGN_METHODS", "ASSOCIATION_TEXT", "EvalOptions", "EvalResult", "align", "angle_segments", "associate",
           "describe_alignment", "evaluate", "errors_by_label", "evaluate_files", "format_metrics", "metrics_json",
           "relative_errors", "rotation_angle_deg", "umeyama"]
