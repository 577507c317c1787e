"""Up axes and units: every reader reports what its file says (or what its caller states), one
conversion takes an asset to flockkit's axes (z up, metres), and scenes and crowds exported to
USD stand upright at their true size, heights along z and feet on the ground."""

import json
import math
import os
import subprocess
import warnings

import numpy as np
import pytest

import flockkit
import flockkit.io as fio
from flockkit import _npzfile
from flockkit.crowd import Crowd, Stream, StreamPool
from flockkit.crowd.drive import Driver, Gait, StateMachine, character_frame
from flockkit.crowd.record import record
from flockkit.errors import FileFormatError, FlockkitWarning, ValidationError
from flockkit.mesh import UNITS, AnimatedMesh, conversion_matrix
from flockkit.testing import inputs

GLTF_ASSETS = {
    "fox-gltf/Fox.glb": "cm",  # the Fox is modelled in centimetres (its README); its file says metres
    "robot-expressive-gltf/RobotExpressive.glb": "m",
    "morph-stress-test-gltf/MorphStressTest.gltf": "m",
}
# m: the Fox stands 74.5 to 79.9 units tall along y over its Survey clip's frames, in centimetres
FOX_HEIGHTS = (0.74, 0.80)
FOX_FEET = ["b_LeftFoot02_018", "b_RightFoot02_022"]


def _fox(shared_data):
    return shared_data / "fox-gltf" / "Fox.glb"


