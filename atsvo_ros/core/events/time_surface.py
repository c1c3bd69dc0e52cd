"""Time surfaces: the adaptive time surface (ATS, Eq. 1-2) and two baselines behind one interface.

All keep per-pixel state updated in O(events) (:meth:`TimeSurface.update`) and render a float32 image in
0..255 in O(pixels) (:meth:`TimeSurface.render`), followed by the paper's box blur and median blur (kernel
sizes from :class:`~atsvo_ros.config.AtsConfig`, applied to every variant so that comparisons differ only
in the decay).

* :class:`AdaptiveTimeSurface` -- Eq. 1, ``T(x, t) = 255 exp(-(t - t_last(x)) / tau(x))`` with a per-pixel
  ``tau`` from the timestamps of a 16-pixel ring (radius ``pattern_radius_px``; 3 = the FAST circle, our
  reading of Fig. 3) around ``x``; how Eq. 2 turns them into ``tau`` is ``tau_mode`` (below).
* :class:`ConstantTimeSurface` -- Eq. 1 with ``tau = constant_tau_s`` everywhere.
* :class:`SpeedInvariantTimeSurface` -- Manderscheid et al. 2019 (patch radius ``sits_radius_px``).

**Eq. 2.** With ``a`` the mean age ``(1/n) sum_i (t - t_last,i)`` of the n latest active ring neighbours,
the printed formula is ``tau = max(tau_u - a, tau_l)`` (``tau_mode = "eq2_printed"``). Because ``tau``
divides the age in Eq. 1, that gives the *slowest* decay where neighbours fired most recently -- dense
texture, fast motion -- the opposite of the text ("decays faster in high-texture environments or during
high-speed motion ... slower in low-texture environments or during low-speed motion"); it reads as if tau
were a rate. Two readings keep the described behaviour:

* ``mean_age`` (the default until the fusion work): ``tau = clip(a, tau_l, tau_u)`` with ``a`` taken at
  the query time. Behind an edge moving at ``v`` px/s, a pixel ``d`` px back has the age ``d / v``, but its
  n latest neighbours are the ring pixels nearest the edge: for ``d`` up to the ring radius they are at the
  edge (age ~0), tau collapses to ``tau_l`` and the pixel goes dark (a notch 2-4 px behind the edge);
  further back their mean age is about the pixel's own, so ``exp(-age / tau)`` sits near ``255 / e = 94``
  (a flat ghost band) until tau reaches ``tau_u``. The gradient changes sign within the ATS term's basin;
  on real data the surface draws every edge as a thin ring with a dark centre.
* ``fire_age`` (the default): Eq. 2's statistic -- the mean age of the ring neighbours -- evaluated at the
  moment the pixel fired instead of at the query time:
  ``tau = clip(fire_age_gain * mean_q min(t_last(x) - t_last(q), tau_u), tau_l, tau_u)`` over the active
  ring neighbours ``q`` that fired at or before ``x`` and have not fired since (``tau_u`` if there is none).
  Every pixel of an edge's trail fired in the same situation -- the neighbours behind it had fired
  ``|dx| / v`` before, ~1.7 px of motion on average on the FAST ring -- so tau is the same along the trail
  and the decay is monotonic and smooth behind the edge (tested on simulated DVS events, an isolated edge
  and a dense texture, 150-3000 px/s). It keeps the paper's intent: the statistic is proportional to
  1 / speed (faster decay under fast motion) and shrinks where neighbours fired shortly before the pixel
  (dense texture, event floods); slow or sparse neighbourhoods give ``tau_u``. The trail fades to 1/e over
  ~1.7 x ``fire_age_gain`` pixels (4: ~7 px) while tau stays within its bounds (above 2700 px/s ``tau_l``
  lengthens it, below ~230 px/s ``tau_u`` shortens it). Neighbours that fired *after* the pixel belong to
  later edges; counting them would let a newer edge lengthen the decay of the older pixels in front of it
  (a glow ahead of every edge in a textured scene), so they are left out; gaps are clipped at ``tau_u`` so
  one stale neighbour cannot dominate.

Measured (``atsvo-bench ats-basin``, table in the README): the basin of the ATS term alone is set mostly by the
pattern, the blur and the pyramid, not by the decay: 3-6 px on one level for every rule, 16-22 px and ~4 deg
(simulated backflip/bound) with 4 pyramid levels (the event camera's, at 320x240). On one level ``fire_age``
removes the notch's cost
at low and medium speed (sparse scene, 300/1000 px/s: 5/6 px vs 3/4 px for ``mean_age``), but at 3000
px/s, where ``tau_l`` bounds both, ``mean_age``'s long ghost band reaches further against the motion (8 vs
2 px; the pyramid evens it out: 22 vs 16 px). On the simulated dense sequences ``mean_age`` converges from
the truth slightly more often and more precisely (bound, 4 levels: 79 % / 0.28 px vs 71 % / 0.45 px):
its rings keep contrast in event floods, where every other decay whites out towards ``tau_l``. The
constant and printed surfaces, with the longest trails, have the largest basins where they do not white out.

Cost. ``fire_age`` needs the last timestamps only: the update is a scatter into the padded surface (~700 M
events/s on one core, dv-processing's ``TimeSurface.accept`` ~400 M/s). Its render reads the 16 neighbours
of every pixel within the decay cutoff: ages once as float32 (NaN where never fired, so no comparison counts
them), then, per row, runs of 16-pixel blocks with an active pixel through a loop written out over the 16
ring offsets so that it vectorises across pixels (one float32 lane per pixel), Eq. 1 in float32 with its own
exp (no libm call). Against the int64 reference (``tau_map`` and the generic-ring path) the values agree to a
relative ~1e-5. On one core, 320x240 DVXplorer recording: ~0.14 ms raw, ~0.22 ms with the blurs (~0.08 ms of
OpenCV box + median blur); 346x260 DAVIS346: ~0.24 / ~0.33 ms (dv-processing's ``generateFrame``, a linear
map without neighbours: ~0.18 / ~0.21 ms). The ring pass is bound by the vector units (~6 operations per
neighbour per pixel), and noise events leave few blocks without an active pixel.

``mean_age`` / ``eq2_printed`` (kept as ablations) keep, per pixel, *which* ring neighbours are its n latest
active ones: events come in time order, so the neighbour that fires is always the newest value of every
ring it belongs to; n ring indices packed as 4-bit nibbles in one int64 move the firing one to the front
with a few branch-free bit operations (one load and one store per ring neighbour, ~25 M events/s for any n);
the render reads the members' times from ``t_last``. State lives on the surface padded by the ring radius,
so ring neighbours need no bounds checks. Rows split over two threads (numba prange) would take half the
time on an idle machine, but when the other core is busy the render waits for a descheduled thread (p90
~8 ms), so everything stays single-threaded.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from atsvo_ros.config import AtsConfig
from atsvo_ros.core.events import _ts_kernels as kern
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import ConfigError

NEVER = kern.NEVER
_TAU_MODES = {"mean_age": 0, "eq2_printed": 1, "fire_age": 2}


def ring_pattern(radius_px: int = 3, n_points: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Offsets (dx, dy) of the neighbour ring: ``n_points`` angles rounded to pixels, duplicates removed.

    Radius 3 gives exactly the 16-pixel Bresenham circle of the FAST detector.
    """
    seen: list[tuple[int, int]] = []
    for k in range(n_points):
        a = 2.0 * math.pi * k / n_points
        off = (int(round(radius_px * math.cos(a))), int(round(radius_px * math.sin(a))))
        if off not in seen and off != (0, 0):
            seen.append(off)
    dx = np.array([o[0] for o in seen], np.int64)
    dy = np.array([o[1] for o in seen], np.int64)
    return dx, dy


