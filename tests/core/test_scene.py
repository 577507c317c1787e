"""Scenes of many duplicates (paper 002, sections 5.1 and 6): placement, following arrows,
de-synchronised neighbours, continuity, files and bad input."""

import functools
import json
import os
import subprocess

import attrs
import numpy as np
import pytest

import flockkit
from flockkit.errors import ValidationError
from flockkit.scene import Arrow, FlowField, SelfMovement
from flockkit.testing import inputs

TOLERANCE = 0.2  # the documented tolerance of a followed arrow (docs/concepts.md, scenes)


@functools.cache
def plants():
    motion, labels, wind = inputs.plants()
    segmentation = flockkit.Segmentation(labels=labels, n_parts=2)
    return flockkit.build_layers(motion, segmentation=segmentation, features=wind, seed=1, transitions_per_minute=400)


MEADOW = flockkit.Polygon(vertices=[[0, 0], [40, 0], [46, 20], [20, 34], [-6, 20]])
TURNING = FlowField(arrows=[Arrow(position=[20, 15], keyframes=[(0, [0.8, 0]), (15, [0.8, 0]), (17, [0, 0.8])])])


@functools.cache
def turning_scene():
    scene = flockkit.Scene(
        templates=[plants()], region=MEADOW, counts=[24], duration=30, constraints=[TURNING], seed=4, headings="aligned"
    )
    return scene, scene.synthesize()


def test_300_objects_are_placed_without_overlapping_boxes():
    scene = flockkit.Scene(templates=[plants()], region=MEADOW, counts=[300], duration=1, seed=2, scale=(0.8, 1.2))
    placement = scene.place()
    animation = flockkit.SceneAnimation(
        templates=scene.templates, placement=placement, walks=[None] * 300, dt=0.1, n_frames=1
    )
    boxes = animation.bounding_boxes()
    overlap = np.all((boxes[:, None, 0] < boxes[None, :, 1]) & (boxes[None, :, 0] < boxes[:, None, 1]), axis=2)
    np.fill_diagonal(overlap, False)
    assert not overlap.any()
    assert np.all(MEADOW.contains(boxes.reshape(-1, 2)))
    assert np.ptp(placement.headings) > 5 and 0.8 <= placement.scales.min() <= placement.scales.max() <= 1.2
    assert scene.place() == placement  # the seed decides


@pytest.mark.parametrize("count", [3000, 40000])
def test_a_region_too_small_for_the_count_is_an_error_not_a_hang(count):
    scene = flockkit.Scene(templates=[plants()], region=MEADOW, counts=[count], duration=1, seed=0)
    with pytest.raises(ValidationError, match="cannot hold|cover at least"):
        scene.place()


def _played_world_features(animation, i):
    """(parts, frames, 3): the arrows object i's parts play, turned into the world."""
    template = animation.templates[animation.placement.templates[i]]
    frames = animation.source_frames()[i]
    local = np.zeros((*frames.shape, 3))
    local[..., :2] = template.features.vectors[frames][..., :2]
    c, s = np.cos(animation.placement.headings[i]), np.sin(animation.placement.headings[i])
    turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return local @ turn.T


def test_objects_follow_a_flow_field_that_turns_a_quarter():
    scene, animation = turning_scene()
    targets = scene.targets(animation.placement)
    shares = []
    for i in range(animation.placement.n_objects):
        error = np.linalg.norm(_played_world_features(animation, i) - targets[i][None], axis=2).max(axis=0)
        shares.append(np.mean(error <= TOLERANCE))
    assert min(shares) >= 0.9, shares


def test_subsequence_replacement_never_raises_e_and_mostly_lowers_it():
    scene, animation = turning_scene()
    targets = scene.targets(animation.placement)
    layers = plants()
    lower = 0
    for i in range(8):
        c, s = np.cos(animation.placement.headings[i]), np.sin(animation.placement.headings[i])
        local = targets[i] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        track = flockkit.Features(vectors=local[:, :3], dt=0.1)
        for k, graph in enumerate(layers.graphs):
            final = flockkit.get("walk", "annotated", target=track, features=layers.features)
            initial = flockkit.get("walk", "annotated", target=track, features=layers.features, budget=0)
            walks = [w.walk(graph, np.random.default_rng(10 * i + k), 30.0) for w in (initial, final)]
            e_initial, e_final = (final.energy(graph, w, 30.0)["E"] for w in walks)
            assert e_final <= e_initial + 1e-9
            lower += e_final < e_initial - 1e-9
    assert lower > 8, f"E lower on {lower} of 16 part walks"


