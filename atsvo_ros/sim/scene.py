"""Analytic indoor scenes: a textured room (inside of a box) with boxes and clutter.

Everything is a box, so ray casting is exact and cheap: the room's six inner faces plus ``N``
boxes that may be rotated about the vertical axis. Each face has a texture from a shared
:class:`~atsvo_ros.sim.textures.TextureAtlas`, a texel density, an offset and a colour tint. A
ceiling point light plus ambient light shades the albedo (no shadows). Face numbering:
room faces ``2*axis + side`` (side 0 = min, 1 = max), box ``i`` faces ``6 + 6*i + 2*axis + side``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.textures import TextureAtlas, build_atlas, make_texture

_LUMA = np.array([0.299, 0.587, 0.114])


@dataclass(frozen=True)
class Scene:
    """A room ``[room_min, room_max]`` (world frame, z up, floor at z = room_min[2]) with boxes.

    ``free_xy`` = ``(x0, x1, y0, y1)``: the floor area the robot may use, at least
    ``clearance_m`` from every wall and box (motions are planned inside it).
    """

    room_min: np.ndarray
    room_max: np.ndarray
    box_center: np.ndarray
    box_half: np.ndarray
    box_yaw: np.ndarray
    face_tex: np.ndarray
    face_texel_per_m: np.ndarray
    face_offset_m: np.ndarray
    face_tint: np.ndarray
    atlas: TextureAtlas
    light_pos: np.ndarray
    ambient: float
    free_xy: tuple[float, float, float, float]
    clearance_m: float = 0.6

    def __post_init__(self) -> None:
        n = len(self.box_center)
        if self.box_half.shape != (n, 3) or self.box_yaw.shape != (n,):
            raise SimulationError("box arrays must be (N, 3), (N, 3) and (N,)")
        nf = 6 + 6 * n
        for name in ("face_tex", "face_texel_per_m", "face_offset_m", "face_tint"):
            if len(getattr(self, name)) != nf:
                raise SimulationError(f"{name} must have {nf} rows (6 room faces + 6 per box)")
        if np.any(self.room_max - self.room_min <= 0):
            raise SimulationError("room_max must exceed room_min on every axis")
        if self.face_tex.max(initial=0) >= len(self.atlas.names):
            raise SimulationError("a face refers to a texture the atlas does not hold")

    @property
    def n_boxes(self) -> int:
        return len(self.box_center)

    @property
    def box_cos_sin(self) -> np.ndarray:
        return np.column_stack([np.cos(self.box_yaw), np.sin(self.box_yaw)])

    def inside_free_space(self, p_w: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Mask of points (N, 3) inside the room and outside every box by at least ``margin_m``."""
        p = np.atleast_2d(np.asarray(p_w, dtype=np.float64))
        ok = np.all((p > self.room_min + margin_m) & (p < self.room_max - margin_m), axis=1)
        for c, h, yaw in zip(self.box_center, self.box_half, self.box_yaw):
            d = p - c
            cs, sn = np.cos(yaw), np.sin(yaw)
            local = np.column_stack([cs * d[:, 0] + sn * d[:, 1], -sn * d[:, 0] + cs * d[:, 1], d[:, 2]])
            ok &= ~np.all(np.abs(local) < h + margin_m, axis=1)
        return ok


def build_scene(room_min, room_max, boxes: list[tuple], textures: list[np.ndarray], face_tex, *,
                face_texel_per_m=None, face_offset_m=None, face_tint=None, light_pos=None,
                ambient: float = 0.35, free_xy=None, clearance_m: float = 0.6) -> Scene:
    """Assemble a :class:`Scene` from plain values (tests build tiny hand-made scenes with it).

    ``boxes`` holds ``(center_xyz, half_extents_xyz, yaw_rad)`` tuples; per-face arrays default to
    128 texels/m, zero offset and a neutral tint.
    """
    room_min = np.asarray(room_min, np.float64)
    room_max = np.asarray(room_max, np.float64)
    n = len(boxes)
    nf = 6 + 6 * n
    centers = np.array([b[0] for b in boxes], np.float64).reshape(n, 3)
    halves = np.array([b[1] for b in boxes], np.float64).reshape(n, 3)
    yaws = np.array([b[2] for b in boxes], np.float64).reshape(n)
    face_tex = np.broadcast_to(np.asarray(face_tex, np.int64), (nf,)).copy()
    tpm = np.broadcast_to(np.asarray(128.0 if face_texel_per_m is None else face_texel_per_m, np.float64),
                          (nf,)).copy()
    off = np.zeros((nf, 2)) if face_offset_m is None else np.asarray(face_offset_m, np.float64).reshape(nf, 2)
    tint = np.ones((nf, 3)) if face_tint is None else np.asarray(face_tint, np.float64).reshape(nf, 3)
    if light_pos is None:
        light_pos = np.array([(room_min[0] + room_max[0]) / 2, (room_min[1] + room_max[1]) / 2, room_max[2] - 0.05])
    if free_xy is None:
        free_xy = (room_min[0], room_max[0], room_min[1], room_max[1])
    return Scene(room_min, room_max, centers, halves, yaws, face_tex, tpm, off, tint, build_atlas(textures),
                 np.asarray(light_pos, np.float64), float(ambient), tuple(float(v) for v in free_xy),
                 float(clearance_m))