def _postfilter(img: np.ndarray, blur_ksize: int, median_ksize: int) -> np.ndarray:
    """Box blur then median blur (OpenCV); float32 median for k <= 5, uint8 beyond (OpenCV's limit)."""
    if blur_ksize > 1:
        img = cv2.blur(img, (blur_ksize, blur_ksize))
    if median_ksize > 1:
        if median_ksize <= 5:
            img = cv2.medianBlur(img, median_ksize)
        else:
            img = cv2.medianBlur(np.clip(img + 0.5, 0, 255).astype(np.uint8), median_ksize).astype(np.float32)
    return img


class TimeSurface:
    """Common interface: ``update(batch)`` in O(events), ``render(t_ns)`` in O(pixels).

    Events must arrive in time order (as :class:`~atsvo_ros.io.decode.EventDecoder` guarantees);
    events outside the ``width x height`` surface are skipped and counted in ``n_skipped``.
    """

    def __init__(self, width: int, height: int, cfg: AtsConfig | None = None) -> None:
        if width <= 0 or height <= 0:
            raise ConfigError(f"time surface size must be positive, got {width}x{height}")
        self.width, self.height = int(width), int(height)
        self.cfg = cfg or AtsConfig()
        self.n_skipped = 0
        self.n_events = 0
        self.t_latest_ns: int | None = None
        self.reset()

    def reset(self) -> None:
        """Forget all events."""
        self.t_last = np.full((self.height, self.width), NEVER, np.int64)
        self.t_latest_ns = None

    def update(self, batch: EventBatch) -> None:
        """Add a time-ordered batch of events."""
        if len(batch) == 0:
            return
        self.n_skipped += self._ingest(batch)
        self.n_events += len(batch)
        t_end = int(batch.t[-1])
        self.t_latest_ns = t_end if self.t_latest_ns is None else max(self.t_latest_ns, t_end)

    def _ingest(self, batch: EventBatch) -> int:
        """Fold events into the state; returns how many were skipped (outside, or older than their pixel)."""
        return int(kern._set_last(self.t_last, batch.x, batch.y, batch.t))

    def _t(self, t_ns: int | None) -> int:
        if t_ns is not None:
            return int(t_ns)
        return self.t_latest_ns if self.t_latest_ns is not None else 0

    def render_raw(self, t_ns: int | None = None) -> np.ndarray:
        """The surface at ``t_ns`` (default: the latest event) before blur and median blur."""
        raise NotImplementedError

    def render(self, t_ns: int | None = None) -> np.ndarray:
        """float32 image in 0..255 at ``t_ns`` (default: the latest event), blurred and median blurred."""
        return _postfilter(self.render_raw(t_ns), self.cfg.blur_ksize, self.cfg.median_ksize)

    def window_ns(self) -> int:
        """The time span the surface represents (upper bound of its decay constant), in ns."""
        return int(round(self.cfg.tau_u_s * 1e9))

    def active_mask(self) -> np.ndarray:
        """Pixels that received at least one event."""
        return self.t_last != NEVER


