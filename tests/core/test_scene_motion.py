"""A scene's object motions (SceneAnimation.motion, local_motion) against their definition,
evaluated plainly with numpy: the object's walk played (each part's frames through
flockkit.synthesize, put on the part's points), cut to the scene's frames, about the template's
center (its mean center of mass, z = 0 in 3D), scaled, turned about +z by the heading and moved
to the object's position; for an object that moves, the played frames read at its clock (linear
between frames, the last held) and each frame turned and moved by its own heading and position.
On drawn graphs and layers (2D and 3D, walks that turn and trade points, start poses), on the
kit's plants, and on the Fox (y up, converted; faces, welds and seams)."""

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import flockkit
from flockkit.scene import Paths, Placement
from flockkit.testing import inputs, strategies

from ..conftest import SHARED_DATA, require_folder
from .test_layers_synthesis import parts_played


def played_plainly(template, walk) -> np.ndarray:
    """Every frame `walk` plays: each part's own synthesis put on its points (a template without
    faces), cut to the shortest part; a single graph's synthesis."""
    if isinstance(template, flockkit.MotionGraph):
        return flockkit.synthesize(template, walk).positions
    return parts_played(template, walk)


def center_of(template) -> np.ndarray:
    source = template.motion if isinstance(template, flockkit.MotionGraph) else template.source
    center = source.positions.mean(axis=(0, 1))
    if source.dims == 3:
        center[2] = 0.0
    return center


def placed_plainly(frames, center, scale, headings, positions) -> np.ndarray:
    """frames (F, N, D) about `center`, scaled, frame t turned by headings[t] about +z and moved
    to positions[t] (F, 2)."""
    local = (frames - center) * scale
    c, s = np.cos(headings)[:, None], np.sin(headings)[:, None]
    out = local.copy()
    out[..., 0] = c * local[..., 0] - s * local[..., 1] + positions[:, None, 0]
    out[..., 1] = s * local[..., 0] + c * local[..., 1] + positions[:, None, 1]
    return out


def read_at(frames, clock) -> np.ndarray:
    """frames (S, N, D) at fractional frames `clock`: linear between the two around each, the
    first and last held outside."""
    out = np.empty((len(clock), *frames.shape[1:]))
    last = len(frames) - 1
    for t, c in enumerate(clock):
        c = min(max(c, 0.0), last)
        below = min(int(c), max(last - 1, 0))
        u = c - below
        out[t] = frames[below] if u == 0 else (1 - u) * frames[below] + u * frames[min(below + 1, last)]
    return out


def expected_motions(animation, i, played):
    """(world, local) of object i from its played frames, by the definitions above."""
    n, scale = animation.n_frames, animation.placement.scales[i]
    center = center_of(animation.templates[animation.placement.templates[i]])
    if animation.paths is not None and animation.paths.moving[i]:
        at = read_at(played, animation.paths.clocks[i])
        world = placed_plainly(at, center, scale, animation.paths.headings[i], animation.paths.positions[i])
    else:
        at = played[:n]
        heading = np.full(len(at), animation.placement.headings[i])
        where = np.repeat(animation.placement.positions[i][None], len(at), axis=0)
        world = placed_plainly(at, center, scale, heading, where)
    local = placed_plainly(at, center, scale, np.zeros(len(at)), np.zeros((len(at), 2)))
    return world, local


def check_object(animation, i, played, size):
    world, local = expected_motions(animation, i, played)
    got, own = animation.motion(i), animation.local_motion(i)
    assert got.positions.shape == world.shape and got.dt == animation.dt
    tolerance = 1e-12 * max(size, 1.0)
    np.testing.assert_allclose(got.positions, world, rtol=0, atol=tolerance)
    np.testing.assert_allclose(own.positions, local, rtol=0, atol=tolerance)
    np.testing.assert_array_equal(animation.motions[i].positions, got.positions)


@st.composite
def templates_and_walks(draw):
    """A drawn MotionGraph (2D or 3D) with a walk, or layers of 1 to 3 such graphs over dealt-out
    points with a walk per part (walks that turn and trade points, start poses)."""
    if draw(st.booleans()):
        graph = draw(strategies.motion_graphs(max_agents=4))
        return graph, draw(strategies.walks(graph, max_edges=8))
    return draw(strategies.layered_walks())