def _quiet(function, *args, **kwargs):
    """`function`'s result with the size hints it warns of kept out of the test's output."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FlockkitWarning)
        return function(*args, **kwargs)


# --- readers report the file's axes -------------------------------------------------------------


@pytest.mark.parametrize("asset", sorted(GLTF_ASSETS))
def test_gltf_readers_report_y_up_metres_as_the_specification_says(shared_data, asset):
    mesh = fio.read_mesh_animation(shared_data / asset, fps=5)
    assert (mesh.up_axis, mesh.meters_per_unit) == ("y", 1.0)
    if "Morph" not in asset:  # the only one without a skin
        skeletons = {id(c.skeleton): c.skeleton for c in fio.read_clips(shared_data / asset).values()}
        assert {(s.up_axis, s.meters_per_unit) for s in skeletons.values()} == {("y", 1.0)}


def test_bvh_is_y_up_with_no_unit_until_one_is_stated(shared_data):
    path = shared_data / "cmu-mocap-bvh" / "01_01.bvh"
    (clip,) = fio.read_clips(path).values()
    assert (clip.skeleton.up_axis, clip.skeleton.meters_per_unit) == ("y", None)
    (stated,) = fio.read_clips(path, meters_per_unit="in").values()
    assert stated.skeleton.meters_per_unit == 0.0254
    (turned,) = fio.read_clips(path, up_axis="Z", meters_per_unit=0.01).values()
    assert (turned.skeleton.up_axis, turned.skeleton.meters_per_unit) == ("z", 0.01)


def test_stated_axes_replace_what_a_gltf_file_says(shared_data):
    mesh = fio.read_mesh_animation(_fox(shared_data), fps=5, meters_per_unit="cm")
    assert (mesh.up_axis, mesh.meters_per_unit) == ("y", 0.01)
    clips = fio.read_clips(_fox(shared_data), meters_per_unit=0.01)
    assert clips["Walk"].skeleton.meters_per_unit == 0.01


# generated assets: a pole 1.8 m tall and 0.3 m across, its foot on the ground, in several conventions


def _pole(up: str, unit: str, frames: int = 3) -> np.ndarray:
    """(frames, 8, 3): a box 1.8 m tall along `up` and 0.3 m across, from the ground up, in
    `unit`s, swaying a little along the first horizontal axis."""
    corners = np.array([[x, y, z] for x in (-0.15, 0.15) for y in (-0.15, 0.15) for z in (0.0, 1.8)])
    height = {"x": 0, "y": 1, "z": 2}[up]
    corners = corners[:, [2, 1, 0] if height == 0 else [0, 2, 1] if height == 1 else [0, 1, 2]]
    sway = np.zeros((frames, 1, 3))
    sway[:, 0, (height + 1) % 3] = np.linspace(0, 0.05, frames)
    return (corners[None] + sway * (corners[None, :, height : height + 1] / 1.8)) / UNITS[unit]


CUBE_FACES = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]


def _obj_sequence(folder, positions):
    folder.mkdir()
    for k, frame in enumerate(positions):
        lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in frame]
        lines += ["f " + " ".join(str(i + 1) for i in face) for face in CUBE_FACES]
        (folder / f"pole{k}.obj").write_text("\n".join(lines) + "\n")
    return folder


def _usd_stage(path, positions, *, up=None, meters_per_unit=None):
    from pxr import Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    if up is not None:
        UsdGeom.SetStageUpAxis(stage, up.upper())
    if meters_per_unit is not None:
        UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.SetTimeCodesPerSecond(10)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(len(positions) - 1)
    mesh = UsdGeom.Mesh.Define(stage, "/Pole")
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([4] * 6))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([i for face in CUBE_FACES for i in face]))
    points = mesh.CreatePointsAttr()
    for k, frame in enumerate(positions):
        points.Set(Vt.Vec3fArray.FromNumpy(frame.astype(np.float32)), Usd.TimeCode(k))
    stage.GetRootLayer().Save()
    return path


def _assert_upright_pole(mesh):
    positions = mesh.motion.positions
    assert (mesh.up_axis, mesh.meters_per_unit) == ("z", 1.0)
    np.testing.assert_allclose(np.ptp(positions[..., 2], axis=1), 1.8, atol=1e-5)  # height along z
    np.testing.assert_allclose(np.ptp(positions[0, :, :2], axis=0), [0.3, 0.3], atol=1e-5)  # a footprint in x, y
    np.testing.assert_allclose(positions[..., 2].min(axis=1), 0.0, atol=1e-6)  # its foot on the ground


@pytest.mark.parametrize(("up", "unit"), [("y", "cm"), ("z", "m"), ("x", "mm"), ("y", "in")])
def test_an_obj_sequence_takes_the_axes_its_caller_states(tmp_path, up, unit):
    folder = _obj_sequence(tmp_path / "pole", _pole(up, unit))
    found = fio.read_mesh_animation(folder, fps=10)
    assert (found.up_axis, found.meters_per_unit) == ("y", None)  # the convention, and no unit
    with pytest.raises(ValidationError, match="its unit is not known .* meters_per_unit="):
        found.to_flockkit_axes()
    stated = fio.read_mesh_animation(folder, fps=10, up_axis=up, meters_per_unit=unit)
    assert (stated.up_axis, stated.meters_per_unit) == (up, UNITS[unit])
    _assert_upright_pole(stated.to_flockkit_axes())
    _assert_upright_pole(found.to_flockkit_axes(up_axis=up, meters_per_unit=UNITS[unit]))


@pytest.mark.parametrize(("up", "unit"), [("y", "cm"), ("z", "m"), ("z", "mm"), (None, None)])
def test_a_usd_stage_reports_its_up_axis_and_meters_per_unit(tmp_path, up, unit):
    pytest.importorskip("pxr", reason="reading USD needs usd-core (pip install 'flockkit[usd]')")
    # a stage that says nothing is y up in centimetres by USD's fallbacks
    path = _usd_stage(tmp_path / "pole.usda", _pole(up or "y", unit or "cm"), up=up,
                      meters_per_unit=None if unit is None else UNITS[unit])  # fmt: skip
    mesh = fio.read_mesh_animation(path, fps=10)
    assert (mesh.up_axis, mesh.meters_per_unit) == (up or "y", UNITS[unit or "cm"])
    _assert_upright_pole(mesh.to_flockkit_axes())


def test_bad_axes_in_a_usd_stage_are_named(tmp_path):
    pytest.importorskip("pxr", reason="reading USD needs usd-core (pip install 'flockkit[usd]')")
    for k, (metadata, field) in enumerate([('upAxis = "X"', "upAxis"), ("metersPerUnit = -1", "metersPerUnit"),
                                           ("metersPerUnit = nan", "metersPerUnit"),
                                           ("metersPerUnit = 0", "metersPerUnit")]):  # fmt: skip
        path = tmp_path / f"bad{k}.usda"
        path.write_text(f'#usda 1.0\n(\n    {metadata}\n    startTimeCode = 0\n    endTimeCode = 0\n)\n'
                        'def Mesh "m" {\n    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]\n'
                        '    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0, 1, 2]\n}\n')  # fmt: skip
        with pytest.raises(FileFormatError, match=rf"{path.name}: {field} must be"):
            fio.read_mesh_animation(path)


def test_bad_axes_are_named_errors(tmp_path):
    motion = flockkit.Motion(positions=np.zeros((2, 3, 3)), dt=0.1)
    for kwargs, field in [({"up_axis": "w"}, "AnimatedMesh.up_axis"), ({"up_axis": 2}, "AnimatedMesh.up_axis"),
                          ({"meters_per_unit": -1}, "AnimatedMesh.meters_per_unit"),
                          ({"meters_per_unit": math.nan}, "AnimatedMesh.meters_per_unit"),
                          ({"meters_per_unit": "furlong"}, "AnimatedMesh.meters_per_unit"),
                          ({"meters_per_unit": True}, "AnimatedMesh.meters_per_unit")]:  # fmt: skip
        with pytest.raises(ValidationError, match=field):
            AnimatedMesh(motion=motion, faces=[[0, 1, 2]], **kwargs)
    with pytest.raises(ValidationError, match="Skeleton.meters_per_unit"):
        flockkit.Skeleton(names=["a"], parents=[-1], meters_per_unit=0)
    with pytest.raises(ValidationError, match="read_mesh_animation: meters_per_unit"):
        fio.read_mesh_animation(tmp_path / "nothing.glb", meters_per_unit=0)
    with pytest.raises(ValidationError, match="read_clips: up_axis"):
        fio.read_clips(tmp_path / "nothing.bvh", up_axis="down")


# --- the conversion -----------------------------------------------------------------------------


def test_the_conversion_is_a_quarter_turn_onto_z_times_the_unit():
    point = np.array([1.0, 2.0, 3.0])
    np.testing.assert_array_equal(conversion_matrix("y", 1) @ point, [1.0, -3.0, 2.0])  # Blender's y-up turn
    np.testing.assert_array_equal(conversion_matrix("x", 1) @ point, [-3.0, 2.0, 1.0])
    np.testing.assert_array_equal(conversion_matrix("z", "cm") @ point, point * 0.01)
    for up in "xyz":
        turn = conversion_matrix(up, 1)
        assert np.allclose(turn @ turn.T, np.eye(3)) and np.isclose(np.linalg.det(turn), 1.0)  # right-handed kept
        assert np.allclose(turn @ np.eye(3)["xyz".index(up)], [0, 0, 1])
    # the crowd's character frame is the same turn, then a turn about +z to face +x
    for up, forward in [("y", "z"), ("z", "y"), ("x", "z")]:
        frame = character_frame(up, forward)
        assert np.allclose(frame @ np.eye(3)["xyz".index(up)], [0, 0, 1])
        assert np.allclose(frame @ np.eye(3)["xyz".index(forward)], [1, 0, 0])


def test_a_gltf_export_read_back_and_converted_lands_where_it_was(tmp_path):
    """glTF's writer turns flockkit's axes into glTF's; reading the file and converting turns them
    back: the round trip ends where it started."""
    motion = flockkit.simulate(n_agents=5, steps=20, seed=1, dims=3)
    flockkit.io.export(motion, tmp_path / "flock.glb")
    mesh = fio.read_mesh_animation(tmp_path / "flock.glb", fps=1 / motion.dt)
    back = mesh.to_flockkit_axes().motion.positions.reshape(mesh.motion.n_frames, motion.n_agents, 4, 3)
    # each agent's arrow head: four corners about its position, at most its half length away
    gap = np.linalg.norm(back.mean(axis=2) - motion.positions[: len(back)], axis=2)
    assert gap.max() < 0.2


@pytest.mark.parametrize("asset", sorted(GLTF_ASSETS))
def test_every_shared_asset_stands_upright_at_its_true_size_once_converted(shared_data, asset):
    mesh = fio.read_mesh_animation(shared_data / asset, fps=5)
    unit = UNITS[GLTF_ASSETS[asset]]
    converted = mesh.to_flockkit_axes(meters_per_unit=unit)
    file, found = mesh.motion.positions, converted.motion.positions
    np.testing.assert_allclose(found[..., 2], file[..., 1] * unit, atol=1e-9)  # height: the file's up axis
    np.testing.assert_allclose(found[..., 1], -file[..., 2] * unit, atol=1e-9)  # glTF's +z forward: -y
    np.testing.assert_allclose(found[..., 0], file[..., 0] * unit, atol=1e-9)
    assert converted.name == mesh.name and np.array_equal(converted.faces, mesh.faces)
    height = np.ptp(found[..., 2])
    assert abs(found[..., 2].min()) <= 0.1 * height and height < 5.0  # its ground at z = 0, of a size


def test_the_fox_stands_80_cm_tall_and_a_size_no_fox_has_gets_a_hint(shared_data):
    mesh = fio.read_mesh_animation(_fox(shared_data), clip="Survey", fps=5)
    with pytest.warns(FlockkitWarning, match=r"175\.2 m at 1 m a unit.*cm \(0.01 m a unit\): 1.75 m"):
        as_metres = mesh.to_flockkit_axes()
    assert np.ptp(as_metres.motion.positions[..., 2]) > 79  # a hint, never a change
    with warnings.catch_warnings():
        warnings.simplefilter("error", FlockkitWarning)
        fox = mesh.to_flockkit_axes(meters_per_unit="cm")
    positions = fox.motion.positions
    heights = np.ptp(positions[..., 2], axis=1)
    assert FOX_HEIGHTS[0] < heights.min() and heights.max() < FOX_HEIGHTS[1]
    assert np.ptp(positions[..., :2], axis=1).max() < 1.6  # nose to tail on the ground
    assert positions[..., 2].min() == pytest.approx(0.0, abs=0.002)


def test_mesh_files_keep_their_axes_and_files_without_them_load_as_flockkits(tmp_path):
    motion = flockkit.Motion(positions=np.arange(18.0).reshape(2, 3, 3), dt=0.1)
    for up, unit in [("y", 0.01), ("z", None), ("x", 1.0)]:
        mesh = AnimatedMesh(motion=motion, faces=[[0, 1, 2]], name="m", up_axis=up, meters_per_unit=unit)
        mesh.save(tmp_path / "mesh.npz")
        again = AnimatedMesh.load(tmp_path / "mesh.npz")
        assert again == mesh and (again.up_axis, again.meters_per_unit) == (up, unit)
    # a file of the first format version has no axes: flockkit used it as z up, metres
    _npzfile.write(tmp_path / "old.npz", kind="mesh", version=1,
                   arrays={**motion._to_arrays(), "faces": np.array([[0, 1, 2]])},
                   metadata={"dt": 0.1, "name": "old"})  # fmt: skip
    old = AnimatedMesh.load(tmp_path / "old.npz")
    assert (old.up_axis, old.meters_per_unit) == ("z", 1.0) and old.motion == motion
    for field, value in [("up_axis", "sideways"), ("meters_per_unit", -2.0), ("meters_per_unit", "leagues")]:
        metadata = {"dt": 0.1, "name": "bad", "up_axis": "y", "meters_per_unit": 1.0, field: value}
        _npzfile.write(tmp_path / "bad.npz", kind="mesh", version=2,
                       arrays={**motion._to_arrays(), "faces": np.array([[0, 1, 2]])}, metadata=metadata)  # fmt: skip
        with pytest.raises(FileFormatError, match=rf"bad.npz: invalid animated mesh: .*{field}"):
            AnimatedMesh.load(tmp_path / "bad.npz")
    metadata = {"dt": 0.1, "name": "bad", "up_axis": "y"}  # a version 2 file must say both
    _npzfile.write(tmp_path / "bad.npz", kind="mesh", version=2,
                   arrays={**motion._to_arrays(), "faces": np.array([[0, 1, 2]])}, metadata=metadata)  # fmt: skip
    with pytest.raises(FileFormatError, match="bad.npz: invalid animated mesh: KeyError: 'meters_per_unit'"):
        AnimatedMesh.load(tmp_path / "bad.npz")


# --- scenes -------------------------------------------------------------------------------------


def _fox_scene(shared_data, *, unit="cm", count=4):
    """A scene of `count` foxes (the Survey clip, one part) made from the Fox read at `unit`."""
    mesh = fio.read_mesh_animation(_fox(shared_data), clip="Survey", fps=10)
    fox = _quiet(mesh.to_flockkit_axes, meters_per_unit=unit)
    still = flockkit.Features(vectors=np.zeros((fox.motion.n_frames, 3)), dt=fox.motion.dt)
    parts = flockkit.Segmentation(labels=np.zeros(fox.motion.n_agents, dtype=np.int64), n_parts=1)
    layers = flockkit.build_layers(fox, segmentation=parts, features=still, seed=0)
    size = 8.0 if unit == "cm" else 800.0
    region = flockkit.Polygon(vertices=[[0, 0], [size, 0], [size, size], [0, size]])
    return flockkit.Scene(templates=[layers], region=region, counts=[count], duration=2, seed=1).synthesize()


def _usd_boxes(path, times):
    """{object name: [(low, high) world-space box at each time]} of a scene stage's objects."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    boxes = {}
    for prim in stage.GetPseudoRoot().GetChild("Scene").GetChildren():
        boxes[prim.GetName()] = []
        for time in times:
            cache = UsdGeom.BBoxCache(Usd.TimeCode(time), [UsdGeom.Tokens.default_])
            box = cache.ComputeWorldBound(prim).ComputeAlignedRange()
            boxes[prim.GetName()].append((np.array(box.GetMin()), np.array(box.GetMax())))
    return stage, boxes


