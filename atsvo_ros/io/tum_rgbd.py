"""TUM RGB-D benchmark folders (``rgb.txt``, ``depth.txt``, ``groundtruth.txt``) -> frames, streamed.

Format (TUM's "file formats" page): the list files hold ``timestamp filename`` lines, comments
start with ``#``; colour PNGs are 8-bit RGB on the raw (distorted) colour grid, depth PNGs are
uint16 registered to the colour image, ``value / 5000`` metres, 0 = no measurement;
``groundtruth.txt`` is ``timestamp tx ty tz qx qy qz qw``, the colour optical frame in the
motion-capture world. Colour and depth are not taken at the same time: they are paired by TUM's
``associate.py`` rule (every pair closer than ``max_diff_s``, closest first, each image used at
most once). Only the lists are held in memory; images are read one pair at a time.

:class:`TumSource` adapts a reader to ``atsvo-replay`` (the same role as its MVSEC source).
"""
from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import ConfigError, DatasetError, ImageError
from atsvo_ros.io.images import depth_to_metres
from atsvo_ros.io.trajectory import _seconds_to_ns, read_tum

#: metres per depth unit in TUM's 16-bit depth PNGs
TUM_DEPTH_SCALE_M = 1.0 / 5000.0
#: TUM associate.py's default pairing window
DEFAULT_MAX_DIFF_S = 0.02

_FREIBURG = re.compile(r"(?<![a-z0-9])(?:freiburg|fr)[ _-]?([123])(?![0-9])", re.IGNORECASE)


@dataclass(frozen=True)
class TumEntry:
    """One line of rgb.txt / depth.txt: stamp, image path (resolved) and where it was listed."""

    stamp_ns: int
    path: Path
    list_file: Path
    line: int


@dataclass(frozen=True)
class TumPair:
    """An associated colour/depth pair; the frame's stamp is the colour stamp."""

    rgb: TumEntry
    depth: TumEntry

    @property
    def stamp_ns(self) -> int:
        return self.rgb.stamp_ns

    @property
    def depth_offset_ns(self) -> int:
        """Depth stamp minus colour stamp (the depth map is this much later than the colour image)."""
        return self.depth.stamp_ns - self.rgb.stamp_ns


@dataclass(frozen=True)
class TumFrame:
    """A loaded pair: RGB uint8 (H, W, 3) and raw uint16 depth (H, W) (``* 1/5000`` = metres, 0 = none)."""

    index: int
    stamp_ns: int
    depth_stamp_ns: int
    rgb: np.ndarray
    depth_raw: np.ndarray


def is_tum_folder(path: str | Path) -> bool:
    """True for a directory holding ``rgb.txt`` and ``depth.txt``."""
    p = Path(path)
    return p.is_dir() and (p / "rgb.txt").is_file() and (p / "depth.txt").is_file()


