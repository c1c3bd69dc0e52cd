"""Matplotlib (Agg) figures of a run: paths, position and roll/pitch/yaw over time, errors over time.

Every function writes PNG files into a directory and returns their paths; nothing is shown on
screen, so the plots work on headless machines and in CI. The data behind the orientation figure
comes from :func:`orientation_series`, a pure function (no matplotlib) that the tests check.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from atsvo_ros.errors import EvaluationError
from atsvo_ros.eval.metrics import EvalResult, rotation_angle_deg
from atsvo_ros.io.trajectory import Trajectory

#: Roll and yaw are left out of the orientation figure where pitch is within this many degrees of
#: +-90 (gimbal lock): there only their difference or sum is defined, and a rotation error of 1 deg
#: moves each of them by up to 1 / sin(margin) deg (5.8 deg at 10 deg), which reads as error.
GIMBAL_MARGIN_DEG = 10.0
#: The largest step in pitch (180 - 2 |pitch| at its nearest to +-90 deg) accepted to draw a pass by
#: the pole as a flip over the top, pitch going on beyond 90 deg, rather than as pitch turning back.
_FLIP_STEP_DEG = 5.0


def _plt():
    matplotlib.use("Agg", force=True)

    return plt


def _save(plt, fig, path: Path) -> Path:
    """Lay out, write (PNG, 110 dpi) and close ``fig``; ``path``."""
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _zyx_candidates(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two ZYX solutions (roll, pitch, yaw; radians) of (N, 3, 3) rotations: ``(r, p, y)`` with
    ``|p| <= 90 deg`` and ``(r + 180, 180 - p, y + 180)``."""
    a = np.stack([np.arctan2(R[:, 2, 1], R[:, 2, 2]), np.arcsin(np.clip(-R[:, 2, 0], -1.0, 1.0)),
                  np.arctan2(R[:, 1, 0], R[:, 0, 0])], 1)
    return a, np.stack([a[:, 0] + np.pi, np.pi - a[:, 1], a[:, 2] + np.pi], 1)


