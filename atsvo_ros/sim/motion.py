"""Body trajectories of a quadruped (and a flying camera), evaluated at any int64 ns time.

A legged motion is a planar path (the robot walks an ellipse around the free floor area, heading
along the path plus a look-around yaw wobble) plus gait components on height, roll and pitch,
blended with smooth weights so that gaits can change over time. Every component has a continuous
first derivative, so the pose curve has continuous linear and angular velocity; impacts are
modelled as fast but smooth velocity reversals plus a damped vibration whose onset is quadratic.

Orientation is ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` of the base (x forward, y left, z up); a
negative pitch raises the nose, so the backflip is a pitch of -360 deg.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.scene import scene_free_xy

SCENARIOS = ("trot", "bound", "pronk", "backflip", "running", "flying")
GRAVITY = 9.81
STAND_HEIGHT_M = 0.30

#: Gait name -> (forward speed m/s, stride frequency Hz).
GAITS: dict[str, tuple[float, float]] = {
    "stand": (0.0, 1.0),
    "trot": (0.5, 2.2),
    "bound": (0.9, 2.6),
    "pronk": (0.35, 2.5),
}
BOUND_PEAK_RATE_DPS = 260.0
BACKFLIP_PEAK_RATE_DPS = 560.0

_FLIP_CROUCH_S, _FLIP_PUSH_S = 0.4, 0.2  # the backflip's crouch and push-off

#: Motion phases of :meth:`Motion.phase`: on the feet, airborne, and the first frames after a touchdown.
PHASES = ("stance", "flight", "landing")
#: How long after a touchdown counts as landing: the few frames its jitter shakes (three at 30 Hz).
LANDING_WINDOW_S = 0.1


@dataclass(frozen=True)
class Touchdown:
    """The trunk's shake after a foot strike: a damped oscillation of the camera mount, per gait.

    Not measured on the robot (no Mini-Cheetah IMU log is at hand): chosen so that the IMU sees what
    quadruped trunk IMUs are reported to see at foot strikes, 1-2 g vertical spikes and gyro swings of
    50-150 deg/s ringing at the 15-25 Hz of a stiff camera mount, over ~0.05 s. Fit to the robot's IMU
    log when there is one: these are the numbers to change.

    Attributes:
        height_m / pitch_deg / roll_deg: amplitudes of the oscillation.
        freq_hz / decay_s: its frequency and decay time.
    """

    height_m: float
    pitch_deg: float
    roll_deg: float
    freq_hz: float
    decay_s: float


#: Touchdown shakes per gait: a trot strikes with one diagonal pair at a time (roll and pitch), a bound
#: with the front then the rear pair (pitch), a pronk with all four feet (height and pitch).
TOUCHDOWNS: dict[str, Touchdown] = {
    "trot": Touchdown(0.0010, 0.4, 0.4, 19.0, 0.04),
    "bound": Touchdown(0.0015, 0.8, 0.1, 16.0, 0.05),
    "pronk": Touchdown(0.0040, 1.2, 0.2, 20.0, 0.055),
}


def smoothstep5(x: np.ndarray) -> np.ndarray:
    """Quintic 0 -> 1 ramp on [0, 1] with zero first and second derivatives at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))


def _smoothstep5_integral(x: np.ndarray) -> np.ndarray:
    """Integral of :func:`smoothstep5` from 0 to x (x clipped to [0, 1], linear past 1)."""
    xc = np.clip(x, 0.0, 1.0)
    inner = xc ** 4 * (2.5 + xc * (-3.0 + xc))
    return inner + np.maximum(x - 1.0, 0.0)


def _vibration(tau: np.ndarray, amp: float, freq_hz: float, decay_s: float, onset_s: float = 0.01) -> np.ndarray:
    """Damped oscillation after an impact at tau = 0; zero with zero slope for tau <= 0."""
    tau = np.maximum(tau, 0.0)
    q = (tau / onset_s) ** 2
    return amp * q / (1.0 + q) * np.exp(-tau / decay_s) * np.sin(2.0 * np.pi * freq_hz * tau)


