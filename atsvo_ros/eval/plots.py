"""Matplotlib (Agg) figures of a run: paths, position and roll/pitch/yaw over time, errors over time.

Every function writes PNG files into a directory and returns their paths; nothing is shown on
screen, so the plots work on headless machines and in CI.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from atsvo_ros.eval.metrics import EvalResult
from atsvo_ros.io.trajectory import Trajectory


def _plt():
    matplotlib.use("Agg", force=True)

    return plt


def _save(plt, fig, path: Path) -> Path:
    """Lay out, write (PNG, 110 dpi) and close ``fig``; ``path``."""
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def rpy_deg(T: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (ZYX, degrees) of (N, 4, 4) poses, continuous over time.

    Each rotation has two ZYX solutions, ``(r, p, y)`` and ``(r + 180, 180 - p, y + 180)``; the one
    nearest the previous sample is kept, so a flip through pitch 90 deg (a backflip) is drawn as a
    continuous curve instead of jumps of 180 deg.
    """
    R = T[:, :3, :3]
    a = np.stack([np.arctan2(R[:, 2, 1], R[:, 2, 2]), np.arcsin(np.clip(-R[:, 2, 0], -1.0, 1.0)),
                  np.arctan2(R[:, 1, 0], R[:, 0, 0])], 1)
    b = np.stack([a[:, 0] + np.pi, np.pi - a[:, 1], a[:, 2] + np.pi], 1)
    out = np.empty_like(a)
    prev = None
    for i in range(len(a)):  # sequential by nature: each choice depends on the previous one
        best = None
        for cand in (a[i], b[i]):
            c = cand if prev is None else prev + (cand - prev + np.pi) % (2 * np.pi) - np.pi
            if best is None or (prev is not None and np.abs(c - prev).sum() < np.abs(best - prev).sum()):
                best = c
        out[i] = prev = best
    return np.degrees(out)


def _series(est: Trajectory, result: EvalResult | None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, int]:
    """Time (s from start), estimate poses, matched GT poses (or None) and the start stamp."""
    if result is not None:
        t0 = int(result.stamps_ns[0])
        return (result.stamps_ns - t0) * 1e-9, result.T_w_est, result.T_w_gt, t0
    t0 = int(est.stamps_ns[0]) if len(est) else 0
    return (est.stamps_ns - t0) * 1e-9, est.T_w_b, None, t0


def plot_run(out_dir: str | Path, est: Trajectory, result: EvalResult | None = None,
             title: str = "") -> list[Path]:
    """Write trajectory.png (top + side view), position.png, orientation.png and, with ground
    truth, error.png; returns the written paths."""
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

    for name, values, unit, labels in (("position", lambda T: T[:, :3, 3], "m", "xyz"),
                                       ("orientation", rpy_deg, "deg", ("roll", "pitch", "yaw"))):
        fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
        ve = values(P) if len(P) else np.zeros((0, 3))
        vg = values(G) if G is not None and len(G) else None
        for k, ax in enumerate(axes):
            if vg is not None:
                ax.plot(t, vg[:, k], "k-", lw=1.2, label="ground truth")
            ax.plot(t, ve[:, k], "-", color="tab:red", lw=1.0, label=label_est)
            if div_t is not None:
                ax.axvline(div_t, color="tab:orange", ls="--", label="diverged")
            ax.set_ylabel(f"{labels[k]} [{unit}]")
            ax.grid(True, alpha=0.3)
        axes[0].legend(loc="best", fontsize=8)
        axes[-1].set_xlabel("time [s]")
        fig.suptitle(f"{title} {name}".strip())
        paths.append(_save(plt, fig, out / f"{name}.png"))

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
            if div_t is not None:
                ax.axvline(div_t, color="tab:orange", ls="--")
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


__all__ = ["plot_comparison", "plot_memory", "plot_run", "rpy_deg"]