def test_a_scene_of_foxes_exports_upright_at_true_size(shared_data, tmp_path):
    pytest.importorskip("pxr", reason="USD export needs usd-core (pip install 'flockkit[usd]')")
    from pxr import UsdGeom

    animation = _fox_scene(shared_data)
    with warnings.catch_warnings():
        warnings.simplefilter("error", FlockkitWarning)
        animation.export(tmp_path / "foxes.usda")
    stage, boxes = _usd_boxes(tmp_path / "foxes.usda", times=[0, 12, 24, 47])
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert len(boxes) == 4
    for name, frames in boxes.items():
        for low, high in frames:
            extent = high - low
            assert FOX_HEIGHTS[0] < extent[2] < FOX_HEIGHTS[1], name  # its height along z, in metres
            assert max(extent[:2]) < 1.6 and max(extent[:2]) > extent[2]  # longer than tall, on the ground
            assert low[2] == pytest.approx(0.0, abs=0.01), name  # standing on z = 0
    recorded = stage.GetRootLayer().customLayerData["flockkit"]
    assert recorded["up_axis"] == "z" and recorded["meters_per_unit"] == 1.0
    assert FOX_HEIGHTS[0] < recorded["template_heights_m"][0] < FOX_HEIGHTS[1]


def test_a_scene_of_foxes_never_said_to_be_centimetres_gets_a_hint_at_export(shared_data, tmp_path):
    pytest.importorskip("pxr", reason="USD export needs usd-core (pip install 'flockkit[usd]')")
    animation = _fox_scene(shared_data, unit="m", count=2)
    with pytest.warns(FlockkitWarning, match=r"template 0 is 175.* cm \(0.01 m a unit\)"):
        animation.export(tmp_path / "giants.usda")


