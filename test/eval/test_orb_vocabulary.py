"""The DBoW2 vocabulary trainer: clusters, inverse document frequencies and the text format ORB-SLAM3 reads."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.eval.orb_vocabulary import DESCRIPTOR_BYTES, orb_descriptors, train, write_text


def _noisy(prototype: np.ndarray, n: int, rng: np.random.Generator, flips: int = 6) -> np.ndarray:
    """``n`` copies of a 32-byte descriptor with ``flips`` random bits flipped in each."""
    bits = np.tile(np.unpackbits(prototype), (n, 1))
    for row in bits:
        row[rng.choice(256, flips, replace=False)] ^= 1
    return np.packbits(bits, axis=1)


def test_three_clusters_give_three_words_at_their_prototypes():
    rng = np.random.default_rng(3)
    protos = rng.integers(0, 256, (3, DESCRIPTOR_BYTES), dtype=np.uint8)  # ~128 bits apart
    # image 0 sees words 0 and 1, image 1 words 1 and 2, image 2 word 1 only
    images = [np.concatenate([_noisy(protos[0], 40, rng), _noisy(protos[1], 40, rng)]),
              np.concatenate([_noisy(protos[1], 40, rng), _noisy(protos[2], 40, rng)]),
              _noisy(protos[1], 40, rng)]
    tree = train(images, k=3, levels=1)
    assert tree.n_words == 3 and len(tree.parent) == 4 and np.all(tree.parent[1:] == 0)
    found = {int(np.argmin([np.unpackbits(d ^ p).sum() for p in protos])): i
             for i, d in enumerate(tree.descriptor[1:], start=1)}
    assert sorted(found) == [0, 1, 2]
    for word, node in found.items():
        # the bitwise majority of 40 copies with 6 of 256 bits flipped is the prototype itself
        assert np.array_equal(tree.descriptor[node], protos[word])
    # inverse document frequency: word 1 is in every image (weight 0), words 0 and 2 in one of three
    assert tree.weight[found[1]] == pytest.approx(0.0)
    assert tree.weight[found[0]] == pytest.approx(np.log(3.0))
    assert tree.weight[found[2]] == pytest.approx(np.log(3.0))


def test_deeper_trees_number_parents_before_children():
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (300, DESCRIPTOR_BYTES), dtype=np.uint8) for _ in range(4)]
    tree = train(images, k=4, levels=3)
    assert np.all(tree.parent[1:] < np.arange(1, len(tree.parent)))  # DBoW2's reader needs each parent first
    inner = set(tree.parent[1:].tolist())
    assert all(tree.is_leaf[i] == (i not in inner) for i in range(1, len(tree.parent)))
    assert np.all(tree.weight[~tree.is_leaf] == 0.0)
    assert 4 < tree.n_words <= 4 ** 3


def test_text_format_is_dbow2s(tmp_path):
    rng = np.random.default_rng(1)
    tree = train([rng.integers(0, 256, (50, DESCRIPTOR_BYTES), dtype=np.uint8) for _ in range(2)], k=5, levels=2)
    path = tmp_path / "voc.txt"
    write_text(tree, path)
    text = path.read_text()
    assert not text.endswith("\n")  # DBoW2 would read an empty last line as one more node
    header, *nodes = text.split("\n")
    assert header == "5 2 0 0" and len(nodes) == len(tree.parent) - 1
    for i, line in enumerate(nodes, start=1):
        fields = line.split()
        assert len(fields) == 2 + DESCRIPTOR_BYTES + 1
        assert int(fields[0]) == tree.parent[i] and int(fields[1]) == int(tree.is_leaf[i])
        assert bytes(int(v) for v in fields[2:-1]) == tree.descriptor[i].tobytes()
        assert float(fields[-1]) == pytest.approx(tree.weight[i], abs=1e-6)


def test_orb_descriptors_of_a_textured_image():
    rng = np.random.default_rng(2)
    img = (rng.random((240, 320, 3)) * 255).astype(np.uint8)
    (desc,) = orb_descriptors([img], n_features=200)
    assert desc.dtype == np.uint8 and desc.shape[1] == DESCRIPTOR_BYTES and 50 <= len(desc) <= 200
    (none,) = orb_descriptors([np.zeros((240, 320), np.uint8)])
    assert none.shape == (0, DESCRIPTOR_BYTES)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="2 <= k <= 20"):
        train([np.zeros((30, DESCRIPTOR_BYTES), np.uint8)], k=1)
    with pytest.raises(ValueError, match="cannot train"):
        train([np.zeros((3, DESCRIPTOR_BYTES), np.uint8)], k=10)