def test_neighbours_are_out_of_step_after_the_optimization():
    from flockkit.scene.desync import largest_in_step, pairs_in_step
    from flockkit.scene.scene import _walk_object

    scene, animation = turning_scene()
    report = animation.report
    # the same objects walked each on its own, avoiding no one: what the rounds of walks avoid
    placement, targets = animation.placement, scene.targets(animation.placement)
    alone = [_walk_object(scene, i, placement, targets[i], 100 + i, None) for i in range(placement.n_objects)]
    frames, near = attrs.evolve(animation, walks=alone).source_frames(), animation.neighbours()
    print(f"neighbours in step: {largest_in_step(frames, near):.1%} of frames walked alone, "
          f"{report['in_step_before']:.1%} after the first walks, {report['in_step_after']:.1%} after")  # fmt: skip
    assert report["in_step_after"] == animation.in_step_share() <= 0.05
    assert report["in_step_after"] <= report["in_step_before"] and report["first_rounds"] > 1
    assert pairs_in_step(frames, near) > 0.0 == report["pairs_in_step_after"]  # there was something to do
    assert report["in_step_frames"] == 1


def test_in_step_counts_frames_one_apart_and_lone_objects_are_neighbours():
    from flockkit.scene import desync

    frames = np.array([[[0, 5, 9, 20]], [[1, 7, 9, -1]]])  # two objects, one part, four frames
    assert desync.in_step(frames[0], frames[[1]])[0] == 0.5  # 0 vs 1 and 9 vs 9; -1 plays nothing
    _, animation = turning_scene()
    far = attrs.evolve(animation.placement, positions=animation.placement.positions * 1000.0)
    neighbours = attrs.evolve(animation, placement=far).neighbours()
    assert all(len(near) >= min(desync.NEAREST, animation.placement.n_objects - 1) for near in neighbours)
    assert all(i in neighbours[j] for i, near in enumerate(neighbours) for j in near)  # each way


def test_no_object_jumps_more_than_its_source():
    _, animation = turning_scene()
    source = plants().source
    largest = np.linalg.norm(np.diff(source.positions, axis=0), axis=2).max()
    for i, motion in enumerate(animation.motions):
        step = np.linalg.norm(np.diff(motion.positions, axis=0), axis=2).max()
        assert step <= 1.5 * largest * animation.placement.scales[i]


def test_the_seed_decides_and_n_jobs_does_not():
    import attrs

    small = flockkit.Scene(templates=[plants()], region=MEADOW, counts=[4], duration=6, constraints=[], seed=9)
    one = small.synthesize()
    assert one == small.synthesize() == attrs.evolve(small, n_jobs=2).synthesize()
    assert one != attrs.evolve(small, seed=10).synthesize()


def test_a_scene_animation_saves_loads_and_exports_to_usd(tmp_path):
    from pxr import Usd, UsdGeom  # usd-core is a test dependency

    scene = flockkit.Scene(
        templates=[plants()], region=MEADOW, counts=[3], duration=20, constraints=[TURNING], seed=5, headings="aligned"
    )
    animation = scene.synthesize()
    animation.save(tmp_path / "scene.npz")
    again = flockkit.SceneAnimation.load(tmp_path / "scene.npz")
    assert again == animation
    np.testing.assert_array_equal(again.source_frames(), animation.source_frames())
    animation.export(tmp_path / "scene.usda", fps=10)
    stage = Usd.Stage.Open(str(tmp_path / "scene.usda"))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == 10
    objects = list(stage.GetPseudoRoot().GetChild("Scene").GetChildren())
    assert len(objects) == 3
    points = UsdGeom.Points(objects[1]).GetPointsAttr().Get(Usd.TimeCode(7))
    np.testing.assert_allclose(np.array(points), animation.motions[1].positions[7], atol=1e-5)


def test_bad_scenes_get_named_errors():
    with pytest.raises(ValidationError, match="zero length"):
        Arrow(position=[0, 0], keyframes=[(0, [0, 0])])
    with pytest.raises(ValidationError, match="must increase"):
        Arrow(position=[0, 0], keyframes=[(2, [1, 0]), (1, [0, 1])])
    with pytest.raises(ValidationError, match="0..5 s"):
        flockkit.Scene(templates=[plants()], region=MEADOW, counts=[2], duration=5, constraints=[TURNING])
    bare = flockkit.GraphLayers(source=plants().source, segmentation=plants().segmentation, graphs=plants().graphs)
    with pytest.raises(ValidationError, match="no features"):
        flockkit.Scene(templates=[bare], region=MEADOW, counts=[2], duration=20, constraints=[TURNING])
    with pytest.raises(ValidationError, match="simple polygon"):
        flockkit.Polygon(vertices=[[0, 0], [1, 1], [1, 0], [0, 1]])
    with pytest.raises(ValidationError, match="counts"):
        flockkit.Scene(templates=[plants()], region=MEADOW, counts=[0], duration=5)
    upward = FlowField(arrows=[Arrow(position=[0, 0, 0], keyframes=[(0, [0, 0, 1.0])])])
    scene = flockkit.Scene(templates=[plants()], region=MEADOW, counts=[1], duration=5, constraints=[upward])
    with pytest.raises(ValidationError, match="closest arrow the graph plays"):
        scene.synthesize()
    with pytest.raises(ValidationError, match="SelfMovement.object"):
        flockkit.Scene(templates=[plants()], region=MEADOW, counts=[1], duration=5,
                       constraints=[SelfMovement(object=3, keyframes=[(0, [1, 0])])])  # fmt: skip