# --- crowds -------------------------------------------------------------------------------------


def _fox_crowd(clips, **driver):
    play = lambda name: flockkit.get("controller", "clip", clip=clips[name])  # noqa: E731
    pool = StreamPool([Stream(controller=play("Survey"), history=10), Stream(controller=play("Walk"), history=10)],
                      fps=24)  # fmt: skip
    crowd = Crowd(pool, n_agents=3, clusters={"body": 0}, seed=0)
    t = np.arange(0, 3, 0.1)[:, None, None]
    positions = np.array([[0.0, 0.0], [2.0, 1.0], [-1.0, 3.0]]) + t * np.array([[1.0, 0.2], [0.4, -1.0], [0.0, 0.0]])
    machine = StateMachine([Gait(name="idle", streams=0, high=0.3), Gait(name="walk", streams=1, low=0.3)])
    return Driver(crowd, flockkit.Motion(positions=positions, dt=0.1), machine, **driver), positions


def test_a_crowd_of_foxes_stands_along_z_at_true_size_facing_where_it_goes(shared_data, tmp_path):
    clips = fio.read_clips(_fox(shared_data), meters_per_unit="cm")
    driver, positions = _fox_crowd(clips)  # up, forward and scale from the skeleton: y, z, 0.01
    assert driver.axes == {"up_axis": "y", "forward_axis": "z", "meters_per_unit": 0.01,
                           "skeleton_meters_per_unit": 0.01}  # fmt: skip
    recording = record(driver, 1.0)
    joints = recording.world()[..., :3, 3]  # (frames, agents, joints, 3)
    height = np.ptp(joints[..., 2], axis=2)
    assert 0.5 < height.min() and height.max() < 0.7  # the Fox's skeleton is 61 cm tall at rest
    assert joints[..., 2].min() > -0.01  # nothing below the ground
    head, tail = clips["Walk"].skeleton.index("b_Head_05"), clips["Walk"].skeleton.index("b_Tail03_014")
    ahead = joints[-1, :2, head, :2] - joints[-1, :2, tail, :2]  # the two walking foxes
    heading = np.gradient(positions, 0.1, axis=0)[10, :2]
    assert np.all(np.sum(ahead * heading, axis=1) / np.linalg.norm(ahead, axis=1) / np.linalg.norm(heading, axis=1)
                  > 0.9)  # fmt: skip
    pytest.importorskip("pxr", reason="USD export needs usd-core (pip install 'flockkit[usd]')")
    from pxr import Usd, UsdGeom, UsdSkel

    recording.export_usd(tmp_path / "foxes.usdc")
    stage = Usd.Stage.Open(str(tmp_path / "foxes.usdc"))
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    character = stage.GetRootLayer().customLayerData["flockkit"]["character"]
    assert character["up_axis"] == "y" and character["meters_per_unit"] == 0.01
    cache = UsdSkel.Cache()
    for agent in range(3):
        root = stage.GetPrimAtPath(f"/Crowd/Agent_{agent}")
        query = cache.GetSkelQuery(UsdSkel.Skeleton(root.GetChild("Skeleton")))
        for frame in (0, 23):
            skel = np.array(query.ComputeJointSkelTransforms(frame)).transpose(0, 2, 1)
            placed = np.array(UsdGeom.Xformable(root).ComputeLocalToWorldTransform(frame)).T
            np.testing.assert_allclose((placed @ skel)[:, :3, 3], joints[frame, agent], atol=1e-5)


