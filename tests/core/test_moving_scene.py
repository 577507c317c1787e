"""Objects that move and turn in a scene (paper 002, section 5.2's self-movement constraints):
a walk played in place follows a flow field, its heading turning at a bounded rate, travelling as
far as its feet push the ground back; exported as transforms over time."""

import functools
import json
import math
import os
import subprocess

import numpy as np
import pytest

import flockkit
from flockkit.errors import ValidationError
from flockkit.scene import Arrow, Features, FlowField, SelfMovement, stride_speed
from flockkit.scene.movement import RATES, Gaits

PERIOD, DT, STRIDE = 30, 1 / 30, 0.25
SPEED = 4 * STRIDE / (PERIOD * DT)  # the walker's feet move back 2 strides in half a period: 1 m/s
REGION = flockkit.Polygon(vertices=[[0, 0], [30, 0], [30, 30], [0, 30]])
EAST = FlowField(arrows=[Arrow(position=[15, 15], keyframes=[(0, [0.6, 0])])])
# a quarter turn over 2 s (45 degrees a second), the same everywhere (one arrow)
TURNING = FlowField(arrows=[Arrow(position=[15, 15], keyframes=[(0, [0.8, 0]), (3, [0.8, 0]), (5, [0, 0.8])])])


def walker_mesh(cycles: int = 2) -> flockkit.Motion:
    """An in-place walker facing +x: a body of 8 points 0.5 to 0.7 m up and two feet of 3 points
    each, half a period apart; a foot on the ground (z = 0) moves back at exactly SPEED."""
    frames = PERIOD * cycles
    phase = (np.arange(frames) % PERIOD) / PERIOD
    body = np.array([[x, y, z] for x in (-0.3, 0.3) for y in (-0.15, 0.15) for z in (0.5, 0.7)])
    bodies = np.broadcast_to(body, (frames, 8, 3)).copy()
    bodies[..., 2] += 0.01 * np.sin(4 * np.pi * phase)[:, None]
    feet = []
    for offset, side in ((0.0, -0.15), (0.5, 0.15)):
        p = (phase + offset) % 1.0
        stance = p < 0.5
        x = np.where(stance, STRIDE - 4 * STRIDE * p, -STRIDE + 4 * STRIDE * (p - 0.5))
        z = np.where(stance, 0.0, 0.1 * np.sin(2 * np.pi * (p - 0.5)))
        feet += [np.stack([x + dx, np.full(frames, side), z], axis=1) for dx in (-0.03, 0.0, 0.03)]
    return flockkit.Motion(positions=np.concatenate([bodies, np.stack(feet, axis=1)], axis=1), dt=DT)


@functools.cache
def walker():
    motion = walker_mesh()
    features = Features.from_stride(motion, forward=[1, 0])
    one = flockkit.Segmentation(labels=np.zeros(motion.n_agents, dtype=np.int64), n_parts=1)
    return flockkit.build_layers(motion, segmentation=one, features=features, seed=0)


@functools.cache
def walking(flow=EAST, count=3, duration=8.0, max_turn=math.pi / 2):
    scene = flockkit.Scene(templates=[walker()], region=REGION, counts=[count], duration=duration, constraints=[flow],
                           seed=1, headings="aligned", max_turn=max_turn)  # fmt: skip
    return scene, scene.synthesize()


def planted_slide(positions: np.ndarray) -> np.ndarray:
    """Horizontal steps (frames - 1, points) of points on the ground (z = 0) in both frames; NaN
    elsewhere."""
    low = (positions[:-1, :, 2] < 1e-9) & (positions[1:, :, 2] < 1e-9)
    steps = np.linalg.norm(np.diff(positions[..., :2], axis=0), axis=2)
    return np.where(low, steps, np.nan)