def _unwrap_to(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``x`` moved by whole turns per angle to lie within 180 deg of ``ref`` (np.unwrap's rule)."""
    return ref + (x - ref + np.pi) % (2 * np.pi) - np.pi


def _nearest_candidate(a: np.ndarray, b: np.ndarray, ref: np.ndarray | None) -> tuple[np.ndarray, bool]:
    """Of the solutions ``a`` and ``b``, each unwrapped to ``ref``, the one nearest ``ref`` (sum of
    absolute differences) and whether it is ``b``; ``a`` as is without a reference."""
    if ref is None:
        return a, False
    ca, cb = _unwrap_to(a, ref), _unwrap_to(b, ref)
    use_b = bool(np.abs(cb - ref).sum() < np.abs(ca - ref).sum())
    return (cb if use_b else ca), use_b


def rpy_deg(T: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (ZYX, degrees) of (N, 4, 4) poses, continuous over time.

    Each rotation has two ZYX solutions, ``(r, p, y)`` and ``(r + 180, 180 - p, y + 180)``; the one
    nearest the previous sample is kept and every angle is unwrapped (no jump at +-180 deg), so a flip
    through pitch 90 deg (a backflip) is drawn as a continuous curve instead of jumps of 180 deg.
    """
    a, b = _zyx_candidates(T[:, :3, :3])
    out = np.empty_like(a)
    prev = None
    for i in range(len(a)):  # sequential by nature: each choice depends on the previous one
        out[i], _ = _nearest_candidate(a[i], b[i], prev)
        prev = out[i]
    return np.degrees(out)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, end)`` of the runs of equal values in ``mask``."""
    cuts = [0, *(np.flatnonzero(np.diff(mask.astype(np.int8))) + 1).tolist(), len(mask)]
    return [(i, j) for i, j in zip(cuts[:-1], cuts[1:]) if j > i]


def _continuous_rpy(R: np.ndarray, gimbal: np.ndarray, anchor: np.ndarray | None = None) -> np.ndarray:
    """Roll, pitch, yaw (radians) of (N, 3, 3) rotations for a plot: unwrapped, on one ZYX solution at a
    time, roll and yaw NaN where ``gimbal``.

    Outside the gaps each sample continues the previous one (as :func:`rpy_deg`). A stretch starts
    on the solution and turn nearest ``anchor`` at its first sample (ground truth's angles, for an
    estimate) or else nearest the last drawn sample before the gap -- roll and yaw inside a gap are
    noise, so they must not decide -- but without ``anchor`` it changes solution across a gap only if
    pitch came within ``_FLIP_STEP_DEG / 2`` of +-90 deg (a flip over the top); otherwise pitch turned
    back (where roll and yaw really swing by 180 deg, hidden by the gap). In a gap pitch is drawn on
    the solution it entered with and switches where it comes closest to +-90 deg, where the two
    solutions meet, so pitch stays continuous.
    """
    a, b = _zyx_candidates(R)
    n = len(a)
    out = np.full((n, 3), np.nan)
    on_b = np.zeros(n, dtype=bool)
    runs = _runs(gimbal)
    last = None
    for r, (i, j) in enumerate(runs):  # the drawn stretches first: the gaps take their solution from both ends
        if gimbal[i]:
            continue
        ref = anchor[i] if anchor is not None else last
        out[i], on_b[i] = _nearest_candidate(a[i], b[i], ref)
        if anchor is None and r >= 2:  # after a gap: through the pole only if pitch came that close to it
            gi, gj = runs[r - 1]
            if on_b[i] != on_b[gi - 1] and np.abs(a[gi:gj, 1]).max() < np.pi / 2 - np.radians(_FLIP_STEP_DEG) / 2:
                on_b[i] = on_b[gi - 1]
                out[i] = _unwrap_to(b[i] if on_b[i] else a[i], last)
        for k in range(i + 1, j):
            out[k], on_b[k] = _nearest_candidate(a[k], b[k], out[k - 1])
        last = out[j - 1]
    for i, j in runs:
        if not gimbal[i]:
            continue
        enter = bool(on_b[i - 1]) if i > 0 else None
        leave = bool(on_b[j]) if j < n else None
        enter = (leave or False) if enter is None else enter
        leave = enter if leave is None else leave
        switch = i + int(np.argmax(np.abs(a[i:j, 1]))) + 1 if enter != leave else j
        prev = out[i - 1, 1] if i > 0 else None
        for k in range(i, j):
            pitch = b[k, 1] if (enter if k < switch else leave) else a[k, 1]
            out[k, 1] = prev = pitch if prev is None else _unwrap_to(pitch, prev)
    return out


@dataclass(frozen=True)
class OrientationSeries:
    """What the orientation figure draws, sample by sample (all angles in degrees).

    Attributes:
        t_s: time of each sample, seconds from the first.
        rpy_est_deg: (N, 3) roll, pitch, yaw of the estimate, unwrapped; roll and yaw NaN (a gap in
            the curve) where the estimate or ground truth is within the margin of gimbal lock.
        rpy_gt_deg: the same for ground truth, or None without it.
        rot_error_deg: (N,) angle of ``R_gt^T R_est`` (the estimate as given, i.e. after the
            alignment), or None without ground truth. Free of any Euler-angle singularity.
        gimbal: (N,) True where roll and yaw are left out.
    """

    t_s: np.ndarray
    rpy_est_deg: np.ndarray
    rpy_gt_deg: np.ndarray | None
    rot_error_deg: np.ndarray | None
    gimbal: np.ndarray


def orientation_series(t_s: np.ndarray, T_est: np.ndarray, T_gt: np.ndarray | None = None,
                       margin_deg: float = GIMBAL_MARGIN_DEG) -> OrientationSeries:
    """Roll/pitch/yaw of estimate and ground truth and the rotation error over time, ready to plot.

    Euler angles of a real trajectory jump where they wrap at +-180 deg and swing where pitch nears
    +-90 deg (gimbal lock), which a plot shows as spikes that are not error. Here each series is
    unwrapped and kept on one ZYX solution at a time (as :func:`rpy_deg`); the estimate starts, and
    restarts after each gap, on the solution and turn nearest ground truth's at that sample, so the
    two curves differ only by the error. Roll and yaw are NaN where either series is within
    ``margin_deg`` of pitch +-90 deg; pitch stays drawn. The rotation error angle, read from the
    rotation matrices, needs no such care.

    Args:
        t_s: (N,) sample times in seconds.
        T_est: (N, 4, 4) estimated poses (already aligned onto ground truth, when there is one).
        T_gt: (N, 4, 4) ground-truth poses at the same samples, or None.
        margin_deg: how close to pitch +-90 deg roll and yaw are still drawn.

    Returns:
        The series; see :class:`OrientationSeries`.

    Raises:
        EvaluationError: ``T_gt`` does not hold one pose per estimate pose.
    """
    R_e = np.asarray(T_est, dtype=np.float64)[:, :3, :3]
    R_g = None if T_gt is None else np.asarray(T_gt, dtype=np.float64)[:, :3, :3]
    if R_g is not None and R_g.shape != R_e.shape:
        raise EvaluationError(f"orientation_series: {len(R_e)} estimate poses but {len(R_g)} ground-truth poses")
    limit = np.cos(np.radians(margin_deg))  # |sin(pitch)| = |R[2, 0]| above this: too close to +-90 deg
    gimbal = np.abs(R_e[:, 2, 0]) > limit
    if R_g is not None:
        gimbal |= np.abs(R_g[:, 2, 0]) > limit
    rpy_gt = None if R_g is None else _continuous_rpy(R_g, gimbal)
    rpy_est = _continuous_rpy(R_e, gimbal, anchor=rpy_gt)
    rot_err = None if R_g is None else rotation_angle_deg(np.swapaxes(R_g, 1, 2) @ R_e)
    return OrientationSeries(np.asarray(t_s, dtype=np.float64), np.degrees(rpy_est),
                             None if rpy_gt is None else np.degrees(rpy_gt), rot_err, gimbal)


def _series(est: Trajectory, result: EvalResult | None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, int]:
    """Time (s from start), estimate poses, matched GT poses (or None) and the start stamp."""
    if result is not None:
        t0 = int(result.stamps_ns[0])
        return (result.stamps_ns - t0) * 1e-9, result.T_w_est, result.T_w_gt, t0
    t0 = int(est.stamps_ns[0]) if len(est) else 0
    return (est.stamps_ns - t0) * 1e-9, est.T_w_b, None, t0


def _mark_divergence(ax, div_t: float | None, label: str | None = "diverged") -> None:
    """A dashed vertical line at the divergence time, if the run diverged."""
    if div_t is not None:
        ax.axvline(div_t, color="tab:orange", ls="--", label=label)


def _gimbal_spans(t: np.ndarray, gimbal: np.ndarray) -> list[tuple[float, float]]:
    """(start, end) times of the runs of consecutive samples flagged in ``gimbal``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], gimbal.astype(np.int8), [0]])))
    return [(float(t[i]), float(t[j - 1])) for i, j in zip(edges[::2], edges[1::2])]


def _plot_orientation(plt, path: Path, s: OrientationSeries, label_est: str, div_t: float | None,
                      title: str) -> Path:
    """orientation.png: roll, pitch, yaw of estimate and ground truth (unwrapped, gaps at gimbal lock)
    and, with ground truth, the rotation error angle below them -- the panel to read the error from."""
    rows = 3 if s.rot_error_deg is None else 4
    fig, axes = plt.subplots(rows, 1, figsize=(10, 2.3 * rows + 0.5), sharex=True)
    spans = _gimbal_spans(s.t_s, s.gimbal)
    for k, ax in enumerate(axes[:3]):
        if s.rpy_gt_deg is not None:
            ax.plot(s.t_s, s.rpy_gt_deg[:, k], "k-", lw=1.2, label="ground truth")
        ax.plot(s.t_s, s.rpy_est_deg[:, k], "-", color="tab:red", lw=1.0, label=label_est)
        if k != 1:
            for n, (a, b) in enumerate(spans):
                ax.axvspan(a, b, color="0.85", lw=0,
                           label=f"not drawn: pitch within {GIMBAL_MARGIN_DEG:g} deg of +-90" if n == 0 else None)
        _mark_divergence(ax, div_t)
        ax.set_ylabel(f"{('roll', 'pitch', 'yaw')[k]} [deg]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    if s.rot_error_deg is not None:
        ax = axes[3]
        ax.plot(s.t_s, s.rot_error_deg, color="tab:blue", lw=1.0)
        _mark_divergence(ax, div_t, label=None)
        ax.set_ylabel("rotation error [deg]")
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        ax.set_title("angle of R_gt^T R_est", fontsize=9, loc="left")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title} (roll/pitch/yaw: ZYX, unwrapped)" if title else "orientation (ZYX, unwrapped)")
    return _save(plt, fig, path)


def plot_run(out_dir: str | Path, est: Trajectory, result: EvalResult | None = None,
             title: str = "") -> list[Path]:
    """Write trajectory.png (top + side view), position.png, orientation.png and, with ground
    truth, error.png; returns the written paths.

    orientation.png holds roll/pitch/yaw from :func:`orientation_series` and, with ground truth, the
    rotation error angle, so Euler-angle wraps and gimbal lock are never drawn as error.
    """
    plt = _plt()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t, P, G, _ = _series(est, result)
    paths: list[Path] = []
    label_est = "estimate (aligned)" if result is not None else "estimate"
    div_t = result.metrics.get("diverged_at_s") if result is not None else None

    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    for ax, (i, j, name) in zip(axes, ((0, 1, "top view (x-y)"), (0, 2, "side view (x-z)"))):
        if G is not None:
            ax.plot(G[:, i, 3], G[:, j, 3], "k-", lw=1.5, label="ground truth")
        ax.plot(P[:, i, 3], P[:, j, 3], "-", color="tab:red", lw=1.0, label=label_est)
        if len(P):
            ax.plot(P[0, i, 3], P[0, j, 3], "o", color="tab:green", label="start")
        ax.set_xlabel("xyz"[i] + " [m]")
        ax.set_ylabel("xyz"[j] + " [m]")
        ax.set_title(name)
        ax.axis("equal")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    fig.suptitle(title or "trajectory")
    paths.append(_save(plt, fig, out / "trajectory.png"))

    fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    ve = P[:, :3, 3] if len(P) else np.zeros((0, 3))
    for k, ax in enumerate(axes):
        if G is not None:
            ax.plot(t, G[:, k, 3], "k-", lw=1.2, label="ground truth")
        ax.plot(t, ve[:, k], "-", color="tab:red", lw=1.0, label=label_est)
        _mark_divergence(ax, div_t)
        ax.set_ylabel(f"{'xyz'[k]} [m]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title} position".strip())
    paths.append(_save(plt, fig, out / "position.png"))

    paths.append(_plot_orientation(plt, out / "orientation.png", orientation_series(t, P, G), label_est, div_t,
                                   f"{title} orientation".strip()))

    if result is not None:
        fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
        axes[0].plot(t, result.position_errors_m * 100.0, color="tab:red")
        axes[0].set_ylabel("position error [cm]")
        tm = t[1:] if len(t) > 1 else t
        axes[1].plot(tm, result.rpe_rot_deg, color="tab:blue")
        axes[1].set_ylabel("RPE rot [deg/f]")
        axes[2].plot(tm, result.rpe_trans_m * 100.0, color="tab:purple")
        axes[2].set_ylabel("RPE trans [cm/f]")
        for ax in axes:
            _mark_divergence(ax, div_t, label=None)
            ax.grid(True, alpha=0.3)
        axes[-1].set_xlabel("time [s]")
        m = result.metrics
        fig.suptitle(f"{title} ATE {m['ate_rmse_m'] * 100:.2f} cm".strip())
        paths.append(_save(plt, fig, out / "error.png"))
    return paths


_COLOURS = ("tab:red", "tab:blue", "tab:green", "tab:purple", "tab:orange", "tab:brown")


def plot_comparison(path: str | Path, runs: dict[str, EvalResult], title: str = "") -> Path:
    """One figure comparing several estimates of the same sequence (each aligned to ground truth by its
    own evaluation): side and top views, height and pitch over time, position error over time.

    ``runs`` maps a label (e.g. ``fused``) to the :class:`EvalResult` of that run; ground truth is
    drawn from the first. Returns the written path.
    """
    if not runs:
        raise ValueError("plot_comparison needs at least one run")
    plt = _plt()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    first = next(iter(runs.values()))
    fig, axes = plt.subplots(2, 2, figsize=(12, 8))
    G = first.T_w_gt
    t_gt = (first.stamps_ns - first.stamps_ns[0]) * 1e-9
    for ax, (i, j, name) in zip(axes[0], ((0, 2, "side view (x-z)"), (0, 1, "top view (x-y)"))):
        ax.plot(G[:, i, 3], G[:, j, 3], "k-", lw=2.0, label="ground truth")
        for (label, r), colour in zip(runs.items(), _COLOURS):
            ate = r.metrics["ate_rmse_m"] * 100.0
            ax.plot(r.T_w_est[:, i, 3], r.T_w_est[:, j, 3], "-", color=colour, lw=1.0,
                    label=f"{label} (ATE {ate:.1f} cm)")
        ax.set_xlabel("xyz"[i] + " [m]")
        ax.set_ylabel("xyz"[j] + " [m]")
        ax.set_title(name)
        ax.axis("equal")
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize=8)
    ax = axes[1, 0]
    ax.plot(t_gt, rpy_deg(G)[:, 1], "k-", lw=2.0, label="ground truth")
    for (label, r), colour in zip(runs.items(), _COLOURS):
        ax.plot((r.stamps_ns - first.stamps_ns[0]) * 1e-9, rpy_deg(r.T_w_est)[:, 1], "-", color=colour, lw=1.0,
                label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("pitch [deg]")
    ax.grid(True, alpha=0.3)
    ax = axes[1, 1]
    for (label, r), colour in zip(runs.items(), _COLOURS):
        ax.plot((r.stamps_ns - first.stamps_ns[0]) * 1e-9, r.position_errors_m * 100.0, "-", color=colour, lw=1.0,
                label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position error [cm]")
    ax.set_yscale("log")
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(loc="best", fontsize=8)
    fig.suptitle(title or "comparison")
    return _save(plt, fig, path)


def plot_memory(path: str | Path, runs: dict[str, np.ndarray], title: str = "") -> Path:
    """Resident memory over time of several runs (``label -> (N, 2)`` of seconds, MB) in one figure.

    What a soak test is judged by: a leak is a line that keeps rising after the start-up plateau.
    """
    plt = _plt()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(9, 4))
    for (label, series), colour in zip(runs.items(), _COLOURS):
        series = np.asarray(series, dtype=float).reshape(-1, 2)
        ax.plot(series[:, 0], series[:, 1], "-", color=colour, lw=1.2, label=label)
    ax.set_xlabel("time since publishing started [s]")
    ax.set_ylabel("resident memory [MB]")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or "memory")
    return _save(plt, fig, path)


__all__ = ["GIMBAL_MARGIN_DEG", "OrientationSeries", "orientation_series", "plot_comparison", "plot_memory",
           "plot_run", "rpy_deg"]