def test_a_z_up_bird_flies_level_instead_of_standing_on_its_beak():
    clip = inputs.bird()  # z up, facing y, flockkit's convention by default
    pool = StreamPool([Stream(controller=flockkit.get("controller", "clip", clip=clip), history=10)], fps=30)
    crowd = Crowd(pool, n_agents=1, clusters={"body": 0}, seed=0)
    motion = flockkit.Motion(positions=np.arange(10.0)[:, None, None] * [[[1.0, 0.0]]], dt=0.1)
    driver = Driver(crowd, motion, StateMachine([Gait(name="fly", streams=0)]), forward="y")
    body, head = driver.world()[0, [0, 1], :3, 3]
    np.testing.assert_allclose(head - body, [0.12, 0.0, 0.02], atol=1e-9)  # beak ahead, a little above


def test_a_character_without_a_unit_is_refused_until_one_is_stated(shared_data):
    path = shared_data / "cmu-mocap-bvh" / "01_01.bvh"
    (take,) = fio.read_clips(path).values()
    stream = Stream(controller=flockkit.get("controller", "clip", clip=take), history=5)
    crowd = Crowd(StreamPool([stream], fps=30), n_agents=1, clusters={"body": 0}, seed=0)
    still = flockkit.Motion(positions=np.zeros((5, 1, 2)), dt=0.1)
    machine = StateMachine([Gait(name="idle", streams=0)])
    with pytest.raises(ValidationError, match=r"states no unit .* meters_per_unit .* units tall"):
        Driver(crowd, still, machine)
    (stated,) = fio.read_clips(path, meters_per_unit="in").values()
    stream = Stream(controller=flockkit.get("controller", "clip", clip=stated), history=5)
    crowd = Crowd(StreamPool([stream], fps=30), n_agents=1, clusters={"body": 0}, seed=0)
    driver = Driver(crowd, still, machine)
    joints = driver.world()[0, :, :3, 3]
    model = crowd.poses([0], "body", space="world")[0, :, :3, 3]  # the skeleton's own coordinates, y up
    # heights along z are the file's y times the stated unit
    assert np.ptp(joints[:, 2]) == pytest.approx(np.ptp(model[:, 1]) * 0.0254, rel=1e-5)