def test_ground_speed_is_how_fast_the_feet_push_back():
    motion = walker_mesh()
    assert stride_speed(motion, forward=[1, 0]) == pytest.approx(SPEED, rel=1e-9)
    assert stride_speed(motion, forward=[-1, 0]) == pytest.approx(-SPEED, rel=1e-9)
    features = Features.from_stride(motion, forward=[2, 0])
    assert features.moves and features.speed == pytest.approx(SPEED) and np.allclose(features.vectors, [1, 0, 0])
    with pytest.raises(ValidationError, match="do not move back"):
        Features.from_stride(motion, forward=[-1, 0])
    with pytest.raises(ValidationError, match="direction in the ground plane"):
        Features.from_stride(motion, forward=[0, 0, 1])
    assert not Features(vectors=[[1.0, 0.0]], dt=0.1).moves


def test_under_a_uniform_flow_an_object_walks_straight_at_the_speed_asked_and_its_feet_stay_put():
    _, animation = walking()
    paths = animation.paths
    assert paths.moving.all()
    asked = 0.6 * SPEED  # the flow's length 0.6 times the speed of an arrow of length 1
    np.testing.assert_allclose(paths.rates, 0.6, atol=1e-12)  # the one gait, slowed to the speed asked
    np.testing.assert_allclose(np.cos(paths.headings), 1.0, atol=1e-12)  # facing east throughout
    steps = np.diff(paths.positions, axis=1)
    np.testing.assert_allclose(steps[..., 0], asked * DT, rtol=1e-9)
    np.testing.assert_allclose(steps[..., 1], 0.0, atol=1e-12)
    for i in range(animation.placement.n_objects):  # an independent check: a foot on the ground does not move
        slide = planted_slide(animation.motions[i].positions)
        assert np.isfinite(slide).sum() > 100 and np.nanmax(slide) < 1e-9


def test_a_fixed_arrow_walker_turns_a_quarter_with_the_flow_at_a_bounded_rate():
    scene, animation = walking(TURNING)
    paths = animation.paths
    targets = np.stack([scene._world(paths.positions[:, t], [t * DT], range(3))[:, 0] for t in range(scene.n_frames)])
    wanted = np.arctan2(targets[..., 1], targets[..., 0]).T  # (objects, frames): the walker faces +x
    error = np.abs((paths.headings - wanted + np.pi) % (2 * np.pi) - np.pi)
    flow_rate = math.radians(45)  # the flow turns 45 degrees a second, the walker can turn 90
    assert error.max() <= flow_rate * DT + 1e-9  # one frame behind at most
    np.testing.assert_allclose(np.sin(paths.headings[:, -1]), 1.0, atol=1e-12)  # facing north at the end
    assert np.abs(np.diff(paths.headings, axis=1)).max() <= math.pi / 2 * DT + 1e-12

    slow = math.radians(20)  # slower than the flow: it lags, turning as fast as it may, then catches up
    _, lagging = walking(TURNING, max_turn=slow)
    turns = np.diff(lagging.paths.headings, axis=1)
    assert np.abs(turns).max() <= slow * DT + 1e-12
    assert np.isclose(turns, slow * DT, rtol=1e-9).sum(axis=1).min() >= 0.9 * (math.pi / 2) / (slow * DT)
    np.testing.assert_allclose(np.sin(lagging.paths.headings[:, -1]), 1.0, atol=1e-12)