def _landing(tau: np.ndarray, v_in: float, rate: float) -> np.ndarray:
    """Critically damped height offset after touching down with downward speed ``v_in`` at tau = 0.

    Starts at 0 with velocity ``-v_in`` and returns to 0: ``-v_in * tau * exp(-rate * tau)``.
    """
    tau = np.maximum(tau, 0.0)
    return -v_in * tau * np.exp(-rate * tau)


@dataclass(frozen=True)
class GaitSchedule:
    """Gait weights over time: segments ``(t_start_s, gait)`` cross-faded over ``blend_s``."""

    segments: tuple[tuple[float, str], ...]
    blend_s: float = 0.5

    def weights(self, t: np.ndarray) -> dict[str, np.ndarray]:
        out = {g: np.zeros_like(t) for g in GAITS}
        starts = [s for s, _ in self.segments]
        for i, (t0, gait) in enumerate(self.segments):
            up = np.ones_like(t) if i == 0 else smoothstep5((t - t0) / self.blend_s)
            down = (np.ones_like(t) if i + 1 == len(starts)
                    else 1.0 - smoothstep5((t - starts[i + 1]) / self.blend_s))
            out[gait] = out[gait] + up * down
        return out

    def speed_integral(self, t: np.ndarray) -> np.ndarray:
        """Closed-form integral from 0 to t of the blended forward speed (distance walked)."""
        total = np.zeros_like(t)
        starts = [s for s, _ in self.segments]
        for i, (t0, gait) in enumerate(self.segments):
            v = GAITS[gait][0]
            if v == 0.0:
                continue
            # weight = up(t) - (1 - down(t)) for non-overlapping blends; integrate each ramp.
            up = t - 0.0 if i == 0 else self.blend_s * _smoothstep5_integral((t - t0) / self.blend_s)
            if i + 1 < len(starts):
                up = up - self.blend_s * _smoothstep5_integral((t - starts[i + 1]) / self.blend_s)
            total = total + v * up
        return total