def test_a_crowd_file_states_the_clips_unit(shared_data, tmp_path):
    from flockkit.crowd.file import read_crowd_scene

    text = """
seconds = 1
[trajectories]
simulate = { agents = 3, seed = 1 }
[character]
clips = "CLIPS"
UNIT
[[streams]]
name = "idle"
clip = "CLIP"
[[states]]
name = "idle"
streams = ["idle"]
"""
    fox, bvh = _fox(shared_data), shared_data / "cmu-mocap-bvh" / "01_01.bvh"
    cases = [
        (fox, "Survey", "meters_per_unit = 0.01", 0.01),
        (fox, "Survey", "scale = 0.01", 0.01),
        (fox, "Survey", 'meters_per_unit = "cm"', 0.01),
        (bvh, "01_01", 'meters_per_unit = "in"', 0.0254),
    ]
    for clips, clip, unit, scale in cases:  # fmt: skip
        (tmp_path / "crowd.toml").write_text(text.replace("CLIPS", str(clips)).replace("CLIP\"", f'{clip}"')
                                             .replace("UNIT", unit))  # fmt: skip
        scene = read_crowd_scene(tmp_path / "crowd.toml", allow_outside=True)
        assert (scene.up, scene.forward, scene.scale) == ("y", "z", scale)
    for clips, clip, unit, message in [
        (bvh, "01_01", "", r"\[character\]: the skeleton states no unit"),
        (fox, "Survey", "scale = 0.01\nmeters_per_unit = 0.01", "meters_per_unit .* or scale .*, not both"),
        (fox, "Survey", 'meters_per_unit = "parsec"', "meters_per_unit must be"),
    ]:
        (tmp_path / "crowd.toml").write_text(text.replace("CLIPS", str(clips)).replace("CLIP\"", f'{clip}"')
                                             .replace("UNIT", unit))  # fmt: skip
        with pytest.raises(ValidationError, match=message):
            read_crowd_scene(tmp_path / "crowd.toml", allow_outside=True)