_BOX_BAND_M = 1.3
_CLEARANCE_M = 0.6


def _scene_rng(seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), 0x5CE4E]))


def _room_size(rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.uniform(7.0, 9.0), rng.uniform(5.5, 7.5), rng.uniform(2.6, 3.2)])


def _free_xy(size: np.ndarray) -> tuple[float, float, float, float]:
    margin = _BOX_BAND_M + _CLEARANCE_M
    return (margin, float(size[0]) - margin, margin, float(size[1]) - margin)


def scene_free_xy(seed: int) -> tuple[float, float, float, float]:
    """``make_scene(seed).free_xy`` without building the scene (textures are the costly part)."""
    return _free_xy(_room_size(_scene_rng(seed)))


def make_scene(seed: int, texture_size: int = 512) -> Scene:
    """A random furnished room, reproducible from ``seed``.

    Room 7-9 m x 5.5-7.5 m x 2.6-3.2 m; 10-16 boxes (0.25-1.3 m) stand along the walls, some
    stacked and slightly rotated; the central free area keeps the robot >= 0.6 m from them so
    the cameras see structure at 0.5-6 m.
    """
    rng = _scene_rng(seed)
    size = _room_size(rng)
    room_min, room_max = np.zeros(3), size
    band = _BOX_BAND_M  # boxes live within this distance of the walls
    boxes: list[tuple] = []

    def fits(c, h, yaw):
        r = np.hypot(h[0], h[1])
        for c2, h2, _ in boxes:
            if np.hypot(*(c[:2] - c2[:2])) < r + np.hypot(h2[0], h2[1]) and abs(c[2] - c2[2]) < h[2] + h2[2]:
                return False
        return True

    tries = 0
    target = int(rng.integers(10, 17))
    while len(boxes) < target and tries < 400:
        tries += 1
        h = np.array([rng.uniform(0.15, 0.6), rng.uniform(0.15, 0.5), rng.uniform(0.12, 0.7)])
        yaw = float(rng.uniform(-0.3, 0.3))
        r = np.hypot(h[0], h[1])
        wall = rng.integers(4)
        if 2 * r + 0.02 > band:  # leave room for the 2 cm clearance below
            continue
        along = rng.uniform(r, (size[0] if wall < 2 else size[1]) - r)
        across = rng.uniform(r + 0.02, band - r)
        if wall == 0:
            c = np.array([along, across, h[2]])
        elif wall == 1:
            c = np.array([along, size[1] - across, h[2]])
        elif wall == 2:
            c = np.array([across, along, h[2]])
        else:
            c = np.array([size[0] - across, along, h[2]])
        if fits(c, h, yaw):
            boxes.append((c, h, yaw))
            if rng.random() < 0.3:  # a smaller box stacked on top
                h2 = h * np.array([rng.uniform(0.4, 0.9), rng.uniform(0.4, 0.9), rng.uniform(0.4, 1.0)])
                boxes.append((c + np.array([0.0, 0.0, h[2] + h2[2]]), h2, yaw + float(rng.uniform(-0.3, 0.3))))
    free_xy = _free_xy(size)

    styles_floor, styles_wall, styles_box = ("carpet", "wood", "concrete"), ("plaster", "poster", "concrete"), \
        ("cardboard", "poster", "wood")
    names = ["plaster", "plaster", "poster", "poster", "concrete", "wood", "carpet", "cardboard", "cardboard"]
    textures = [make_texture(rng, texture_size, s) for s in names]
    by_style = {s: [i for i, n in enumerate(names) if n == s] for s in set(names)}

    def pick(styles):
        return int(rng.choice(by_style[str(rng.choice(styles))]))

    nf = 6 + 6 * len(boxes)
    face_tex = np.zeros(nf, np.int64)
    tpm = np.zeros(nf)
    for f in range(nf):
        if f < 6:
            axis = f // 2
            styles = styles_wall if axis < 2 else (styles_floor if f == 4 else ("plaster",))
            tile_m = rng.uniform(2.0, 3.0) if axis < 2 else rng.uniform(2.0, 3.5)
        else:
            styles, tile_m = styles_box, rng.uniform(0.6, 1.4)
        face_tex[f] = pick(styles)
        tpm[f] = texture_size / tile_m
    tint = 1.0 + rng.uniform(-0.15, 0.15, (nf, 3))
    tint /= (tint @ _LUMA)[:, None]
    offset = rng.uniform(0.0, 5.0, (nf, 2))
    light = np.array([size[0] * rng.uniform(0.4, 0.6), size[1] * rng.uniform(0.4, 0.6), size[2] - 0.05])
    return build_scene(room_min, room_max, boxes, textures, face_tex, face_texel_per_m=tpm, face_offset_m=offset,
                       face_tint=tint, light_pos=light, ambient=float(rng.uniform(0.3, 0.45)), free_xy=free_xy)