BLENDER_PYTHON = os.environ.get("FLOCKKIT_BPY_PYTHON")  # a Python with Blender's bpy module (pip install bpy)
BLENDER_SCENE = """
import json, sys, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=sys.argv[1], relative_path=False)
scene, found = bpy.context.scene, {}
objects = sorted((o for o in bpy.data.objects if o.name.startswith("Object")), key=lambda o: o.name)
for frame in map(int, sys.argv[2:]):
    scene.frame_set(frame)
    graph = bpy.context.evaluated_depsgraph_get()
    found[frame] = []
    for o in objects:
        evaluated = o.evaluated_get(graph)
        found[frame].append([list(evaluated.matrix_world @ v.co) for v in evaluated.data.vertices])
print("RESULT" + json.dumps({"fps": scene.render.fps / scene.render.fps_base, "names": [o.name for o in objects],
                             "frames": found}))
"""


@pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to import in Blender"
)
def test_blender_imports_a_scene_of_meshes_where_flockkit_put_them(tmp_path):
    layers = plants()
    ribbon = [[k, k + 1, k + 8] for k in range(7)] + [[k + 1, k + 9, k + 8] for k in range(7)]  # the stalks joined
    meshes = flockkit.GraphLayers(source=layers.source, segmentation=layers.segmentation, graphs=layers.graphs,
                                  faces=ribbon, features=layers.features)  # fmt: skip
    scene = flockkit.Scene(templates=[meshes], region=MEADOW, counts=[3], duration=4, seed=5, headings="aligned")
    animation = scene.synthesize()
    animation.export(tmp_path / "scene.usdc")  # the default 24 fps time line: Blender's own
    seconds = (0.0, 1.0, 2.5)
    frames = [round(24 * t) for t in seconds]
    done = subprocess.run([BLENDER_PYTHON, "-c", BLENDER_SCENE, str(tmp_path / "scene.usdc"), *map(str, frames)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    found = json.loads(done.stdout.split("RESULT", 1)[1])
    assert found["fps"] == 24 and len(found["names"]) == 3
    for t, frame in zip(seconds, frames):
        for i, vertices in enumerate(found["frames"][str(frame)]):
            np.testing.assert_allclose(vertices, animation.motions[i].positions[round(t / animation.dt)], atol=1e-4)


def test_the_annotated_walk_walks_every_part_of_layers_after_one_target():
    layers = plants()
    target = [(0.0, [0.0, 0.8]), (10.0, [0.0, 0.8]), (12.0, [-0.8, 0.0])]
    walk = flockkit.walk(layers, strategy="annotated", duration=20.0, seed=3, target=target, features=layers.features)
    assert isinstance(walk, flockkit.LayeredWalk) and len(walk.walks) == 2
    assert walk == flockkit.walk(layers, strategy="annotated", duration=20.0, seed=3, target=target,
                                 features=layers.features)  # fmt: skip
    wanted = flockkit.scene.interpolate_arrows(np.array([0.0, 10.0, 12.0]), np.array([v for _, v in target]),
                                                  np.arange(200) * 0.1)  # fmt: skip
    for graph, part in zip(layers.graphs, walk.walks):
        played = layers.features.vectors[flockkit.graphs.played_frames(graph, part)[0][:200]]
        assert np.mean(np.linalg.norm(played - wanted, axis=1) <= TOLERANCE) >= 0.9
    assert flockkit.synthesize(layers, walk).n_frames >= 200


def _turning_body(points, seconds=6.0, dt=0.1, rate=0.8, travel=1.5):
    t = np.arange(round(seconds / dt) + 1)[:, None] * dt
    c, s = np.cos(rate * t), np.sin(rate * t)
    x, y = points[:, 0], points[:, 1]
    return np.stack([c * x - s * y + travel * t, s * x + c * y], axis=2)


def test_merge_rigid_parts_joins_the_pieces_of_a_turning_body_and_keeps_independent_ones():
    rng = np.random.default_rng(5)
    body, other = rng.uniform(-1, 1, (12, 2)), rng.uniform(-1, 1, (8, 2)) + 4
    positions = np.concatenate([_turning_body(body), _turning_body(other, rate=-0.5, travel=0.2)], axis=1)
    motion = flockkit.Motion(positions=positions, dt=0.1)
    cut = np.array([0, 1, 2] * 4 + [3, 4] * 4)  # each body cut into pieces
    merged = flockkit.scene.merge_rigid_parts(motion, cut)
    assert list(merged) == [0] * 12 + [1] * 8
    bent = motion.positions.copy()
    bent[:, 0] += np.linspace(0, 0.5, motion.n_frames)[:, None]  # one point slides: no longer rigid
    found = flockkit.scene.merge_rigid_parts(flockkit.Motion(positions=bent, dt=0.1), cut)
    assert len(np.unique(found[:12])) > 1 and len(np.unique(found[12:])) == 1
    with pytest.raises(ValidationError, match="one entry per point"):
        flockkit.scene.merge_rigid_parts(motion, cut[:-1])