@dataclass(frozen=True)
class Motion:
    """A seeded body trajectory: ``T_world_base(t_ns)`` for ``0 <= t <= duration``.

    ``t0_ns`` is the stamp of the first sample (sequence time starts there).
    """

    scenario: str
    duration_s: float
    seed: int
    free_xy: tuple[float, float, float, float]
    t0_ns: int = 0
    params: dict = field(default_factory=dict, compare=False)

    # ------------------------------------------------------------------ public
    def T_world_base(self, t_ns) -> np.ndarray:
        """Pose(s) of base_link in the world at int64 ns stamp(s): (4, 4) or (N, 4, 4)."""
        t_arr = np.asarray(t_ns, dtype=np.int64)
        t = (np.atleast_1d(t_arr) - self.t0_ns).astype(np.float64) * 1e-9
        pos, ypr = self._evaluate(t)
        T = np.zeros((len(t), 4, 4))
        T[:, :3, :3] = euler_zyx(ypr[:, 0], ypr[:, 1], ypr[:, 2])
        T[:, :3, 3] = pos
        T[:, 3, 3] = 1.0
        return T[0] if t_arr.ndim == 0 else T

    def stamps_ns(self, rate_hz: float) -> np.ndarray:
        """Stamps from t0 to t0 + duration at ``rate_hz`` (int64 ns)."""
        n = int(np.floor(self.duration_s * rate_hz + 1e-9)) + 1
        return self.t0_ns + np.round(np.arange(n) * (1e9 / rate_hz)).astype(np.int64)

    @property
    def t_end_ns(self) -> int:
        return self.t0_ns + int(round(self.duration_s * 1e9))

    def phase(self, t_ns) -> np.ndarray:
        """The motion phase (index into :data:`PHASES`) at int64 ns stamp(s): stance, flight or landing.

        Landing is the :data:`LANDING_WINDOW_S` after a touchdown of the gait that dominates at the time
        (every foot strike of a trot or bound, a pronk's or the backflip's touchdown); flight is a pronk's
        or the flip's airborne time (the flying camera is always in flight); stance is the rest.
        """
        t = (np.atleast_1d(np.asarray(t_ns, dtype=np.int64)) - self.t0_ns).astype(np.float64) * 1e-9
        out = np.zeros(len(t), np.int64)
        if self.scenario == "flying":
            out[:] = PHASES.index("flight")
            return out
        w = self.params["schedule"].weights(t)
        dominant = np.array(list(w))[np.argmax(np.stack(list(w.values())), axis=0)]
        landing, flight = PHASES.index("landing"), PHASES.index("flight")
        for gait in ("trot", "bound"):
            out[(dominant == gait) & (self._since_touchdown(t, gait) < LANDING_WINDOW_S)] = landing
        pronk = dominant == "pronk"
        out[pronk & (self._pronk_since_touchdown(t) < LANDING_WINDOW_S)] = landing
        out[pronk & (np.mod(t, self.params["pronk_air_s"] + self.params["pronk_stance_s"])
                     < self.params["pronk_air_s"])] = flight
        if self.scenario == "backflip":
            t_to, t_land = self._flip_times()
            out[(t >= t_to) & (t < t_land)] = flight
            out[(t >= t_land) & (t < t_land + 3 * LANDING_WINDOW_S)] = landing  # the flip's landing rings longer
        return out

    # ------------------------------------------------------------------ internals
    def _path(self, dist: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ellipse around the free area; arc parameter from the distance walked (approximate arc length)."""
        p = self.params
        x0, x1, y0, y1 = self.free_xy
        ax, ay = p["ax"], p["ay"]
        r_mean = 0.5 * (ax + ay)
        phi = p["phi0"] + p["direction"] * dist / r_mean
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        x = cx + ax * np.cos(phi)
        y = cy + ay * np.sin(phi)
        tx, ty = -ax * np.sin(phi) * p["direction"], ay * np.cos(phi) * p["direction"]
        base = phi + p["direction"] * 0.5 * np.pi
        delta = np.angle(np.exp(1j * (np.arctan2(ty, tx) - base)))
        yaw = base + delta + p["look_amp"] * np.sin(2 * np.pi * p["look_hz"] * t + p["look_phase"])
        return np.column_stack([x, y]), yaw

    def _evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.scenario == "flying":
            return self._flying(t)
        p = self.params
        sched: GaitSchedule = p["schedule"]
        w = sched.weights(t)
        dist = sched.speed_integral(t)
        xy, yaw = self._path(dist, t)
        z = np.full_like(t, STAND_HEIGHT_M)
        pitch = np.zeros_like(t)
        roll = np.zeros_like(t)
        # Stand: slow sway (breathing, balance).
        z += w["stand"] * 0.004 * np.sin(2 * np.pi * 0.4 * t)
        roll += w["stand"] * np.radians(0.6) * np.sin(2 * np.pi * 0.3 * t + 1.0)
        # Trot: diagonal pairs -> bounce at twice the stride frequency, roll at the stride frequency.
        f = GAITS["trot"][1]
        z += w["trot"] * 0.010 * np.cos(4 * np.pi * f * t)
        roll += w["trot"] * np.radians(2.0) * np.sin(2 * np.pi * f * t)
        pitch += w["trot"] * np.radians(1.2) * np.sin(4 * np.pi * f * t + 0.7)
        # Touchdowns: a diagonal pair strikes twice per stride, as the bounce starts down.
        self._shake(t, w["trot"], self._since_touchdown(t, "trot"), 0.5 / f, TOUCHDOWNS["trot"], z, pitch, roll,
                    alternate_roll=True)
        # Bound: front/rear pairs -> large pitch oscillation; height bounce at the stride frequency.
        f = GAITS["bound"][1]
        amp = np.radians(BOUND_PEAK_RATE_DPS) / (2 * np.pi * f) / 1.0 * p["bound_gain"]
        pitch += w["bound"] * amp * (np.sin(2 * np.pi * f * t) + 0.15 * np.sin(4 * np.pi * f * t + 0.4)) / 1.3
        z += w["bound"] * (0.035 * np.cos(2 * np.pi * f * t + 0.6) + 0.01)
        # Touchdowns: the front pair, then the rear pair half a stride later.
        self._shake(t, w["bound"], self._since_touchdown(t, "bound"), 0.5 / f, TOUCHDOWNS["bound"], z, pitch, roll)
        # Pronk: ballistic hops, spring-like stance, vibration after each touchdown.
        z += w["pronk"] * self._pronk_height(t)
        tau_td = self._pronk_since_touchdown(t)
        period = self.params["pronk_air_s"] + self.params["pronk_stance_s"]
        self._shake(t, w["pronk"], tau_td, period, TOUCHDOWNS["pronk"], z, pitch, roll)
        pitch += w["pronk"] * np.radians(2.0) * np.sin(2 * np.pi * GAITS["pronk"][1] * t + 0.3)
        if self.scenario == "backflip":
            dz, dpitch, dx = self._backflip(t)
            z += dz
            pitch += dpitch
            xy = xy + dx[:, None] * np.column_stack([np.cos(yaw), np.sin(yaw)])
        pos = np.column_stack([xy, z])
        return pos, np.column_stack([yaw, pitch, roll])

    def _since_touchdown(self, t: np.ndarray, gait: str) -> np.ndarray:
        """Seconds since the last touchdown of a trot or bound (two strikes per stride, as the bounce goes down)."""
        f = GAITS[gait][1]
        half = 0.5 / f
        if gait == "trot":  # z = cos(4 pi f t): falling fastest at 4 pi f t = pi / 2 (mod 2 pi)
            t0 = 0.125 / f
        else:  # z = cos(2 pi f t + 0.6): falling fastest at 2 pi f t + 0.6 = pi / 2
            t0 = (0.5 * np.pi - 0.6) / (2 * np.pi * f)
        return np.mod(t - t0, half)

    @staticmethod
    def _shake(t: np.ndarray, weight: np.ndarray, since: np.ndarray, period: float, td: Touchdown, z: np.ndarray,
               pitch: np.ndarray, roll: np.ndarray, alternate_roll: bool = False) -> None:
        """Add the damped shakes of the latest touchdowns (``since``: time since the last one, every ``period``)."""
        # A shake fades out smoothly between 4 and 8 decay times (from 2 % of its amplitude): a strike leaves the sum
        # at exactly zero, so the pose stays smooth when the oldest one is dropped.
        n_live = int(np.ceil(8.0 * td.decay_s / period)) + 1
        for k in range(n_live):
            tau = since + k * period
            fade = weight * (1.0 - smoothstep5((tau - 4.0 * td.decay_s) / (4.0 * td.decay_s)))
            sign = 1.0
            if alternate_roll:  # the two diagonal pairs roll the trunk opposite ways
                sign = np.where(np.mod(np.floor((t - tau) / period + 0.5), 2) == 0, 1.0, -1.0)
            z += fade * _vibration(tau, td.height_m, td.freq_hz, td.decay_s)
            pitch += fade * _vibration(tau, np.radians(td.pitch_deg), td.freq_hz, td.decay_s)
            roll += fade * sign * _vibration(tau, np.radians(td.roll_deg), 0.85 * td.freq_hz, td.decay_s)

    def _pronk_height(self, t: np.ndarray) -> np.ndarray:
        t_air, t_st = self.params["pronk_air_s"], self.params["pronk_stance_s"]
        period = t_air + t_st
        v0 = GRAVITY * t_air / 2.0
        tau = np.mod(t, period)
        air = tau < t_air
        ta = np.where(air, tau, 0.0)
        ts = np.where(air, 0.0, tau - t_air)
        # Flight: up and down from the takeoff height; stance: sin dip with matching end velocities.
        flight = v0 * ta - 0.5 * GRAVITY * ta * ta
        stance = -(v0 * t_st / np.pi) * np.sin(np.pi * ts / t_st)
        return np.where(air, flight, stance) + 0.02

    def _pronk_since_touchdown(self, t: np.ndarray) -> np.ndarray:
        t_air, t_st = self.params["pronk_air_s"], self.params["pronk_stance_s"]
        period = t_air + t_st
        return np.mod(t - t_air, period)

    def _flip_times(self) -> tuple[float, float]:
        """Take-off and touchdown of the backflip, in seconds of sequence time."""
        t_to = self.params["flip_t_s"] + _FLIP_CROUCH_S + _FLIP_PUSH_S
        return t_to, t_to + self.params["flip_air_s"]

    def _backflip(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Crouch, push-off, aerial full pitch rotation, landing with impact; offsets to the stand pose."""
        p = self.params
        t_c = p["flip_t_s"]  # crouch start
        crouch_s, push_s, air_s = _FLIP_CROUCH_S, _FLIP_PUSH_S, p["flip_air_s"]
        crouch_m = 0.08
        t_p = t_c + crouch_s
        t_to, t_land = self._flip_times()
        v0 = GRAVITY * air_s / 2.0
        # Height offset: crouch, Hermite push from (-crouch, 0) to (h_to, v0), flight, damped landing.
        h_to = -crouch_m + 0.5 * v0 * push_s
        z = -crouch_m * smoothstep5((t - t_c) / crouch_s)
        s = np.clip((t - t_p) / push_s, 0.0, 1.0)
        h00, h01, h11 = 2 * s**3 - 3 * s**2 + 1, -2 * s**3 + 3 * s**2, s**3 - s**2
        push = h00 * (-crouch_m) + h01 * h_to + h11 * push_s * v0
        z = np.where((t >= t_p) & (t < t_to), push, z)
        ta = t - t_to
        flight = h_to + v0 * ta - 0.5 * GRAVITY * ta * ta
        z = np.where((t >= t_to) & (t < t_land), flight, z)
        tl = t - t_land
        # After touchdown at h_to with speed v0: critically damped return to the stand height.
        lam = 10.0
        a = h_to
        landing = a * (1.0 + lam * tl) * np.exp(-lam * tl) + _landing(tl, v0, lam)
        z = np.where(t >= t_land, landing + _vibration(tl, 0.006, 21.0, 0.08), z)
        # Pitch: plateau-rate profile with quintic ramps; total -2 pi.
        omega = np.radians(p["flip_peak_dps"])
        ramp = p["flip_ramp_s"]
        span = 2 * np.pi / omega + ramp  # rotation time so that the integral is 2 pi
        t_r0 = t_p + 0.5 * (push_s + air_s) - 0.5 * span
        angle = omega * ramp * (_smoothstep5_integral((t - t_r0) / ramp)
                                - _smoothstep5_integral((t - t_r0 - span + ramp) / ramp))
        pitch = -angle + _vibration(tl, np.radians(3.0), 15.0, 0.08)
        # Slight backward drift of the body during the flip.
        dx = -p["flip_drift_m"] * smoothstep5((t - t_p) / (t_land + 0.3 - t_p))
        return z, pitch, dx

    def _flying(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = self.params
        x0, x1, y0, y1 = self.free_xy
        c = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), p["fly_height"]])
        half = np.array([0.5 * (x1 - x0), 0.5 * (y1 - y0), 0.35])
        pos = np.empty((len(t), 3))
        ypr = np.empty((len(t), 3))
        for k in range(3):
            pos[:, k] = c[k] + half[k] * _sines(p["fly_pos"][k], t)
            ypr[:, k] = _sines(p["fly_rot"][k], t)
        ypr[:, 0] += p["fly_yaw0"]
        return pos, ypr