def read_file_list(path: str | Path) -> list[TumEntry]:
    """Parse a ``timestamp filename`` list; stamps must increase strictly. Raises DatasetError(file:line)."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read {path}: {getattr(exc, 'strerror', None) or exc}") from None
    out: list[TumEntry] = []
    for lineno, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.replace(",", " ").replace("\t", " ").split()
        if len(parts) != 2:
            raise DatasetError(f"{path}:{lineno}: expected 'timestamp filename', got {line!r}")
        try:
            if not re.fullmatch(r"\d+(\.\d*)?", parts[0]):
                raise ValueError
            stamp = _seconds_to_ns(parts[0])
        except ValueError:
            raise DatasetError(f"{path}:{lineno}: timestamp {parts[0]!r} is not a number of seconds") from None
        if out and stamp <= out[-1].stamp_ns:
            raise DatasetError(f"{path}:{lineno}: timestamp {parts[0]} is not after the one on line {out[-1].line}")
        out.append(TumEntry(stamp, path.parent / parts[1], path, lineno))
    return out


def associate_stamps(first_ns: np.ndarray, second_ns: np.ndarray, max_diff_ns: int,
                     offset_ns: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(i, j)`` by TUM's associate.py rule, sorted by ``i``.

    Candidates are all pairs with ``|first[i] - (second[j] + offset)| < max_diff``; they are taken
    closest first (ties: earlier ``first``, then earlier ``second``), skipping any whose image is
    already used. Both inputs must be sorted.
    """
    a = np.asarray(first_ns, np.int64)
    b = np.asarray(second_ns, np.int64) + int(offset_ns)
    lo = np.searchsorted(b, a - max_diff_ns, side="right")
    hi = np.searchsorted(b, a + max_diff_ns, side="left")
    counts = hi - lo
    ia = np.repeat(np.arange(len(a)), counts)
    ib = (np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)) + np.repeat(lo, counts)
    diff = np.abs(a[ia] - b[ib])
    order = np.lexsort((ib, ia, diff))
    used_a = np.zeros(len(a), bool)
    used_b = np.zeros(len(b), bool)
    keep = []
    for k in order.tolist():  # greedy one-to-one pick: sequential by nature, ~1-2 candidates per image
        i, j = ia[k], ib[k]
        if not used_a[i] and not used_b[j]:
            used_a[i] = used_b[j] = True
            keep.append(k)
    keep_arr = np.asarray(keep, np.int64)
    sel = np.argsort(ia[keep_arr], kind="stable")
    return ia[keep_arr][sel], ib[keep_arr][sel]


def detect_tum_preset(folder: str | Path) -> tuple[str, str] | None:
    """``('tum_frN', where)`` from 'freiburgN' / 'frN' in the folder name, its README.txt or the lists' headers."""
    folder = Path(folder)
    m = _FREIBURG.search(folder.resolve().name)
    if m:
        return f"tum_fr{m.group(1)}", "the folder name"
    for name in ("README.txt", "rgb.txt", "depth.txt", "groundtruth.txt"):
        p = folder / name
        if not p.is_file():
            continue
        try:
            with p.open(errors="replace") as fh:
                head = fh.read(4096)
        except OSError:
            continue
        if name != "README.txt":  # only the comment lines of the lists
            head = "\n".join(line for line in head.splitlines() if line.lstrip().startswith("#"))
        m = _FREIBURG.search(head)
        if m:
            return f"tum_fr{m.group(1)}", name
    return None


def _imread(path: Path, entry: TumEntry, flags: int) -> np.ndarray:
    if not path.is_file():
        raise DatasetError(f"{entry.list_file}:{entry.line}: image {path} does not exist")
    img = cv2.imread(str(path), flags)
    if img is None:
        raise ImageError(f"cannot decode image {path} (listed in {entry.list_file}:{entry.line})")
    return img


def read_colour(entry: TumEntry) -> np.ndarray:
    """RGB uint8 (H, W, 3) of a colour entry."""

    img = _imread(entry.path, entry, cv2.IMREAD_COLOR)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def read_depth(entry: TumEntry) -> np.ndarray:
    """Raw uint16 depth (H, W) of a depth entry (TUM: 5000 units per metre, 0 = none)."""

    img = _imread(entry.path, entry, cv2.IMREAD_UNCHANGED)
    if img.dtype != np.uint16 or img.ndim != 2:
        raise ImageError(f"depth image {entry.path} must be 16-bit single channel, got {img.dtype} "
                         f"with shape {img.shape} (listed in {entry.list_file}:{entry.line})")
    return img


