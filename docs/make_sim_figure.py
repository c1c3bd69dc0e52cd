"""Make docs/sim_backflip.png: colour (motion blur), D455 depth, true depth and events in a backflip.

Usage: ``python docs/make_sim_figure.py [--out docs/sim_backflip.png] [--seed 1]`` (about a minute:
the sequence is generated up to the chosen frame only).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib
import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.geometry import so3_log
from atsvo_ros.sim.render import Renderer
from atsvo_ros.sim.sequence import RgbdFrame, SequenceSpec, Simulation, iter_sequence


def _pick_stamp(sim: Simulation, rate_dps: float) -> int:
    """The frame stamp during the flip's spin-up where the pitch rate first reaches ``rate_dps``."""
    ts = sim.motion.stamps_ns(1000.0)
    R = sim.motion.T_world_base(ts)[:, :3, :3]
    w = np.degrees(np.abs(so3_log(np.swapaxes(R[:-1], 1, 2) @ R[1:])[:, 1]) * 1000.0)
    t_hit = ts[int(np.argmax(w >= rate_dps))]
    period = 1e9 / sim.spec.rate_hz
    k = round((t_hit - sim.t_start_ns) / period)
    return sim.t_start_ns + int(round(k * period))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).with_name("sim_backflip.png")))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--rate-dps", type=float, default=400.0, help="pitch rate at the shown frame")
    ap.add_argument("--window-ms", type=float, default=1.0, help="events shown around the frame stamp")
    args = ap.parse_args()
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spec = SequenceSpec(scenario="backflip", duration_s=3.0, seed=args.seed)
    stamp = _pick_stamp(Simulation(spec), args.rate_dps)
    half = int(args.window_ms * 0.5e6)
    frame, events = None, []
    for item in iter_sequence(spec):
        if isinstance(item, EventBatch) and stamp - half <= item.t[-1] and item.t[0] < stamp + half:
            events.append(item)
        elif isinstance(item, RgbdFrame) and item.stamp_ns == stamp:
            frame = item
        if frame is not None and isinstance(item, EventBatch) and item.t[0] >= stamp + half:
            break
    ev = EventBatch.concatenate(events)
    ev = ev.select((ev.t >= stamp - half) & (ev.t < stamp + half))
    img = np.ones((ev.height, ev.width, 3))
    img[ev.y[ev.p == 1], ev.x[ev.p == 1]] = (0.85, 0.1, 0.1)
    img[ev.y[ev.p == 0], ev.x[ev.p == 0]] = (0.1, 0.2, 0.85)
    depth = frame.depth_m
    sim = Simulation(spec)
    truth = Renderer(sim.scene, sim.rig.rgb_camera).render(sim.T_world_rgb(stamp))[1]
    fig, axes = plt.subplots(1, 4, figsize=(16, 3.2), dpi=100)
    axes[0].imshow(frame.rgb)
    axes[0].set_title(f"RGB, {spec.exposure_s * 1e3:.0f} ms exposure (motion blur)")
    im = axes[1].imshow(np.ma.masked_invalid(depth), cmap="turbo", vmin=0.3, vmax=6.0)
    axes[1].set_title(f"D455 depth (m), exposed {sim.depth_phase_s * 1e3:+.1f} ms away; holes = none")
    fig.colorbar(im, ax=axes[1], fraction=0.035, pad=0.02)
    axes[2].imshow(truth, cmap="turbo", vmin=0.3, vmax=6.0)
    axes[2].set_title("true depth at the colour image's time")
    axes[3].imshow(img, interpolation="nearest")
    axes[3].set_title(f"events +/-{args.window_ms / 2:g} ms ({len(ev)}; red ON, blue OFF)")
    for a in axes:
        a.set_axis_off()
    t_s = (stamp - spec.start_ns) * 1e-9
    fig.suptitle(f"atsvo-sim backflip, seed {args.seed}, t = {t_s:.3f} s, pitch rate ~{args.rate_dps:.0f} deg/s",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
