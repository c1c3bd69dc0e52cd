"""A DBoW2 vocabulary of ORB descriptors, trained here, in the text format ORB-SLAM3 loads (``ORBvoc.txt``).

ORB-SLAM3's pip bindings ship no vocabulary and fetch one at run time, which an offline machine cannot. Its
words only index keypoints for matching and place recognition, so a smaller tree trained on other images serves
its tracking: the same hierarchical k-majority clustering as DBoW2 (Galvez-Lopez and Tardos, 2012; k-means++
seeding, centres the bitwise majority, Hamming distances), leaves weighted by inverse document frequency (TF-IDF
scoring, L1 norm: ORB-SLAM's ``k L 0 0`` header). No I/O but :func:`write_text`.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

#: an ORB descriptor's length in bytes (DBoW2's ``FORB::L``)
DESCRIPTOR_BYTES = 32


@dataclass(frozen=True)
class VocabularyTree:
    """The nodes of a vocabulary tree in breadth-first order (node 0 is the root; parents before children).

    ``parent[i]``, ``is_leaf[i]``, ``descriptor[i]`` (32 bytes) and ``weight[i]`` (IDF for leaves, 0 else)
    for nodes ``1..n``; row 0 is the root's placeholder.
    """

    k: int
    levels: int
    parent: np.ndarray
    is_leaf: np.ndarray
    descriptor: np.ndarray
    weight: np.ndarray

    @property
    def n_words(self) -> int:
        return int(np.count_nonzero(self.is_leaf))


def orb_descriptors(images: Iterable[np.ndarray], n_features: int = 1000) -> list[np.ndarray]:
    """ORB descriptors (n x 32 uint8) of each grey or RGB image, with ORB-SLAM's pyramid (8 levels, x1.2)."""
    orb = cv2.ORB_create(nfeatures=n_features, scaleFactor=1.2, nlevels=8, fastThreshold=20)
    out = []
    for img in images:
        grey = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        _, desc = orb.detectAndCompute(grey, None)
        out.append(np.zeros((0, DESCRIPTOR_BYTES), np.uint8) if desc is None else desc)
    return out


def _hamming(bits: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Hamming distances (n x m) between unpacked bit rows (float32, 0/1) and unpacked centres."""
    return bits.sum(1, keepdims=True) + centres.sum(1)[None, :] - 2.0 * (bits @ centres.T)


def _k_majority(bits: np.ndarray, k: int, rng: np.random.Generator, iterations: int = 10) -> np.ndarray:
    """Cluster labels of ``bits`` into ``k`` groups: k-means++ seeds, then majority centres until stable."""
    n = len(bits)
    centres = [bits[rng.integers(n)]]
    d = _hamming(bits, centres[0][None, :])[:, 0]
    for _ in range(1, k):
        p = d ** 2
        total = p.sum()
        idx = int(rng.choice(n, p=p / total)) if total > 0 else int(rng.integers(n))
        centres.append(bits[idx])
        d = np.minimum(d, _hamming(bits, bits[idx][None, :])[:, 0])
    c = np.stack(centres)
    labels = np.full(n, -1)
    for _ in range(iterations):
        new = np.argmin(_hamming(bits, c), axis=1)
        if np.array_equal(new, labels):
            break
        labels = new
        for j in range(k):
            members = bits[labels == j]
            if len(members):
                c[j] = (members.mean(0) >= 0.5).astype(np.float32)
    return labels


def train(descriptors_per_image: list[np.ndarray], k: int = 10, levels: int = 4, seed: int = 0) -> VocabularyTree:
    """Train a ``k``-ary tree of ``levels`` levels on the descriptors of a set of images (one array per image)."""
    if not 2 <= k <= 20 or not 1 <= levels <= 10:
        raise ValueError(f"a DBoW2 vocabulary needs 2 <= k <= 20 and 1 <= levels <= 10 (got k={k}, levels={levels})")
    desc = np.concatenate([d for d in descriptors_per_image if len(d)])
    image_of = np.concatenate([np.full(len(d), i) for i, d in enumerate(descriptors_per_image) if len(d)])
    if len(desc) < k:
        raise ValueError(f"{len(desc)} descriptors cannot train a vocabulary of branching {k}")
    bits = np.unpackbits(desc, axis=1).astype(np.float32)
    rng = np.random.default_rng(seed)
    parent, leaf, centre, members = [0], [False], [np.zeros(8 * DESCRIPTOR_BYTES, np.float32)], [None]
    queue = [(0, np.arange(len(desc)), 0)]  # (node, its descriptors, its level): breadth first
    while queue:
        node, idx, level = queue.pop(0)
        if len(idx) <= k:  # as DBoW2: each descriptor its own cluster
            groups = [np.array([i]) for i in idx]
        else:
            labels = _k_majority(bits[idx], k, rng)
            groups = [idx[labels == j] for j in range(k) if np.any(labels == j)]
        for g in groups:
            child = len(parent)
            parent.append(node)
            centre.append((bits[g].mean(0) >= 0.5).astype(np.float32))
            deeper = level + 1 < levels and len(g) > 1
            leaf.append(not deeper)
            members.append(g)
            if deeper:
                queue.append((child, g, level + 1))
    n_images = len(descriptors_per_image)
    weight = np.zeros(len(parent))
    for i, g in enumerate(members):
        if leaf[i] and g is not None:
            weight[i] = np.log(n_images / len(np.unique(image_of[g])))
    return VocabularyTree(k, levels, np.array(parent), np.array(leaf),
                          np.packbits(np.array(centre, np.uint8), axis=1), weight)


def write_text(tree: VocabularyTree, path: str | Path) -> None:
    """Write ``tree`` as DBoW2's text vocabulary (``k L scoring weighting``, then one node per line)."""
    lines = [f"{tree.k} {tree.levels} 0 0"]  # L1 norm scoring, TF-IDF weighting: ORB-SLAM's
    for i in range(1, len(tree.parent)):
        d = " ".join(str(int(b)) for b in tree.descriptor[i])
        lines.append(f"{int(tree.parent[i])} {int(tree.is_leaf[i])} {d} {tree.weight[i]:.6f}")
    # no newline after the last node: DBoW2's reader would take the empty line for one more node
    Path(path).write_text("\n".join(lines))