def _sines(comp: tuple[np.ndarray, np.ndarray, np.ndarray], t: np.ndarray) -> np.ndarray:
    amps, freqs, phases = comp
    return np.sum(amps[:, None] * np.sin(2 * np.pi * freqs[:, None] * t + phases[:, None]), axis=0)


def euler_zyx(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """Rotation matrices ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``, vectorised (N, 3, 3)."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    R = np.empty(np.shape(yaw) + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def _schedule(scenario: str, duration_s: float, rng: np.random.Generator) -> GaitSchedule:
    if scenario in ("trot", "bound", "pronk"):
        return GaitSchedule(((0.0, scenario),))
    if scenario == "backflip":
        return GaitSchedule(((0.0, "trot"),), blend_s=0.5)  # replaced below (needs the flip time)
    # running: a mix of gaits changing every 2-5 s, like the paper's running1/2.
    segs = [(0.0, "trot")]
    t = float(rng.uniform(1.5, 3.0))
    order = [str(g) for g in rng.permutation(["bound", "pronk", "stand"])]
    i = 0
    while t < duration_s:
        segs.append((t, order[i % 3] if segs[-1][1] == "trot" else "trot"))
        i += segs[-1][1] != "trot"
        t += float(rng.uniform(2.0, 4.0))
    return GaitSchedule(tuple(segs), blend_s=0.6)


def make_motion(scenario: str, duration_s: float, seed: int,
                free_xy: tuple[float, float, float, float] | None = None, t0_ns: int = 0) -> Motion:
    """The body trajectory of ``scenario`` (one of :data:`SCENARIOS`), reproducible from ``seed``.

    ``free_xy`` is the floor rectangle the body stays inside (``Scene.free_xy``); by default the one
    of ``make_scene(seed)``, so that ``make_scene(s)`` and ``make_motion(..., s)`` fit together.
    """
    if free_xy is None:
        free_xy = scene_free_xy(seed)
    if scenario not in SCENARIOS:
        raise SimulationError(f"unknown scenario {scenario!r} (choose one of {', '.join(SCENARIOS)})")
    if not duration_s > 0:
        raise SimulationError(f"duration must be positive, got {duration_s} s")
    if scenario == "backflip" and duration_s < 2.2:
        raise SimulationError(f"a backflip needs at least 2.2 s (crouch, flight, landing), got {duration_s} s")
    x0, x1, y0, y1 = free_xy
    if x1 - x0 < 0.4 or y1 - y0 < 0.4:
        raise SimulationError(f"free floor area {free_xy} is too small for the robot")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x40710]))
    margin = 0.25
    params: dict = {
        "ax": max(0.5 * (x1 - x0) - margin, 0.1), "ay": max(0.5 * (y1 - y0) - margin, 0.1),
        "phi0": float(rng.uniform(0, 2 * np.pi)), "direction": float(rng.choice([-1.0, 1.0])),
        "look_amp": float(rng.uniform(0.15, 0.35)), "look_hz": float(rng.uniform(0.08, 0.2)),
        "look_phase": float(rng.uniform(0, 2 * np.pi)),
        "bound_gain": 1.0 + float(rng.uniform(-0.03, 0.03)),
        "pronk_air_s": float(rng.uniform(0.22, 0.28)), "pronk_stance_s": float(rng.uniform(0.14, 0.18)),
        "schedule": _schedule(scenario, duration_s, rng),
    }
    if scenario == "backflip":
        t_flip = float(np.clip(0.35 * duration_s, 0.3, duration_s - 1.9))
        params.update({
            "flip_t_s": t_flip, "flip_air_s": float(rng.uniform(0.5, 0.56)),
            "flip_peak_dps": BACKFLIP_PEAK_RATE_DPS + float(rng.uniform(0.0, 40.0)), "flip_ramp_s": 0.12,
            "flip_drift_m": float(rng.uniform(0.15, 0.3)),
            # Walk slowly, stand still for the flip, trot away after landing.
            "schedule": GaitSchedule(((0.0, "trot"), (max(t_flip - 0.6, 0.0), "stand"),
                                      (t_flip + 1.6, "trot")), blend_s=0.4),
        })
    if scenario == "flying":
        def comps(n, amp, fmin, fmax):
            a = rng.uniform(0.3, 1.0, n)
            return (amp * a / a.sum(), rng.uniform(fmin, fmax, n), rng.uniform(0, 2 * np.pi, n))

        params.update({
            "fly_height": float(rng.uniform(1.0, 1.4)),
            "fly_pos": [comps(3, 0.9, 0.03, 0.25), comps(3, 0.9, 0.03, 0.25), comps(3, 0.9, 0.05, 0.3)],
            "fly_rot": [comps(3, np.radians(60), 0.03, 0.2), comps(3, np.radians(8), 0.1, 0.5),
                        comps(3, np.radians(8), 0.1, 0.5)],
            "fly_yaw0": float(rng.uniform(-np.pi, np.pi)),
        })
    return Motion(scenario, float(duration_s), int(seed), tuple(float(v) for v in free_xy), int(t0_ns), params)
