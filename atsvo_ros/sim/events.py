"""DVS event model of the DVXplorer Lite: log-intensity change detection with a scanned (semi-synchronous) readout.

Modelled, per pixel, between two renders of the event camera (log intensity linear in time between them):

* change detection: the pixel memorises a reference log intensity and its comparator fires when the
  log intensity leaves ``reference + C+`` / ``reference - C-`` (per-pixel thresholds with Gaussian
  mismatch, drawn once per sensor); the request is held in the pixel (one event, the first polarity);
* readout: the DVXplorer reads its array in scans every ``scan_period_s`` (~5 kHz), column by column,
  and stamps an event with the time its column is read (sensor clock ``timestamp_resolution_ns``), so
  per-pixel intervals lie on the scan lattice and the stamp's phase within a scan moves with the column
  (a whole sweep across the width: the "sliding timestamp plane"). ``scan_period_s = 0`` reads every
  request at once, like the asynchronous readout of a DAVIS;
* reset: reading a pixel resets it for ``refractory_s``; when the reset ends the reference is the log
  intensity *at that moment*. Change during the wait for the readout and during the reset is lost, not
  queued, so a pixel fires at most once per readout + refractory period and a large fast step gives
  one event, not ``|dlog I| / C`` (as the Lichtsteiner pixel's reset, which re-balances the differencing
  amplifier on the current photoreceptor output);
* background activity: Poisson requests (random polarity) at ``noise_rate_hz`` per pixel, which go
  through the same readout and reset (lost while the pixel waits or is in reset).

Not modelled: the photoreceptor's finite bandwidth (its low-pass lag; not identifiable from the
recordings we have), the readout slowing down under a very high event load (the DVXplorer's default
5 kHz scan rate is variable), the pixel noise that makes real pixels fire ON/OFF pairs two or three
scans apart (half of the real 2-3-scan intervals flip polarity), leak / intensity-dependent noise,
hot pixels, and the per-pixel spread of the refractory period.

Defaults are measured on real DVXplorer recordings (../shared/realdata: tonic sample.aedat4, 320x240;
event_camera_codecs libcaer_rollover, 640x480): event stamps = scan start + column offset with a 1 us
residual (clock rounding only); scan period 197.28 us (195.16 us on the 640x480 unit); the columns are
read from the last to the first, 192 us per sweep on both units; a pixel read in one scan is not read
again in the next (one-scan intervals: 98 of the 5344 intervals of one to six scans, all from 20 pixels).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import SimulationError

#: Largest contrast threshold, in log units (a brightness ratio of e^2 = 7.4; real sensors: 0.1-0.6).
MAX_CONTRAST = 2.0
#: Longest pixel reset after an event: 0.1 s (the DVXplorer's: ~220 us; a DAVIS's biases reach a few ms).
MAX_REFRACTORY_S = 0.1
#: Most background activity per pixel and second (real sensors: ~0.1 Hz; 100 Hz on 640x480 is 31 M events/s).
MAX_NOISE_RATE_HZ = 100.0
#: Slowest readout scan: 10 ms (100 Hz; the DVXplorer scans at ~5 kHz).
MAX_SCAN_PERIOD_S = 0.01


@dataclass(frozen=True)
class EventModel:
    """Event-camera parameters (thresholds in natural-log units, times in seconds).

    Attributes:
        contrast_pos / contrast_neg: nominal ON / OFF thresholds C+ / C-.
        contrast_sigma: per-pixel Gaussian mismatch of the thresholds (drawn once per sensor).
        contrast_min: floor of a pixel's threshold after the mismatch.
        refractory_s: reset time after a pixel is read; change during it is lost. The DVXplorer's lies
            between one and two scans (no one-scan repeats but from 20 pixels, two-scan repeats the most
            common), near one scan (those 20 pixels need a reset shorter than a scan).
        scan_period_s: readout scan period (DVXplorer: 5 kHz nominal, 197.28 us measured); 0 = the
            asynchronous readout of a DAVIS (each event stamped at its threshold crossing).
        scan_sweep_s: time the readout takes from the first read column to the last read column, within a
            scan (192 us measured; <= scan_period_s).
        scan_last_column_first: the readout sweeps from the last column (x = width - 1) to the first, as
            measured on both DVXplorer recordings.
        noise_rate_hz: background-activity requests per pixel and second (Poisson, random polarity).
        log_eps: dark offset in log(irradiance + log_eps): dark regions fire fewer events.
        max_step_px: largest apparent scene motion between two renders (sets the render rate).
        max_render_interval_s: render at least this often even when nothing moves.
        timestamp_resolution_ns: the sensor clock (1 us for the DVXplorer).
    """

    contrast_pos: float = 0.2
    contrast_neg: float = 0.2
    contrast_sigma: float = 0.03
    contrast_min: float = 0.05
    refractory_s: float = 220e-6
    scan_period_s: float = 197.28e-6
    scan_sweep_s: float = 192e-6
    scan_last_column_first: bool = True
    noise_rate_hz: float = 0.1
    log_eps: float = 0.02
    max_step_px: float = 0.5
    max_render_interval_s: float = 0.01
    timestamp_resolution_ns: int = 1000

    def __post_init__(self) -> None:
        # every test is written so that NaN fails it (a comparison with NaN is False)
        for name in ("contrast_pos", "contrast_neg", "contrast_min"):
            if not 0 < getattr(self, name) <= MAX_CONTRAST:
                raise SimulationError(f"contrast threshold {name} must be in (0, {MAX_CONTRAST:g}] log units (real "
                                      f"sensors: 0.1-0.6), got {getattr(self, name)}")
        if not 0 <= self.contrast_sigma <= MAX_CONTRAST:
            raise SimulationError(f"threshold sigma must be in [0, {MAX_CONTRAST:g}], got {self.contrast_sigma}")
        if not 0 <= self.refractory_s <= MAX_REFRACTORY_S:
            raise SimulationError(f"refractory period must be in [0, {MAX_REFRACTORY_S:g}] s (the DVXplorer's: "
                                  f"~220 us), got {self.refractory_s} s")
        if not 0 <= self.noise_rate_hz <= MAX_NOISE_RATE_HZ:
            raise SimulationError(f"noise rate must be in [0, {MAX_NOISE_RATE_HZ:g}] events per pixel and s (real "
                                  f"sensors: ~0.1), got {self.noise_rate_hz}")
        if not 0 <= self.scan_period_s <= MAX_SCAN_PERIOD_S or not 0 <= self.scan_sweep_s <= MAX_SCAN_PERIOD_S \
                or (0 < self.scan_period_s < self.scan_sweep_s):
            raise SimulationError(f"scan period ({self.scan_period_s} s) must be in [0, {MAX_SCAN_PERIOD_S:g}] s "
                                  f"(0 = asynchronous; the DVXplorer's: ~200 us) and the column sweep "
                                  f"({self.scan_sweep_s} s) >= 0 and within it")
        if not 0 < self.max_step_px <= 5 or not 0 < self.max_render_interval_s <= 1.0:
            raise SimulationError("max_step_px must be in (0, 5] px and max_render_interval_s in (0, 1] s")
        if self.timestamp_resolution_ns < 1:
            raise SimulationError("timestamp_resolution_ns must be >= 1")

    def column_offsets_ns(self, width: int) -> np.ndarray:
        """Time of each column's read after the start of a scan (float64 ns; zeros when asynchronous)."""
        if self.scan_period_s == 0:
            return np.zeros(width)
        order = np.arange(width, dtype=np.float64)
        if self.scan_last_column_first:
            order = width - 1 - order
        return order * (self.scan_sweep_s * 1e9 / width)