angles = st.floats(-10.0, 10.0, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(templates_and_walks(), st.data())
def test_motion_and_local_motion_are_the_walk_played_scaled_turned_and_moved(drawn, data):
    template, walk = drawn
    played = played_plainly(template, walk)
    n_frames = data.draw(st.integers(1, len(played)), label="n_frames")
    placement = Placement(positions=[data.draw(st.tuples(angles, angles)) for _ in range(2)],
                          headings=data.draw(st.lists(angles, min_size=2, max_size=2)),
                          scales=data.draw(st.lists(st.floats(0.1, 3.0), min_size=2, max_size=2)),
                          templates=[0, 0])  # fmt: skip
    # object 1 moves: a clock at drawn rates (running past the played frames: the last is held),
    # a heading and a position per frame
    rates = data.draw(st.lists(st.floats(0.25, 2.0), min_size=n_frames, max_size=n_frames), label="rates")
    clock = np.concatenate([[0.0], np.cumsum(rates[:-1])])
    headings = np.cumsum(data.draw(st.lists(st.floats(-0.2, 0.2), min_size=n_frames, max_size=n_frames)))
    paths = Paths(positions=np.stack([np.repeat(placement.positions[:1], n_frames, 0),
                                      placement.positions[1] + np.cumsum(np.ones((n_frames, 2)) * 0.1, axis=0)]),
                  headings=np.stack([np.full(n_frames, placement.headings[0]), headings]),
                  clocks=np.stack([np.arange(n_frames, dtype=float), clock]), moving=[False, True])  # fmt: skip
    size = float(np.abs(played).max()) * 3.0 + 10.0
    for moving in (None, paths):
        animation = flockkit.SceneAnimation(templates=[template], placement=placement, walks=[walk, walk], dt=0.1,
                                            n_frames=n_frames, paths=moving)  # fmt: skip
        for i in (0, 1):
            check_object(animation, i, played, size)


def test_plants_standing_and_walking_in_a_synthesized_scene_match_the_definition():
    motion, labels, wind = inputs.plants()
    layers = flockkit.build_layers(motion, segmentation=flockkit.Segmentation(labels=labels, n_parts=2),
                                   features=wind, seed=1, transitions_per_minute=400)  # fmt: skip
    region = flockkit.Polygon(vertices=[[0, 0], [20, 0], [20, 20], [0, 20]])
    scene = flockkit.Scene(templates=[layers], region=region, counts=[4], duration=8.0, seed=2, headings="random")
    animation = scene.synthesize()
    assert animation.paths is None
    for i in range(4):
        check_object(animation, i, played_plainly(layers, animation.walks[i]), 20.0)


@functools.cache
def fox_layers():
    path = require_folder(SHARED_DATA / "fox-gltf") / "Fox.glb"
    fox = flockkit.io.read_mesh_animation(path, clip="Walk", fps=30.0).to_flockkit_axes(meters_per_unit="cm")
    return flockkit.build_layers(fox, seed=0)


def test_the_fox_y_up_converted_with_seams_placed_still_and_moving_matches_the_definition():
    layers = fox_layers()
    assert layers.faces is not None and layers.welds is not None and layers.n_parts > 1
    walk = flockkit.walk(layers, duration=16.0, seed=3)
    # a mesh with faces is smoothed at its seams: its played frames are synthesize's (checked
    # part by part and against a plain evaluation in bench/synthesis_assets.py)
    played = flockkit.synthesize(layers, walk).positions
    n = 300
    placement = Placement(positions=[[3.0, -2.0], [-5.0, 7.5]], headings=[2.2, -0.7], scales=[1.3, 0.8],
                          templates=[0, 0])  # fmt: skip
    clock = np.cumsum(np.full(n, 1.37)) - 1.37
    paths = Paths(positions=np.stack([np.repeat(placement.positions[:1], n, 0), np.linspace([-5, 7.5], [4, 1], n)]),
                  headings=np.stack([np.full(n, 2.2), np.linspace(-0.7, 3.0, n)]),
                  clocks=np.stack([np.arange(n, dtype=float), clock]), moving=[False, True])  # fmt: skip
    assert clock.max() < len(played) - 1 and len(played) > n
    for moving in (None, paths):
        animation = flockkit.SceneAnimation(templates=[layers], placement=placement, walks=[walk, walk], dt=1 / 30,
                                            n_frames=n, paths=moving)  # fmt: skip
        for i in (0, 1):
            check_object(animation, i, played, 10.0)
        # the feet stand on z = 0 at the scene's scale: the center's height is 0
        assert animation.motion(0).positions[..., 2].min() == pytest.approx(1.3 * played[:n, :, 2].min(), abs=1e-12)
