"""Trajectory metrics: association, alignment, ATE, RPE per frame and per degree, divergence.

Definitions (numpy only; ``evo`` is used in the tests as an independent cross-check):

* Association: nearest stamp within ``max_diff_s`` (default 10 ms), searched from the trajectory
  with fewer poses into the longer one, ties to the earlier stamp -- the pairing of
  ``evo.core.sync.associate_trajectories``. With ``interpolate_gt`` the same pairs are kept but
  ground truth is interpolated at the estimate stamps (evo's ``SyncMethod.interpolation``); the
  replay tool uses it because a 100 Hz ground truth is up to 5 ms away from a frame otherwise.
* Alignment of the estimate onto ground truth (``align``):
  ``paper`` -- the paper's protocol (Section III): SE(3) Umeyama on the beginning frames -- the
  matched poses of the first ``align_s`` seconds (2 s) but at most ``align_fraction`` (20 %) of
  them and at least 3 -- applied to the whole estimate, then an SO(3) alignment: one constant
  rotation of the body frame (right-multiplied) that makes the first estimated orientation equal
  to ground truth's, positions untouched. When ground truth hardly moves in that window (less than
  ``min_align_spread_m`` off a straight line: Umeyama's rotation would be unobservable), the first
  pose is put onto ground truth's instead (``evo --align_origin``). ``se3`` / ``sim3`` -- Umeyama over all
  matched poses without / with scale (``evo -a`` / ``-as``). ``none`` -- as is.
* ATE: RMSE of the position differences of the aligned matched poses.
* RPE per frame: for consecutive matched pairs, ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``; rotation
  error = angle of E (deg), translation error = norm of E's translation (cm); reported as means
  (like the paper's tables; ``evo_rpe --delta 1 --delta_unit f``).
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
* ``tracked_fraction``: ground-truth time span covered by matched estimate poses whose status is
  ok (gaps longer than twice the median estimate period do not count), over the ground-truth span.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from atsvo_ros.core.geometry import interpolate_trajectory, se3_inv
from atsvo_ros.errors import EvaluationError
from atsvo_ros.io.trajectory import Trajectory, read_tum

ALIGN_METHODS = ("paper", "se3", "sim3", "none")


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
        if not self.max_diff_s >= 0 or not self.align_s > 0 or not 0 < self.delta_deg <= 180:
            raise EvaluationError("max_diff_s must be >= 0, align_s > 0 and delta_deg in (0, 180]")


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
        """The metrics.json document: the issue's keys at top level, the rest under ``extra``."""
        out = dict(self.metrics)
        extra = dict(self.extra)
        if self.partial is not None:
            extra["partial"] = {k: v for k, v in self.partial.metrics.items()
                                if k not in ("diverged", "diverged_at_s", "tracked_fraction")}
        out["extra"] = extra
        return out


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
    mx, my = x.mean(0), y.mean(0)
    xc, yc = x - mx, y - my
    var_x = np.sum(xc * xc) / len(x)
    cov = yc.T @ xc / len(x)
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
        out = (T_gt[0] @ se3_inv(T_est[0]))[None] @ T_est
        info["fallback"] = (f"first pose (ground truth moves less than {opts.min_align_spread_m} m "
                            "off a line in the alignment window)")
    return out, info


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