@njit(cache=True, nogil=True)
def _log(irradiance, eps, out):
    for i in range(irradiance.shape[0]):
        out[i] = np.log(irradiance[i] + eps)


@njit(cache=True, nogil=True)
def _pixel_events(L0, irradiance, eps, L1, t0, t1, origin, state_ref, state_arm, state_latch, state_read, cpos, cneg,
                  refr_ns, res_ns, period_ns, col_off, width, n_pix, n_t, n_pol):
    """Events of all pixels read in (t0, t1]; the log intensity is linear from ``L0`` to ``L1`` (filled here
    with log(irradiance + eps)).

    Pixel state (updated in place): ``state_ref`` reference; ``state_arm`` end of the current reset
    (the reference is taken there); ``state_latch`` held request (-1 none, 0 OFF, 1 ON, 2 = reset
    pending: the reference is still to be taken at ``state_arm``); ``state_read`` time (ns) of the held
    request's readout, stamped on the sensor clock (rounded up to ``res_ns``). Noise requests ``n_*`` are
    sorted by pixel, then time.
    """
    n = L0.shape[0]
    cap = 1024
    idx = np.empty(cap, np.int64)
    ts = np.empty(cap, np.int64)
    pol = np.empty(cap, np.uint8)
    k = 0
    span = float(t1 - t0)
    j = 0
    for i in range(n):
        a = L0[i]
        L1[i] = np.log(irradiance[i] + eps)
        while j < n_pix.shape[0] and n_pix[j] < i:
            j += 1
        if state_latch[i] == -1 and (j == n_pix.shape[0] or n_pix[j] != i):  # idle, armed, no noise request:
            d0 = a - state_ref[i]  # the segment is monotonic, so inside the thresholds at both ends = no event
            d1 = L1[i] - state_ref[i]
            if d0 < cpos[i] and d1 < cpos[i] and -d0 < cneg[i] and -d1 < cneg[i]:
                continue
        slope = (L1[i] - a) / span
        t_cur = t0
        while True:
            if state_latch[i] == 0 or state_latch[i] == 1:  # a held request: read it if its scan has come
                if state_read[i] > t1:
                    break
                if k == cap:
                    cap *= 2
                    idx = np.concatenate((idx, np.empty(cap - k, np.int64)))
                    ts = np.concatenate((ts, np.empty(cap - k, np.int64)))
                    pol = np.concatenate((pol, np.empty(cap - k, np.uint8)))
                idx[k] = i
                ts[k] = origin + (state_read[i] - origin + res_ns - 1) // res_ns * res_ns  # the sensor clock
                pol[k] = state_latch[i]
                k += 1
                t_cur = state_read[i]
                state_arm[i] = t_cur + refr_ns
                state_latch[i] = 2
            if state_latch[i] == 2:  # in reset: the reference is the log intensity when it ends
                if state_arm[i] > t1:
                    break
                state_ref[i] = a + slope * float(state_arm[i] - t0)
                state_latch[i] = -1
            t_from = max(t_cur, state_arm[i], t0)
            # First threshold crossing from t_from on (the segment is monotonic), then the first noise request.
            hi = state_ref[i] + cpos[i]
            lo = state_ref[i] - cneg[i]
            l_from = a + slope * float(t_from - t0)
            tc = t1 + 1
            p = 1
            if l_from >= hi or l_from <= lo:
                tc = t_from
                p = 1 if l_from >= hi else 0
            elif slope > 0 and L1[i] >= hi:
                tc = t0 + np.int64(np.ceil((hi - a) / slope))
            elif slope < 0 and L1[i] <= lo:
                tc = t0 + np.int64(np.ceil((lo - a) / slope))
                p = 0
            tc = min(max(tc, t_from), t1 + 1)
            while j < n_pix.shape[0] and n_pix[j] == i and n_t[j] <= t_from:
                j += 1  # the pixel was busy: the request is lost
            if j < n_pix.shape[0] and n_pix[j] == i and n_t[j] < tc:
                tc = n_t[j]
                p = n_pol[j]
                j += 1
            if tc > t1:
                break
            # Held until its column is read: the next scan at or after tc (at once when asynchronous).
            t_read = tc
            if period_ns > 0:
                scans = max(np.ceil((float(tc - origin) - col_off[i % width]) / period_ns), 0.0)
                t_read = max(origin + np.int64(np.ceil(col_off[i % width] + scans * period_ns)), tc)
            state_latch[i] = p
            state_read[i] = t_read
            t_cur = tc
        while j < n_pix.shape[0] and n_pix[j] == i:
            j += 1
    return idx[:k], ts[:k], pol[:k]


