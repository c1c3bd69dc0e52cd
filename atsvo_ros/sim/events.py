"""DVS event model: log-intensity change detection between two renders of the event camera.

Each pixel keeps a reference log intensity. Between renders at ``t0`` and ``t1`` the log intensity
is taken as linear in time; every crossing of ``reference +/- C`` (C+ and C- per pixel, drawn once
with Gaussian mismatch) emits an event at the interpolated crossing time, rounded to the sensor's
microsecond clock, and moves the reference by one threshold, so a large change fires several
events. A pixel cannot fire again within the refractory period: a crossing that falls inside it
is postponed to its end (or to a later interval), which is what the real pixel's reset does.
Background-activity noise adds Poisson events at a per-pixel rate, independent of the signal.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from atsvo_ros.core.events import EventBatch
from atsvo_ros.errors import SimulationError


@dataclass(frozen=True)
class EventModel:
    """Event-camera parameters (thresholds in natural-log units).

    Attributes:
        contrast_pos / contrast_neg: nominal ON / OFF thresholds C+ / C-.
        contrast_sigma: per-pixel Gaussian mismatch of the thresholds (drawn once per sensor).
        contrast_min: floor of a pixel's threshold after the mismatch.
        refractory_s: dead time after an event; later crossings are postponed, not lost.
        noise_rate_hz: background-activity events per pixel and second (Poisson, random polarity).
        log_eps: dark offset in log(irradiance + log_eps): dark regions fire fewer events.
        max_step_px: largest apparent scene motion between two renders (sets the render rate).
        max_render_interval_s: render at least this often even when nothing moves.
        timestamp_resolution_ns: the sensor clock (1 us for the DVXplorer).
    """

    contrast_pos: float = 0.2
    contrast_neg: float = 0.2
    contrast_sigma: float = 0.03
    contrast_min: float = 0.05
    refractory_s: float = 0.0005
    noise_rate_hz: float = 0.1
    log_eps: float = 0.02
    max_step_px: float = 0.5
    max_render_interval_s: float = 0.01
    timestamp_resolution_ns: int = 1000

    def __post_init__(self) -> None:
        if min(self.contrast_pos, self.contrast_neg) <= 0 or self.contrast_min <= 0:
            raise SimulationError("contrast thresholds must be positive")
        if self.refractory_s < 0 or self.noise_rate_hz < 0 or self.contrast_sigma < 0:
            raise SimulationError("refractory period, noise rate and threshold sigma must be >= 0")
        if not 0 < self.max_step_px <= 5 or self.max_render_interval_s <= 0:
            raise SimulationError("max_step_px must be in (0, 5] px and max_render_interval_s > 0")
        if self.timestamp_resolution_ns < 1:
            raise SimulationError("timestamp_resolution_ns must be >= 1")


@njit(cache=True)
def _log(irradiance, eps, out):
    for i in range(irradiance.shape[0]):
        out[i] = np.log(irradiance[i] + eps)


@njit(cache=True)
def _crossings(L0, irradiance, eps, L1, t0_ns, t1_ns, ref, last_t, cpos, cneg, refractory_ns, res_ns):
    """Events of all pixels between two log-intensity images; fills ``L1`` = log(irradiance + eps) and
    updates ``ref``/``last_t`` in place."""
    n = L0.shape[0]
    cap = 0
    for i in range(n):
        L1[i] = np.log(irradiance[i] + eps)
        d = L1[i] - ref[i]
        c = cpos[i] if d > 0 else cneg[i]
        cap += int(abs(d) / c)
    idx = np.empty(cap, np.int64)
    ts = np.empty(cap, np.int64)
    pol = np.empty(cap, np.uint8)
    k = 0
    span = float(t1_ns - t0_ns)
    for i in range(n):
        a = L0[i]
        b = L1[i]
        while True:
            d = b - ref[i]
            if d >= cpos[i]:
                level = ref[i] + cpos[i]
                p = 1
            elif -d >= cneg[i]:
                level = ref[i] - cneg[i]
                p = 0
            else:
                break
            # Crossing time on the linear segment; a level already passed at t0 (postponed by the
            # refractory period) fires at t0.
            if b != a:
                frac = (level - a) / (b - a)
                if frac < 0.0:
                    frac = 0.0
                elif frac > 1.0:
                    frac = 1.0
            else:
                frac = 0.0
            tc = t0_ns + np.int64(frac * span)
            tc = (tc + res_ns // 2) // res_ns * res_ns
            if last_t[i] > -(1 << 62) and tc < last_t[i] + refractory_ns:
                tc = last_t[i] + refractory_ns
            if tc > t1_ns:
                break
            idx[k] = i
            ts[k] = tc
            pol[k] = p
            k += 1
            ref[i] = level
            last_t[i] = tc
    return idx[:k], ts[:k], pol[:k]


class EventSensor:
    """Stateful event generator for one camera: feed it log-intensity renders in time order."""

    def __init__(self, model: EventModel, width: int, height: int, rng: np.random.Generator) -> None:
        self.model = model
        self.width, self.height = int(width), int(height)
        n = self.width * self.height
        self.rng = rng
        self.c_pos = np.maximum(model.contrast_pos + model.contrast_sigma * rng.standard_normal(n),
                                model.contrast_min)
        self.c_neg = np.maximum(model.contrast_neg + model.contrast_sigma * rng.standard_normal(n),
                                model.contrast_min)
        self.ref: np.ndarray | None = None
        self.last_t = np.full(n, -(1 << 62), np.int64)
        self._L: np.ndarray | None = None
        self._t_ns: int | None = None

    def log_intensity(self, irradiance: np.ndarray) -> np.ndarray:
        """Natural log of irradiance plus the dark offset ``log_eps`` (float64, flattened)."""
        out = np.empty(np.size(irradiance))
        _log(np.ascontiguousarray(irradiance, np.float32).ravel(), np.float64(self.model.log_eps), out)
        return out

    def reset(self, irradiance: np.ndarray, t_ns: int) -> None:
        """Start from a render: the references equal the current log intensity (no events)."""
        self._L = self.log_intensity(irradiance)
        self.ref = self._L.copy()
        self._t_ns = int(t_ns)

    def step(self, irradiance: np.ndarray, t_ns: int) -> EventBatch:
        """Events between the previous render and this one (sorted by time, ties by pixel)."""
        if self._L is None or self._t_ns is None or self.ref is None:
            raise SimulationError("EventSensor.step called before reset")
        t0, t1 = self._t_ns, int(t_ns)
        if t1 <= t0:
            raise SimulationError(f"renders must move forward in time ({t0} -> {t1} ns)")
        m = self.model
        L1 = np.empty_like(self._L)
        idx, ts, pol = _crossings(self._L, np.ascontiguousarray(irradiance, np.float32).ravel(), np.float64(m.log_eps),
                                  L1, np.int64(t0), np.int64(t1), self.ref, self.last_t, self.c_pos, self.c_neg,
                                  np.int64(round(m.refractory_s * 1e9)), np.int64(m.timestamp_resolution_ns))
        self._L, self._t_ns = L1, t1
        idx, ts, pol = self._add_noise(idx, ts, pol, t0, t1)
        order = np.argsort(ts, kind="stable")
        idx = idx[order]
        return EventBatch((idx % self.width).astype(np.uint16), (idx // self.width).astype(np.uint16),
                          ts[order], pol[order], self.width, self.height)

    def _add_noise(self, idx, ts, pol, t0: int, t1: int):
        m = self.model
        n_pix = self.width * self.height
        lam = m.noise_rate_hz * n_pix * (t1 - t0) * 1e-9
        count = int(self.rng.poisson(lam)) if lam > 0 else 0
        if count == 0:
            return idx, ts, pol
        res = m.timestamp_resolution_ns
        nt = t0 + (self.rng.random(count) * (t1 - t0)).astype(np.int64)
        nt = np.minimum((nt + res // 2) // res * res, t1)
        return (np.concatenate([idx, self.rng.integers(0, n_pix, count)]), np.concatenate([ts, nt]),
                np.concatenate([pol, self.rng.integers(0, 2, count).astype(np.uint8)]))