def test_foot_speeds_are_measured_along_the_characters_own_axes(shared_data):
    clips = fio.read_clips(_fox(shared_data), meters_per_unit="cm")
    speed = flockkit.crowd.ground_speed(clips["Walk"], FOX_FEET)  # y up, z forward, 0.01 m a unit: the skeleton's
    assert speed == flockkit.crowd.ground_speed(clips["Walk"], FOX_FEET, up="y", forward="z", scale=0.01)
    assert 0.2 < speed < 2.0  # metres a second: a fox's walk


# --- Blender ------------------------------------------------------------------------------------

BLENDER_PYTHON = os.environ.get("FLOCKKIT_BPY_PYTHON")  # a Python with Blender's bpy module (pip install bpy)
BLENDER_BOXES = """
import json, sys, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=sys.argv[1], relative_path=False)
scene, found = bpy.context.scene, {}
for frame in map(int, sys.argv[2:]):
    scene.frame_set(frame)
    graph = bpy.context.evaluated_depsgraph_get()
    found[frame] = {}
    for o in scene.objects:
        if o.type == "MESH":
            e = o.evaluated_get(graph)
            points = [list(e.matrix_world @ v.co) for v in e.data.vertices]
        elif o.type == "ARMATURE":
            points = [list(o.matrix_world @ bone.head) for bone in o.pose.bones]
        else:
            continue
        found[frame][o.name] = [[min(p[i] for p in points) for i in range(3)], [max(p[i] for p in points)
                                                                                 for i in range(3)]]
print("RESULT" + json.dumps({"unit": scene.unit_settings.scale_length, "frames": found}))
"""


