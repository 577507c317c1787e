"""Layered synthesis (flockkit.scene.synthesize_layers) of motions without faces, in 2D and 3D:
every part plays exactly what flockkit.synthesize plays for its own walk, bit for bit, whether
its walk leaves it in place (read from the source, blended where the walk blends) or moves it
(a start pose, transitions that turn or trade points: read from its placed frames), with the
parts' points in any order."""

import numpy as np
import pytest
from hypothesis import given, settings

import flockkit
from flockkit.testing import strategies


def waving(dims, points, frames=80, seed=0):
    """Points whose coordinates wave at their own rates: a motion with no faces."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames)[:, None, None] / 30
    rate, phase = rng.uniform(0.5, 2, (1, points, dims)), rng.uniform(0, 6, (1, points, dims))
    base = rng.normal(size=(1, points, dims))
    return flockkit.Motion(positions=base + 0.2 * np.sin(2 * np.pi * rate * t + phase), dt=1 / 30)


def parts_played(layers, walk):
    own = [flockkit.synthesize(graph, w).positions for graph, w in zip(layers.graphs, walk.walks)]
    frames = min(len(p) for p in own)
    expected = np.empty((frames, layers.source.n_agents, layers.source.dims))
    for points, played in zip(layers.segmentation.parts(), own):
        expected[:, points] = played[:frames]
    return expected


@settings(max_examples=30, deadline=None)
@given(strategies.layered_walks())
def test_every_part_plays_its_own_walk_bit_for_bit(drawn):
    layers, walk = drawn
    played = flockkit.synthesize(layers, walk)
    np.testing.assert_array_equal(played.positions, parts_played(layers, walk))
    assert played.dt == layers.source.dt


@pytest.mark.parametrize("dims", [2, 3])
def test_blends_are_played(dims):
    """A walk long enough to take transitions blends: some frames are neither source frame."""
    motion = waving(dims, 10, frames=120, seed=3)
    parts = flockkit.Segmentation(labels=np.arange(10) % 2, n_parts=2)
    layers = flockkit.build_layers(motion, segmentation=parts, seed=0)
    walk = flockkit.walk(layers, duration=20, seed=4)
    weights = [flockkit.graphs.blended_frames(g, w)[2] for g, w in zip(layers.graphs, walk.walks)]
    assert any(np.any(w < 1) for w in weights)
    np.testing.assert_array_equal(flockkit.synthesize(layers, walk).positions, parts_played(layers, walk))