def test_positions_integrate_the_velocity_the_clip_carries():
    """Each frame's step from an evaluation written from the definition: rate x the clip's ground
    speed x the arrow played (the walker's is +x, length 1), turned by the frame's heading."""
    _, animation = walking(TURNING)
    paths = animation.paths
    rate = np.diff(paths.clocks, axis=1)
    heading = paths.headings[:, :-1]
    expected = (rate * SPEED * DT)[..., None] * np.stack([np.cos(heading), np.sin(heading)], axis=2)
    np.testing.assert_allclose(np.diff(paths.positions, axis=1), expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(rate, 0.8, atol=1e-12)
    reach = np.linalg.norm(walker_mesh().positions[..., :2], axis=2).max()  # the farthest point from the center
    for i in range(animation.placement.n_objects):  # a planted foot moves only as the turn swings it
        slide = planted_slide(animation.motions[i].positions)
        turn = np.abs(np.diff(paths.headings[i]))[:, None]
        assert np.nanmax(slide - turn * reach) < 1e-9 and np.nanmax(slide[turn[:, 0] < 1e-12]) < 1e-9


def test_the_gait_and_rate_chosen_reach_the_speed_asked():
    gaits = Gaits(lengths=np.array([0.0, 0.5, 1.0]), arrows=np.eye(3)[[0, 0, 0]] * [[0], [0.5], [1.0]], forward=0.0,
                  speed=2.0)  # fmt: skip
    index, rate = gaits.choose(np.array([0.5, 1.0, 0.7, 0.9, 3.0, 0.3, 0.02]))
    assert index.tolist() == [1, 2, 1, 2, 2, 1, 0]
    np.testing.assert_allclose(rate, [1.0, 1.0, 1.4, 0.9, RATES[1], 0.6, 1.0])
    # within the rates, the gait x rate is the length asked: the speed the feet carry is the speed asked
    reached = gaits.lengths[index] * rate
    np.testing.assert_allclose(reached[:4], [0.5, 1.0, 0.7, 0.9])


def test_a_self_movement_arrow_steers_its_object_and_the_others_follow_the_flow():
    arrow = SelfMovement(object=0, keyframes=[(0, [0, 1.0]), (4, [0, 0.5])])
    scene = flockkit.Scene(templates=[walker()], region=REGION, counts=[2], duration=4, constraints=[EAST, arrow],
                           seed=2, headings="random")  # fmt: skip
    paths = scene.synthesize().paths
    assert np.sin(paths.headings[0, -1]) == pytest.approx(1.0) and np.cos(paths.headings[1, -1]) == pytest.approx(1.0)
    assert paths.rates[0, 0] == pytest.approx(1.0) and paths.rates[0, -2] == pytest.approx(0.5, abs=0.01)


def test_a_moving_scene_saves_loads_and_exports_transforms_upright(tmp_path):
    from pxr import Usd, UsdGeom

    _, animation = walking(TURNING)
    animation.save(tmp_path / "scene.npz")
    again = flockkit.SceneAnimation.load(tmp_path / "scene.npz")
    assert again == animation and again.paths == animation.paths
    np.testing.assert_array_equal(again.motions[1].positions, animation.motions[1].positions)
    animation.export(tmp_path / "scene.usda", fps=30)
    stage = Usd.Stage.Open(str(tmp_path / "scene.usda"))
    objects = list(stage.GetPseudoRoot().GetChild("Scene").GetChildren())
    for i, prim in enumerate(objects):
        for frame in (0, 100, 140, 239):
            when = Usd.TimeCode(frame)
            matrix = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(when)).T  # column vectors
            np.testing.assert_allclose(matrix[:3, 2], [0, 0, 1], atol=1e-6)  # upright: z stays up
            heading = animation.paths.headings[i, frame]
            np.testing.assert_allclose(matrix[:2, 0], [np.cos(heading), np.sin(heading)], atol=1e-6)
            np.testing.assert_allclose(matrix[:2, 3], animation.paths.positions[i, frame], atol=1e-5)
            local = np.array(UsdGeom.Points(prim).GetPointsAttr().Get(when))
            world = local @ matrix[:3, :3].T + matrix[:3, 3]
            np.testing.assert_allclose(world, animation.motions[i].positions[frame], atol=1e-5)
    start, end = (np.array(UsdGeom.Xformable(objects[0]).ComputeLocalToWorldTransform(Usd.TimeCode(t)))[3, :2]
                  for t in (0, 239))  # fmt: skip
    assert np.linalg.norm(end - start) > 4  # it walked