def _blender_boxes(path, frames):
    done = subprocess.run([BLENDER_PYTHON, "-c", BLENDER_BOXES, str(path), *map(str, frames)], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert "RESULT" in done.stdout, done.stderr[-2000:]
    return json.loads(done.stdout.split("RESULT", 1)[1])


@pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to import in Blender"
)
def test_blender_shows_the_scene_and_the_crowd_upright_at_true_size(shared_data, tmp_path):
    _fox_scene(shared_data).export(tmp_path / "foxes.usdc")
    found = _blender_boxes(tmp_path / "foxes.usdc", [0, 24])
    assert found["unit"] == 1.0
    for boxes in found["frames"].values():
        assert len(boxes) == 4
        for low, high in boxes.values():
            extent = np.subtract(high, low)
            assert FOX_HEIGHTS[0] < extent[2] < FOX_HEIGHTS[1] and max(extent[:2]) > extent[2]
            assert low[2] == pytest.approx(0.0, abs=0.01)
    clips = fio.read_clips(_fox(shared_data), meters_per_unit="cm")
    recording = record(_fox_crowd(clips)[0], 1.0)
    recording.export_usd(tmp_path / "crowd.usdc")
    found = _blender_boxes(tmp_path / "crowd.usdc", [0, 23])
    joints = recording.world()[..., :3, 3]
    for frame, boxes in found["frames"].items():
        assert len(boxes) == 3
        for agent, (low, high) in enumerate(box for _, box in sorted(boxes.items())):
            np.testing.assert_allclose(low, joints[int(frame), agent].min(axis=0), atol=1e-4)
            np.testing.assert_allclose(high, joints[int(frame), agent].max(axis=0), atol=1e-4)
            assert 0.5 < high[2] - low[2] < 0.7 and low[2] > -0.01