def _tracked_fraction(gt: Trajectory, stamps_ns: np.ndarray, ok: np.ndarray) -> float:
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
    """Score ``est`` against ``gt``; ``est_ok`` marks estimate poses tracked with status ok."""
    opts = opts or EvalOptions()
    gt = gt.sorted_unique()
    order = np.argsort(est.stamps_ns, kind="stable")
    est = Trajectory(est.stamps_ns[order], est.T_w_b[order])
    ok_all = np.ones(len(est), bool) if est_ok is None else np.asarray(est_ok, bool)[order]
    if len(ok_all) != len(est):
        raise EvaluationError(f"{len(ok_all)} status flags for {len(est)} estimate poses")
    ig, ie = associate(gt.stamps_ns, est.stamps_ns, int(round(opts.max_diff_s * 1e9)))
    if len(ig) < 2:
        raise EvaluationError(f"only {len(ig)} estimate poses match ground truth within {opts.max_diff_s * 1e3:g} ms "
                              f"(ground truth {gt.stamps_ns[0] * 1e-9:.3f}-{gt.stamps_ns[-1] * 1e-9:.3f} s, estimate "
                              f"{est.stamps_ns[0] * 1e-9:.3f}-{est.stamps_ns[-1] * 1e-9:.3f} s); check the time bases")
    T_gt, stamps = gt.T_w_b[ig], est.stamps_ns[ie]
    if opts.interpolate_gt:  # same pairs, ground truth resampled at the estimate stamps (evo's interpolation sync)
        T_gt = interpolate_trajectory(gt.stamps_ns, gt.T_w_b, stamps)[0]
    T_raw = est.T_w_b[ie]
    T_est, info = align(T_gt, T_raw, stamps, opts)
    return _score(gt, est, T_gt, T_est, T_raw, stamps, ok_all, ie, info, opts, _check_divergence)


def _score(gt: Trajectory, est: Trajectory, T_gt: np.ndarray, T_est: np.ndarray, T_raw: np.ndarray,
           stamps: np.ndarray, ok_all: np.ndarray, ie: np.ndarray, info: dict, opts: EvalOptions,
           check: bool) -> EvalResult:
    n = len(stamps)
    pos_err = np.linalg.norm(T_est[:, :3, 3] - T_gt[:, :3, 3], axis=1)
    ate = float(np.sqrt(np.mean(pos_err ** 2)))
    idx = np.arange(n)
    rot_f, trans_f = relative_errors(T_gt, T_est, idx[:-1], idx[1:])
    si, sj = angle_segments(T_gt, opts.delta_deg)
    rot_d, trans_d = relative_errors(T_gt, T_est, si, sj)
    rot_dd, trans_dd = _mean(rot_d), _mean(trans_d)
    metrics: dict[str, Any] = {
        "ate_rmse_m": ate,
        "rpe_rot_deg_per_frame": _mean(rot_f),
        "rpe_trans_cm_per_frame": None if not len(trans_f) else float(np.mean(trans_f) * 100.0),
        "rpe_rot_deg_per_deg": rot_dd,
        "rpe_trans_cm_per_deg": None if trans_dd is None else trans_dd * 100.0,
        "diverged": False,
        "diverged_at_s": None,
        "tracked_fraction": _tracked_fraction(gt, est.stamps_ns, ok_all) if check else None,
        "n_matched": int(n),
    }
    extra: dict[str, Any] = {
        "alignment": info,
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
    """:func:`evaluate` on two TUM files."""

    return evaluate(read_tum(gt_path), read_tum(est_path), opts)


def format_metrics(metrics: dict[str, Any]) -> str:
    """Human-readable multi-line summary of a metrics dict."""
    def f(v: Any, scale: float = 1.0, fmt: str = ".4f") -> str:
        return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v * scale, fmt)

    div = f"yes, at {metrics['diverged_at_s']:.2f} s" if metrics["diverged"] else "no"
    lines = [
        f"matched poses        {metrics['n_matched']}",
        f"ATE RMSE             {f(metrics['ate_rmse_m'], 100.0, '.2f')} cm",
        f"RPE per frame        {f(metrics['rpe_rot_deg_per_frame'])} deg/f  "
        f"{f(metrics['rpe_trans_cm_per_frame'])} cm/f",
        f"RPE per degree       {f(metrics['rpe_rot_deg_per_deg'])} deg/d  {f(metrics['rpe_trans_cm_per_deg'])} cm/d",
        f"tracked fraction     {f(metrics['tracked_fraction'], 1.0, '.3f')}",
        f"diverged             {div}",
    ]
    return "\n".join(lines)


__all__ = ["ALIGN_METHODS", "EvalOptions", "EvalResult", "align", "angle_segments", "associate", "evaluate",
           "errors_by_label", "evaluate_files", "format_metrics", "relative_errors", "rotation_angle_deg", "umeyama"]