def test_a_scene_file_walks_its_templates_by_their_stride(tmp_path):
    bare = walker()
    arrows = Features(vectors=[[1.0, 0, 0]] * 60, dt=DT)  # forces: the file says they are a stride
    layers = flockkit.GraphLayers(source=bare.source, segmentation=bare.segmentation, graphs=bare.graphs,
                                  features=arrows)  # fmt: skip
    layers.save(tmp_path / "walker.npz")
    text = """duration = 4
region = [[0, 0], [30, 0], [30, 30], [0, 30]]
max_turn = 45
[[templates]]
layers = "walker.npz"
count = 2
speed = "stride"
[[arrows]]
position = [15, 15]
keyframes = [[0, [0.5, 0]]]
"""
    (tmp_path / "scene.toml").write_text(text)
    scene = flockkit.scene.read_scene(tmp_path / "scene.toml")
    assert scene.max_turn == pytest.approx(math.radians(45))
    assert scene.templates[0].features.speed == pytest.approx(SPEED)
    paths = scene.synthesize().paths
    step = 0.5 * SPEED * DT * np.cos(paths.headings[:, :-1])
    np.testing.assert_allclose(np.diff(paths.positions[..., 0], axis=1), step, rtol=1e-9, atol=1e-12)
    (tmp_path / "bad.toml").write_text(text.replace('"stride"', '"fast"'))
    with pytest.raises(ValidationError, match="speed: a number"):
        flockkit.scene.read_scene(tmp_path / "bad.toml")


def test_the_fox_walks_a_turning_flow_upright_at_true_size(shared_data):
    fox = flockkit.io.read_mesh_animation(shared_data / "fox-gltf" / "Fox.glb", clip="Walk")
    mesh = fox.to_flockkit_axes(meters_per_unit="cm")
    features = Features.from_stride(mesh.motion, forward=[0, -1])  # the Fox faces -y in flockkit's axes
    assert 0.8 < features.speed < 1.5  # m/s: a fox's walk
    layers = flockkit.build_layers(mesh, segmenter="ica-kmeans", seed=0, features=features)
    region = flockkit.Polygon(vertices=[[0, 0], [20, 0], [20, 20], [0, 20]])
    scene = flockkit.Scene(templates=[layers], region=region, counts=[2], duration=6, constraints=[TURNING], seed=1,
                           headings="aligned")  # fmt: skip
    animation = scene.synthesize()
    paths = animation.paths
    facing = paths.headings - math.pi / 2  # the Fox's forward is -y: its heading turned a quarter back
    np.testing.assert_allclose(np.cos(facing[:, 0]), 1.0, atol=1e-9)
    np.testing.assert_allclose(np.sin(facing[:, -1]), 1.0, atol=1e-9)  # east, then north
    np.testing.assert_allclose(np.linalg.norm(np.diff(paths.positions, axis=1), axis=2),
                               0.8 * features.speed / 30, rtol=1e-9)  # fmt: skip
    for motion in animation.motions:
        heights = motion.positions[..., 2]
        assert heights.min() > -0.05 and 0.7 < np.ptp(heights, axis=1).max() < 0.85


BLENDER_PYTHON = os.environ.get("FLOCKKIT_BPY_PYTHON")  # a Python with Blender's bpy module (pip install bpy)


@pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to import in Blender"
)
def test_blender_shows_moving_objects_where_flockkit_put_them(tmp_path):
    from .test_scene import BLENDER_SCENE

    bare = walker()  # Blender reads points without faces as a point cloud: give the walker a body and soles
    faces = [[0, 1, 3], [0, 3, 2], [4, 5, 7], [4, 7, 6], [0, 4, 6], [8, 9, 0], [11, 12, 1]]
    meshes = flockkit.GraphLayers(source=bare.source, segmentation=bare.segmentation, graphs=bare.graphs,
                                  features=bare.features, faces=faces)  # fmt: skip
    scene = flockkit.Scene(templates=[meshes], region=REGION, counts=[3], duration=8, constraints=[TURNING], seed=1,
                           headings="aligned")  # fmt: skip
    animation = scene.synthesize()
    assert animation.paths.moving.all()
    animation.export(tmp_path / "scene.usdc", fps=30)
    frames = (0, 120, 150, 239)
    done = subprocess.run([BLENDER_PYTHON, "-c", BLENDER_SCENE, str(tmp_path / "scene.usdc"), *map(str, frames)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    found = json.loads(done.stdout.split("RESULT", 1)[1])
    assert len(found["names"]) == 3
    for frame in frames:
        for i, vertices in enumerate(found["frames"][str(frame)]):
            np.testing.assert_allclose(vertices, animation.motions[i].positions[frame], atol=1e-4)