class AdaptiveTimeSurface(TimeSurface):
    """The paper's ATS (Eq. 1-2); see the module docstring for the reading of Eq. 2."""

    def __init__(self, width: int, height: int, cfg: AtsConfig | None = None) -> None:
        c = cfg or AtsConfig()
        self.ring_dx, self.ring_dy = ring_pattern(c.pattern_radius_px)
        # state lives on the surface padded by the ring radius, so ring neighbours need no bounds checks
        self._pad = int(max(np.abs(self.ring_dx).max(), np.abs(self.ring_dy).max()))
        self._wp = int(width) + 2 * self._pad
        self._ring_off = (self.ring_dy * self._wp + self.ring_dx).astype(np.int64)
        if c.tau_mode not in _TAU_MODES:
            raise ConfigError(f"ats.tau_mode = {c.tau_mode!r}; allowed: {sorted(_TAU_MODES)}")
        self._mode = _TAU_MODES[c.tau_mode]
        self._gain = float(c.fire_age_gain) if self._mode == 2 else 1.0  # mean_age: tau = the mean age itself
        super().__init__(width, height, c)
        # beyond this age even tau_u leaves less than half a grey level
        self._cutoff_s = c.tau_u_s * math.log(2 * 255.0)
        self._out = np.empty((self.height, self.width), np.float32)
        self._tau = np.empty((1, 1), np.float32)
        # fire_age with the 16-point ring renders through float32 ages (kern._fire_age_render)
        self._fast = self._mode == 2 and len(self.ring_dx) == 16
        self._age = np.empty(self._t_flat.shape, np.float32) if self._fast else np.empty(0, np.float32)

    def reset(self) -> None:
        super().reset()
        pad, hp = self._pad, self.height + 2 * self._pad
        self._n = int(min(self.cfg.n_latest, len(self.ring_dx)))
        t_pad = np.full((hp, self._wp), NEVER, np.int64)
        self.t_last = t_pad[pad:pad + self.height, pad:pad + self.width]  # a view: same values, public shape
        self._t_flat = t_pad.reshape(-1)
        if self.cfg.tau_mode == "fire_age":  # the render reads the times only
            self._rec = np.zeros(1, np.int64)
        else:  # per pixel: n ring indices, most recent first (4 bits each); see kern._ats_update
            self._rec = np.full(hp * self._wp, kern._ring_list_init(self._n), np.int64)

    def _ingest(self, batch: EventBatch) -> int:
        if self._mode == 2:
            return int(kern._set_last_padded(self._t_flat, batch.x, batch.y, batch.t, self.width, self.height,
                                             self._wp, self._pad))
        return int(kern._ats_update(self._t_flat, self._rec, batch.x, batch.y, batch.t, self._ring_off,
                                    self._n, self.width, self.height, self._wp, self._pad))

    def _run(self, t_ns: int | None, want_tau: bool) -> None:
        c = self.cfg
        if self._fast and not want_tau:
            kern._fire_age_render(self._t_flat, self._ring_off, self.width, self.height, self._wp, self._pad,
                                  self._t(t_ns), c.tau_l_s, c.tau_u_s, self._gain, self._cutoff_s,
                                  self._age, self._out)
            return
        if want_tau and self._tau.shape != self._out.shape:
            self._tau = np.empty_like(self._out)
        kern._ats_render(self._t_flat, self._rec, self._ring_off, self._n, self.width, self.height, self._wp,
                         self._pad, self._t(t_ns), c.tau_l_s, c.tau_u_s, self._mode, self._gain, self._cutoff_s,
                         self._out, self._tau, want_tau)

    def render_raw(self, t_ns: int | None = None) -> np.ndarray:
        self._run(t_ns, False)
        return self._out.copy()

    def render(self, t_ns: int | None = None) -> np.ndarray:
        c = self.cfg
        if c.blur_ksize == 1 and c.median_ksize == 1:
            return self.render_raw(t_ns)
        self._run(t_ns, False)
        return _postfilter(self._out, c.blur_ksize, c.median_ksize)  # OpenCV writes a new image: no copy needed

    def tau_map(self, t_ns: int | None = None) -> np.ndarray:
        """Per-pixel decay time constant in seconds at ``t_ns`` (NaN where no event arrived yet)."""
        self._run(t_ns, True)
        return self._tau.copy()


