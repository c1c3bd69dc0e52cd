"""The ORB vocabulary ORB-SLAM3 runs with here: trained on the simulator's rooms, never on a scored sequence.

ORB-SLAM3's own ``ORBvoc.txt`` (trained on Bovisa outdoor images, 10^6 words) is downloaded at run time by its
bindings, which this machine cannot. Its words index keypoints for matching and relocalisation; tracking from
frame to frame projects map points and matches without them. So a 10^4-word tree trained on images that are
none of the evaluated sequences stands in (:mod:`atsvo_ros.eval.orb_vocabulary`), built once and cached.
"""
from __future__ import annotations

import itertools
from pathlib import Path

from tqdm import tqdm

from atsvo_ros.eval.orb_vocabulary import orb_descriptors, train, write_text
from atsvo_ros.sim.sequence import SequenceSpec, make_simulation

#: (scenario, seed): the rooms the vocabulary sees; every ``_EVERY``-th frame of ``_DURATION_S`` each
_VIEWS = (("trot", 0), ("running", 1), ("bound", 2), ("pronk", 3), ("backflip", 4), ("trot", 5))
_DURATION_S = 3.0
_EVERY = 5
#: DBoW2 branching and depth: 10^4 words
_K, _LEVELS = 10, 4
_VERSION = 1


def vocabulary_file(cache: Path, progress: bool = True) -> Path:
    """The cached vocabulary (built on first use: about a minute of rendering and clustering)."""
    path = cache / "orbslam3" / f"orbvoc_sim_k{_K}_l{_LEVELS}_v{_VERSION}.txt"
    if path.is_file():
        return path
    images = []
    for scenario, seed in tqdm(_VIEWS, desc="ORB vocabulary: simulated rooms", disable=not progress, leave=False):
        sim = make_simulation(SequenceSpec(scenario=scenario, duration_s=_DURATION_S, seed=seed, width=640,
                                           height=480, depth="sharp", imu=False))
        images += [f.rgb for f in itertools.islice(sim.frames(), 0, None, _EVERY)]
    tree = train(orb_descriptors(images), _K, _LEVELS)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    write_text(tree, tmp)
    tmp.replace(path)
    return path
