"""ORB-SLAM3's vocabulary from simulated rooms: built once, then read from the cache."""
from __future__ import annotations

import pytest

from atsvo_ros.bench import peer_vocabulary


def test_vocabulary_is_built_from_simulated_rooms_then_cached(tmp_path, monkeypatch):
    monkeypatch.setattr(peer_vocabulary, "_VIEWS", (("trot", 0),))
    monkeypatch.setattr(peer_vocabulary, "_DURATION_S", 0.3)
    path = peer_vocabulary.vocabulary_file(tmp_path, progress=False)
    header, *nodes = path.read_text().split("\n")
    assert header == "10 4 0 0" and len(nodes) > 100  # 2 images of a textured room: hundreds of descriptors
    assert not list(path.parent.glob("*.tmp"))

    def no_rendering(*_args, **_kwargs):
        raise AssertionError("the cached vocabulary was rebuilt")

    monkeypatch.setattr(peer_vocabulary, "make_simulation", no_rendering)
    assert peer_vocabulary.vocabulary_file(tmp_path, progress=False) == path
    with pytest.raises(AssertionError, match="rebuilt"):
        peer_vocabulary.vocabulary_file(tmp_path / "elsewhere", progress=False)