class EventSensor:
    """Stateful event generator for one camera: feed it renders (irradiance images) in time order."""

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
        self._arm = np.full(n, -(1 << 62), np.int64)
        self._latch = np.full(n, -1, np.int8)
        self._read = np.zeros(n, np.int64)
        self._col_off = model.column_offsets_ns(self.width)
        self._L: np.ndarray | None = None
        self._t_ns: int | None = None
        self._origin_ns = 0

    def log_intensity(self, irradiance: np.ndarray) -> np.ndarray:
        """Natural log of irradiance plus the dark offset ``log_eps`` (float64, flattened)."""
        out = np.empty(np.size(irradiance))
        _log(np.ascontiguousarray(irradiance, np.float32).ravel(), np.float64(self.model.log_eps), out)
        return out

    def reset(self, irradiance: np.ndarray, t_ns: int) -> None:
        """Start from a render: the references equal the current log intensity (no events); the first
        readout scan starts at ``t_ns``."""
        self._L = self.log_intensity(irradiance)
        self.ref = self._L.copy()
        self._t_ns = self._origin_ns = int(t_ns)
        self._arm[:] = -(1 << 62)
        self._latch[:] = -1

    def step(self, irradiance: np.ndarray, t_ns: int) -> EventBatch:
        """Events read out between the previous render and this one (sorted by time, ties by pixel)."""
        if self._L is None or self._t_ns is None or self.ref is None:
            raise SimulationError("EventSensor.step called before reset")
        t0, t1 = self._t_ns, int(t_ns)
        if t1 <= t0:
            raise SimulationError(f"renders must move forward in time ({t0} -> {t1} ns)")
        m = self.model
        L1 = np.empty_like(self._L)
        n_pix, n_t, n_pol = self._noise(t0, t1)
        idx, ts, pol = _pixel_events(self._L, np.ascontiguousarray(irradiance, np.float32).ravel(),
                                     np.float64(m.log_eps), L1, np.int64(t0), np.int64(t1), np.int64(self._origin_ns),
                                     self.ref, self._arm, self._latch, self._read, self.c_pos, self.c_neg,
                                     np.int64(round(m.refractory_s * 1e9)), np.int64(m.timestamp_resolution_ns),
                                     np.float64(m.scan_period_s * 1e9), self._col_off, np.int64(self.width),
                                     n_pix, n_t, n_pol)
        self._L, self._t_ns = L1, t1
        order = np.argsort(ts, kind="stable")
        idx = idx[order]
        return EventBatch((idx % self.width).astype(np.uint16), (idx // self.width).astype(np.uint16),
                          ts[order], pol[order], self.width, self.height)

    def _noise(self, t0: int, t1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Background-activity requests in (t0, t1]: pixel, time, polarity, sorted by pixel then time."""
        lam = self.model.noise_rate_hz * self.width * self.height * (t1 - t0) * 1e-9
        count = int(self.rng.poisson(lam)) if lam > 0 else 0
        pix = self.rng.integers(0, self.width * self.height, count)
        t = t1 - (self.rng.random(count) * (t1 - t0)).astype(np.int64)
        pol = self.rng.integers(0, 2, count).astype(np.int8)
        order = np.lexsort((t, pix))
        return pix[order], t[order], pol[order]