class ConstantTimeSurface(TimeSurface):
    """Baseline: Eq. 1 with a constant ``tau`` (``constant_tau_s``)."""

    def render_raw(self, t_ns: int | None = None) -> np.ndarray:
        out = np.empty((self.height, self.width), np.float32)
        kern._constant_render(self.t_last, self._t(t_ns), float(self.cfg.constant_tau_s), out)
        return out

    def tau_map(self, t_ns: int | None = None) -> np.ndarray:
        """``constant_tau_s`` on active pixels, NaN elsewhere."""
        return np.where(self.active_mask(), np.float32(self.cfg.constant_tau_s), np.float32(np.nan))

    def window_ns(self) -> int:
        return int(round(self.cfg.constant_tau_s * 1e9))


class SpeedInvariantTimeSurface(TimeSurface):
    """Baseline: speed-invariant time surface (Manderscheid et al., CVPR 2019), scaled to 0..255.

    Each event sets its pixel to the maximum ``(2r+1)^2`` and lowers by one every neighbour in the
    patch that was at least as bright, so an edge leaves a trail of fixed width whatever its speed.
    The value does not depend on the query time.
    """

    def reset(self) -> None:
        super().reset()
        r = int(self.cfg.sits_radius_px)
        # padded by r on every side (see kern._sits_update); surface is a view of the inside
        self._padded = np.zeros((self.height + 2 * r, self.width + 2 * r), np.int16)
        self.surface = self._padded[r:r + self.height, r:r + self.width]

    def _ingest(self, batch: EventBatch) -> int:
        kern._sits_update(self._padded.reshape(-1), batch.x, batch.y, int(self.cfg.sits_radius_px), self.width,
                          self.height, self._padded.shape[1])
        return super()._ingest(batch)

    def render_raw(self, t_ns: int | None = None) -> np.ndarray:
        full = (2 * self.cfg.sits_radius_px + 1) ** 2
        return self.surface.astype(np.float32) * np.float32(255.0 / full)


SURFACES = {"ats": AdaptiveTimeSurface, "constant": ConstantTimeSurface, "sits": SpeedInvariantTimeSurface}


def make_time_surface(kind: str, width: int, height: int, cfg: AtsConfig | None = None) -> TimeSurface:
    """Build a surface by name: ``ats``, ``constant`` or ``sits``."""
    if kind not in SURFACES:
        raise ConfigError(f"unknown time surface {kind!r}; choose one of {sorted(SURFACES)}")
    return SURFACES[kind](width, height, cfg)


__all__ = ["AdaptiveTimeSurface", "ConstantTimeSurface", "SpeedInvariantTimeSurface", "TimeSurface",
           "make_time_surface", "ring_pattern"]
