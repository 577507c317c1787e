"""A long recording that happens to loop (its last frame steps on to its first) still has its
features followed: the windowed builder's looping graph keeps transitions in every stretch of
the recording (holds of each wind direction), whose costs are not rounding noise, so that the
annotated walk holds whichever direction the target asks for, as it does on the plain graph."""

import numpy as np
import pytest

import flockkit
from flockkit.testing import inputs

WINDS = [[0.8, 0.0], [0.0, 0.8], [-0.8, 0.0], [0.0, -0.8]]


@pytest.fixture(scope="module")
def layers():
    # steady flutters of whole frames: the 24 s wind cycle returns to its start, an exact repeat
    motion, labels, wind = inputs.plants(dt=1 / 30, seconds=24.0, points=100, rates=(1.5, 3.0))
    segmentation = flockkit.Segmentation(labels=labels, n_parts=2)
    return flockkit.build_layers(motion, segmentation=segmentation, features=wind, seed=1, transitions_per_minute=2000)


def within(layers, graph, walk, target) -> float:
    """The share of played frames whose arrow is within 0.2 of `target` (bench/scene.py's measure)."""
    frames = flockkit.graphs.played_frames(graph, walk)[0][:900]
    return float(np.mean(np.linalg.norm(layers.features.vectors[frames, :2] - target, axis=1) <= 0.2))


@pytest.mark.parametrize("part", [0, 1])
def test_every_wind_of_a_looping_recording_is_held(layers, part):
    graph = layers.graphs[part]
    assert graph.period == 720  # the whole recording loops
    for k, wind in enumerate(WINDS):
        strategy = flockkit.get("walk", "annotated", target=[(0.0, wind)], features=layers.features)
        walk = strategy.walk(graph, np.random.default_rng(k), 30.0)
        assert within(layers, graph, walk, wind) >= 0.9, (part, wind)


def test_transitions_leave_from_every_wind(layers):
    for graph in layers.graphs:
        sources = np.array([graph.nodes[t.source] for t in graph.transitions])
        assert set(sources // 180) == {0, 1, 2, 3}, np.bincount(sources // 180)
