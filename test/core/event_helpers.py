"""Events for the fusion tests: log-intensity threshold crossings between fine renders of a box room.

A deliberately simple event model (no noise, no refractory period) on :class:`BoxRoom` renders: enough
to give the time surface real moving edges with known geometry, independent of ``atsvo_ros.sim``.
"""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from test.core.render_helpers import BoxRoom


def simulate_events(room: BoxRoom, camera: CameraModel, pose_at, t0_ns: int, t1_ns: int, step_ns: int = 1_000_000,
                    contrast: float = 0.15) -> EventBatch:
    """Events of a camera whose pose ``pose_at(t_ns) -> T_w_c`` moves from ``t0_ns`` to ``t1_ns``."""
    ref = np.log(room.render(camera, pose_at(t0_ns), supersample=1)[0] + 10.0)
    prev = ref.copy()
    xs, ys, ts, ps = [], [], [], []
    t_prev = t0_ns
    for t in range(t0_ns + step_ns, t1_ns + 1, step_ns):
        cur = np.log(room.render(camera, pose_at(t), supersample=1)[0] + 10.0)
        diff = cur - ref
        n = np.floor(np.abs(diff) / contrast).astype(int)
        yy, xx = np.nonzero(n > 0)
        k = n[yy, xx]
        sign = np.sign(diff[yy, xx])
        rep = np.repeat(np.arange(len(k)), k)  # one entry per event
        j = np.arange(len(rep)) - np.repeat(np.cumsum(k) - k, k) + 1  # 1..k within each pixel
        level = ref[yy, xx][rep] + sign[rep] * j * contrast
        span = (cur - prev)[yy, xx][rep]
        safe = np.where(span == 0, 1.0, span)
        frac = np.where(span == 0, 0.5, np.clip((level - prev[yy, xx][rep]) / safe, 0.0, 1.0))
        xs.append(xx[rep])
        ys.append(yy[rep])
        ts.append((t_prev + frac * (t - t_prev)).astype(np.int64))
        ps.append((sign[rep] > 0).astype(np.uint8))
        ref[yy, xx] += sign * k * contrast
        prev = cur
        t_prev = t
    x, y, t, p = (np.concatenate(a) if a else np.zeros(0) for a in (xs, ys, ts, ps))
    order = np.argsort(t, kind="stable")
    return EventBatch(x[order], y[order], np.asarray(t, np.int64)[order], p[order], camera.width, camera.height)