class TumRgbdReader:
    """Reader over one TUM RGB-D folder; use as a context manager.

    Args:
        folder: directory with rgb.txt, depth.txt (and usually groundtruth.txt).
        max_diff_s: colour/depth pairing window (associate.py's ``--max_difference``).
        offset_s: added to the depth stamps before pairing (associate.py's ``--offset``).
    """

    def __init__(self, folder: str | Path, max_diff_s: float = DEFAULT_MAX_DIFF_S, offset_s: float = 0.0) -> None:
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise DatasetError(f"TUM RGB-D folder {self.folder} does not exist")
        for name in ("rgb.txt", "depth.txt"):
            if not (self.folder / name).is_file():
                raise DatasetError(f"{self.folder} is not a TUM RGB-D folder: it has no {name}")
        rgb = read_file_list(self.folder / "rgb.txt")
        depth = read_file_list(self.folder / "depth.txt")
        ia, ib = associate_stamps(np.array([e.stamp_ns for e in rgb], np.int64),
                                  np.array([e.stamp_ns for e in depth], np.int64),
                                  int(round(max_diff_s * 1e9)), int(round(offset_s * 1e9)))
        if len(ia) == 0:
            raise DatasetError(f"no colour/depth pair within {max_diff_s * 1e3:g} ms in {self.folder} "
                               f"({len(rgb)} colour, {len(depth)} depth images listed)")
        self.pairs = [TumPair(rgb[i], depth[j]) for i, j in zip(ia.tolist(), ib.tolist())]
        self.n_rgb, self.n_depth = len(rgb), len(depth)
        gt = self.folder / "groundtruth.txt"
        self.groundtruth_path = gt if gt.is_file() else None

    def __enter__(self) -> TumRgbdReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Nothing stays open between frames; kept for the reader interface."""

    def __len__(self) -> int:
        return len(self.pairs)

    @property
    def stamps_ns(self) -> np.ndarray:
        """Frame (colour) stamps of the pairs."""
        return np.array([p.stamp_ns for p in self.pairs], np.int64)

    @property
    def depth_offsets_ns(self) -> np.ndarray:
        """Depth minus colour stamp per pair."""
        return np.array([p.depth_offset_ns for p in self.pairs], np.int64)

    @property
    def duration_s(self) -> float:
        return (self.pairs[-1].stamp_ns - self.pairs[0].stamp_ns) * 1e-9

    def has(self, role: str) -> bool:
        """Whether the folder provides ``rgb``, ``depth`` or ``ground_truth`` (never ``events``)."""
        return role in ("rgb", "depth") or (role == "ground_truth" and self.groundtruth_path is not None)

    def ground_truth(self):
        """groundtruth.txt as a :class:`~atsvo_ros.io.trajectory.Trajectory` (colour optical frame in world)."""

        if self.groundtruth_path is None:
            raise DatasetError(f"{self.folder} has no groundtruth.txt")
        return read_tum(self.groundtruth_path).sorted_unique()

    def preset(self) -> tuple[str, str] | None:
        """See :func:`detect_tum_preset`."""
        return detect_tum_preset(self.folder)

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[TumFrame]:
        """Load the pairs ``start:stop`` one at a time, in time order; a missing or corrupt image raises."""
        for k in range(start, len(self.pairs) if stop is None else min(stop, len(self.pairs))):
            yield self.frame(k)

    def frame(self, k: int) -> TumFrame:
        """Load pair ``k``. Raises DatasetError (image missing) or ImageError (undecodable, sizes differ)."""
        p = self.pairs[k]
        rgb, depth = read_colour(p.rgb), read_depth(p.depth)
        if rgb.shape[:2] != depth.shape:
            raise ImageError(f"depth {p.depth.path} is {depth.shape[1]}x{depth.shape[0]} but colour "
                             f"{p.rgb.path} is {rgb.shape[1]}x{rgb.shape[0]}")
        return TumFrame(k, p.stamp_ns, p.depth.stamp_ns, rgb, depth)

    def summary(self) -> str:
        """One line on the pairing (for notes and logs)."""
        off = self.depth_offsets_ns * 1e-6
        return (f"{len(self.pairs)} colour/depth pairs (associate.py rule) from {self.n_rgb} colour and "
                f"{self.n_depth} depth images; depth - colour stamp: median {np.median(off):.1f} ms, "
                f"range {off.min():.1f} to {off.max():.1f} ms")


class TumSource:
    """A TUM folder as an ``atsvo-replay`` source (cameras from the preset, poses = colour optical frame).

    Each depth map is handed to the frame assembler at its colour image's stamp, so the replay
    tracks exactly the associate.py pairs (the assembler's own nearest-stamp rule can pair
    differently).
    """

    topic_types: dict[str, str] = {}
    #: trajectory.tum holds the colour optical frame by default: that is what groundtruth.txt gives
    default_frame = "camera"

    def __init__(self, folder: str | Path) -> None:
        self.reader = TumRgbdReader(folder)

    @property
    def preset(self) -> str:
        """The bundled preset for this folder; ConfigError when the name/README do not tell."""
        found = self.reader.preset()
        if found is None:
            raise ConfigError(f"cannot tell the Freiburg camera (fr1/fr2/fr3) of {self.reader.folder} from its name "
                              "or README.txt; pass --preset tum_fr1|tum_fr2|tum_fr3 or --config")
        return found[0]

    @property
    def preset_note(self) -> str:
        found = self.reader.preset()
        return f"config preset {self.preset} (from {found[1] if found else '?'})"

    def close(self) -> None:
        self.reader.close()

    def has(self, role: str) -> bool:
        return self.reader.has(role)

    def require(self) -> None:
        """The reader already refused a folder without pairs."""

    def n_frames(self) -> int:
        return len(self.reader)

    def duration_s(self) -> float:
        return self.reader.duration_s

    def setup(self, config: Any, notes: list[str]):
        notes.append(f"TUM folder: {self.reader.summary()}; cameras and extrinsics from the configuration")
        if not np.isclose(config.rig.depth_scale_m, TUM_DEPTH_SCALE_M, rtol=1e-9):
            notes.append(f"warning: rig.depth_scale_m = {config.rig.depth_scale_m:g} differs from TUM's 1/5000 m, so "
                         f"depths are read {config.rig.depth_scale_m / TUM_DEPTH_SCALE_M:g}x what the files say; "
                         "a TUM dataset wants --preset tum_fr1|tum_fr2|tum_fr3 (or --set rig.depth_scale_m=0.0002)")
        self._rig = config.rig
        return config, CameraModel.from_config(config.rgb_camera), CameraModel.from_config(config.event_camera)

    def feed(self, sink: Any, roles: tuple[str, ...], gt: list | None) -> Iterator[None]:
        """Generator: one colour image or depth map into ``sink`` per step (ground truth into ``gt``)."""

        if gt is not None and self.reader.has("ground_truth"):
            g = self.reader.ground_truth()
            gt.extend(zip(g.stamps_ns.tolist(), g.T_w_b))
        rig = self._rig
        for k in range(len(self.reader)):
            try:
                fr = self.reader.frame(k)
            except (DatasetError, ImageError) as exc:  # one bad image costs its frame, not the run (as in a bag)
                sink.skip_input("images_rejected", f"TUM pair {k} skipped: {exc}")
                yield
                continue
            sink.add_rgb(fr.stamp_ns, fr.rgb)
            yield
            sink.add_depth(fr.stamp_ns, depth_to_metres(fr.depth_raw, rig.depth_scale_m, rig.depth_min_m,
                                                        rig.depth_max_m))
            yield

    def decoder_stats(self) -> dict[str, Any]:
        return {}

    def read_problems(self) -> tuple[dict[str, Any] | None, list[str]]:
        return None, []


__all__ = ["DEFAULT_MAX_DIFF_S", "TUM_DEPTH_SCALE_M", "TumEntry", "TumFrame", "TumPair", "TumRgbdReader",
           "TumSource", "associate_stamps", "detect_tum_preset", "is_tum_folder", "read_colour", "read_depth",
           "read_file_list"]
