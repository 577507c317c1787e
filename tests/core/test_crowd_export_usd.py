"""USD crowd exports (flockkit.crowd.export_usd, CrowdRecording.export_usd) read back by usd-core's
UsdSkel and by Blender: every agent's world joints equal the crowd's own poses (Crowd.poses by
forward kinematics, kept by record() from an identical run) through whole frames, time dilation,
blends, unique slots and a Stopped stream that starts twice; the skinned mesh deforms as
flockkit's linear blend skinning of those poses; frame f is integer time code f, frame 0 the
crowd before its first update; steady agents reference their stream's animation."""

import json
import os
import subprocess

import numpy as np
import pytest

import flockkit
from flockkit.crowd import Crowd, Driver, Stream, StreamPool, UniquePool, export_usd, read_skin, record
from flockkit.errors import ValidationError

pytest.importorskip("pxr", reason="USD export needs usd-core (pip install 'flockkit[usd]')")
from pxr import Sdf, Usd, UsdGeom, UsdSkel  # noqa: E402

FOX, ROBOT = "fox-gltf/Fox.glb", "robot-expressive-gltf/RobotExpressive.glb"
FPS = 24.0
SECONDS = 1.5  # 36 frames
# float32 poses and float32 / half-precision files: joints and vertices within this share of the
# character's size (its joints' widest extent) of the crowd's own (measured: below 1e-7)
TOLERANCE = 2e-6


def fox_pool(path):
    clips = flockkit.io.read_clips(path)
    play = lambda name, **k: flockkit.get("controller", "clip", clip=clips[name], **k)  # noqa: E731
    streams = [Stream(controller=play("Walk"), history=48, name="Walk"),
               Stream(controller=play("Survey"), history=48, name="Survey"),
               Stream(controller=play("Run"), history=30, default="Stopped", name="Run")]  # fmt: skip
    unique = UniquePool(1, max_bones=clips["Run"].skeleton.n_joints, fps=FPS)
    unique.set(0, play("Run", rate=0.7))
    return StreamPool(streams, fps=FPS), unique


def fox_crowd(path, n=12):
    pool, unique = fox_pool(path)
    return Crowd(pool, n_agents=n, clusters={"body": np.arange(n) % 2}, unique=unique, seed=1)


def script(crowd, frame):
    """Every case the runtime makes: a Stopped stream started with dilation, blends into a
    Running stream, a unique slot, the Stopped stream left (it stops) and started again."""
    if frame == 2:
        crowd.transition_to_streamed([0, 1, 2], "body", 2, blend_time=0.4, time_to_dilate=0.5)
    if frame == 8:
        crowd.transition_to_streamed([3, 4], "body", 0, blend_time=0.3)
    if frame == 11:
        crowd.transition_to_unique([5], "body", 0, blend_time=0.2)
    if frame == 20:
        crowd.transition_to_streamed([0, 1, 2], "body", 1, blend_time=0.25)
    if frame == 29:
        crowd.transition_to_streamed([6], "body", 2, blend_time=0.1)


@pytest.fixture(scope="module")
def fox(shared_data, tmp_path_factory):
    path = shared_data / FOX
    mesh = read_skin(path)
    usd = tmp_path_factory.mktemp("usd") / "foxes.usdc"
    summary = export_usd(fox_crowd(path), usd, SECONDS, mesh=mesh, on_frame=script, meters_per_unit=0.01)
    recording = record(fox_crowd(path), SECONDS, on_frame=script)
    return {"path": path, "mesh": mesh, "usd": usd, "summary": summary, "recording": recording}


def skel_world(stage, agent: int, frame: int, cache=None) -> np.ndarray:
    """World joint matrices (J, 4, 4), column vectors, of /Crowd/Agent_<agent> as UsdSkel computes them."""
    cache = cache or UsdSkel.Cache()
    root = stage.GetPrimAtPath(f"/Crowd/Agent_{agent}")
    query = cache.GetSkelQuery(UsdSkel.Skeleton(root.GetChild("Skeleton")))
    skel = np.array(query.ComputeJointSkelTransforms(frame)).transpose(0, 2, 1)
    placed = np.array(UsdGeom.Xformable(root).ComputeLocalToWorldTransform(frame)).T
    return placed @ skel


def test_every_agent_reads_back_as_the_crowds_own_poses_on_integer_time_codes(fox):
    stage = Usd.Stage.Open(str(fox["usd"]))
    recording = fox["recording"]
    frames = recording.n_frames
    assert frames == round(SECONDS * FPS)
    assert stage.GetTimeCodesPerSecond() == stage.GetFramesPerSecond() == FPS
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, frames - 1)
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    layer = stage.GetRootLayer()
    times = np.array(layer.ListAllTimeSamples())
    assert np.array_equal(times, np.round(times))  # every time code an integer, stream runs included
    world = recording.world()
    size = np.ptp(world[..., :3, 3], axis=2).max()
    cache = UsdSkel.Cache()
    worst = max(np.abs(skel_world(stage, a, f, cache) - world[f, a]).max()
                for a in range(recording.n_agents) for f in range(frames))  # fmt: skip
    assert worst <= TOLERANCE * size
    # frame 0 is the crowd as it was made, before any update
    fresh = fox_crowd(fox["path"]).poses(space="world")
    assert max(np.abs(skel_world(stage, a, 0, cache) - fresh[a]).max() for a in range(12)) <= TOLERANCE * size


def test_steady_agents_reference_their_streams_and_the_others_hold_samples(fox):
    summary = fox["summary"]
    assert summary["agents"] == 12 and summary["frames"] == round(SECONDS * FPS)
    layer = Sdf.Layer.FindOrOpen(str(fox["usd"]))
    referencing = []
    for agent in range(12):
        spec = layer.GetPrimAtPath(f"/Crowd/Agent_{agent}/Skeleton/Animation")
        references = spec.referenceList.prependedItems
        if references:
            assert str(references[0].primPath).startswith("/CrowdPrototypes/Streams/")
            assert "rotations" not in spec.properties  # nothing of its own
            referencing.append(agent)
        else:
            assert len(spec.properties["rotations"].GetInfo("timeSamples")) == summary["frames"]
    # agents 7-11 read one stream at one offset throughout; 0-6 switch, blend or read a unique slot
    assert referencing == list(range(7, 12)) and summary["referencing"] == 5 and summary["sampled"] == 7
    meshes = []
    layer.Traverse("/", lambda path: meshes.append(path) if layer.GetPrimAtPath(path) is not None
                   and path.IsPrimPath() and layer.GetPrimAtPath(path).typeName == "Mesh" else None)  # fmt: skip
    assert [str(p) for p in meshes] == ["/CrowdPrototypes/Body/Mesh"]  # the mesh is stored once


def test_parts_dilating_throughout_reference_their_stream_at_a_slower_rate(fox, tmp_path):
    def dilating():
        crowd = fox_crowd(fox["path"], n=8)
        crowd.assign(np.arange(8), "body", 2)  # the Stopped Run: offsets spread at a quarter frame a frame
        return crowd

    summary = export_usd(dilating(), tmp_path / "dilating.usda", SECONDS)
    recording = record(dilating(), SECONDS)
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "dilating.usda"))
    scales = [layer.GetPrimAtPath(f"/Crowd/Agent_{k}/Skeleton/Animation").referenceList.prependedItems[0].layerOffset
              .scale for k in range(8)]  # fmt: skip
    assert summary["referencing"] == 8 and sum(scale > 1.01 for scale in scales) >= 5  # slower than the stream
    stage = Usd.Stage.Open(str(tmp_path / "dilating.usda"))
    world = recording.world()
    size = np.ptp(world[..., :3, 3], axis=2).max()
    cache = UsdSkel.Cache()
    worst = max(np.abs(skel_world(stage, a, f, cache) - world[f, a]).max() for a in range(8)
                for f in range(recording.n_frames))  # fmt: skip
    # USD slerps between the run's frames in its own float arithmetic, the crowd in float32 with
    # offsets stepped in float32: the same poses up to that rounding (measured 2.2e-6 of the size)
    assert worst <= 1e-5 * size


def test_the_skinned_mesh_deforms_as_flockkit_skins_the_poses(fox):
    stage = Usd.Stage.Open(str(fox["usd"]))
    mesh, recording = fox["mesh"], fox["recording"]
    world = recording.world()
    size = np.ptp(world[..., :3, 3], axis=2).max()
    cache = UsdSkel.Cache()
    moved = 0.0
    for agent in (0, 3, 5, 9):
        root = UsdSkel.Root(stage.GetPrimAtPath(f"/Crowd/Agent_{agent}"))
        cache.Populate(root, Usd.PrimDefaultPredicate)
        (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
        (target,) = binding.GetSkinningTargets()
        query = cache.GetSkelQuery(binding.GetSkeleton())
        rest = UsdGeom.Mesh(target.GetPrim()).GetPointsAttr().Get()
        found = []
        for frame in (0, 13, 35):
            points = type(rest)(rest)
            assert target.ComputeSkinnedPoints(query.ComputeSkinningTransforms(frame), points, frame)
            found.append(np.array(points))
            expected = mesh.skinned(world[frame, agent])
            assert np.abs(found[-1] - expected).max() <= TOLERANCE * size
        moved = max(moved, np.abs(found[1] - found[0]).max())
    assert moved > 0.05 * size  # the mesh moves between frames


def test_instanceable_bodies_skin_through_instance_proxies(fox, tmp_path):
    export_usd(fox_crowd(fox["path"], n=4), tmp_path / "foxes.usda", 0.5, mesh=fox["mesh"], instanceable=True)
    stage = Usd.Stage.Open(str(tmp_path / "foxes.usda"))
    recording = record(fox_crowd(fox["path"], n=4), 0.5)
    world = recording.world()
    size = np.ptp(world[..., :3, 3], axis=2).max()
    cache = UsdSkel.Cache()
    proxies = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
    for agent in range(4):
        body = stage.GetPrimAtPath(f"/Crowd/Agent_{agent}/Body")
        assert body.IsInstance()
        root = UsdSkel.Root(stage.GetPrimAtPath(f"/Crowd/Agent_{agent}"))
        cache.Populate(root, proxies)
        (binding,) = cache.ComputeSkelBindings(root, proxies)
        (target,) = binding.GetSkinningTargets()
        assert target.GetPrim().IsInstanceProxy()
        points = UsdGeom.Mesh(target.GetPrim()).GetPointsAttr().Get()
        transforms = cache.GetSkelQuery(binding.GetSkeleton()).ComputeSkinningTransforms(7)
        assert target.ComputeSkinnedPoints(transforms, points, 7)
        assert np.abs(np.array(points) - fox["mesh"].skinned(world[7, agent])).max() <= TOLERANCE * size


def test_a_driven_crowd_turns_about_z_and_its_recording_exports_the_same_joints(tmp_path):
    from flockkit.crowd.drive import Gait, StateMachine
    from flockkit.testing import inputs

    walker = inputs.walker()
    play = lambda **k: flockkit.get("controller", "clip", clip=walker, **k)  # noqa: E731
    machine = StateMachine([Gait(name="idle", streams=0, high=0.3),
                            Gait(name="walk", streams=[1, 2], speeds=[0.8, 1.4], low=0.3)])  # fmt: skip
    t = np.arange(0, 3, 0.1)[:, None, None]
    positions = np.array([[0.0, 0.0], [2.0, 1.0], [-1.0, 3.0]]) + t * np.array([[1.0, 0.2], [0.4, -1.0], [0.0, 0.1]])
    positions[:, 0] += np.stack([np.sin(t[:, 0, 0] * 3), np.cos(t[:, 0, 0] * 3)], axis=1)  # agent 0 goes round

    def driver():
        pool = StreamPool([Stream(controller=play(rate=0.2), history=20), Stream(controller=play(), history=20),
                           Stream(controller=play(rate=1.7), history=20)], fps=30)  # fmt: skip
        crowd = Crowd(pool, n_agents=3, clusters={"body": 0}, seed=0)
        return Driver(crowd, flockkit.Motion(positions=positions, dt=0.1), machine, up="z", forward="y")

    export_usd(driver(), tmp_path / "driven.usdc", 1.0)
    recording = record(driver(), 1.0)
    recording.export_usd(tmp_path / "recorded.usdc")
    world = recording.world()
    size = np.ptp(world[..., :3, 3], axis=(0, 1, 2)).max()
    for name in ("driven.usdc", "recorded.usdc"):
        stage = Usd.Stage.Open(str(tmp_path / name))
        ops = UsdGeom.Xformable(stage.GetPrimAtPath("/Crowd/Agent_0")).GetOrderedXformOps()
        assert [op.GetOpName() for op in ops] == ["xformOp:translate", "xformOp:rotateZ", "xformOp:orient",
                                                  "xformOp:scale"]  # fmt: skip
        assert len(ops[1].GetTimeSamples()) == 30 and ops[2].GetNumTimeSamples() == 0  # a float a frame
        cache = UsdSkel.Cache()
        for agent in range(3):
            for frame in range(30):
                assert np.abs(skel_world(stage, agent, frame, cache) - world[frame, agent]).max() <= 1e-5 * size
    stage = Usd.Stage.Open(str(tmp_path / "driven.usdc"))
    metadata = stage.GetRootLayer().customLayerData["flockkit"]
    assert metadata["character"]["up_axis"] == "z"


def test_a_recording_stores_each_repeated_pose_once(shared_data, tmp_path):
    path = shared_data / FOX
    sizes = {}
    for n in (6, 60):
        pool, _ = fox_pool(path)
        crowd = Crowd(pool, n_agents=n, clusters={"body": 0}, seed=2)  # every agent on Walk, 48 frames of it
        recording = record(crowd, 1.0)
        recording.export_usd(tmp_path / f"{n}.usdc")
        sizes[n] = (tmp_path / f"{n}.usdc").stat().st_size
        stage = Usd.Stage.Open(str(tmp_path / f"{n}.usdc"))
        world = recording.world()
        assert np.abs(skel_world(stage, n - 1, 23) - world[23, n - 1]).max() <= 1e-5 * np.ptp(world[..., :3, 3]).max()
    per_sample = (sizes[60] - sizes[6]) / (54 * 24)  # bytes an agent-frame adds
    assert per_sample < 100  # an index per attribute and frame; a new pose would take 24 joints x 28 bytes


@pytest.mark.parametrize("fps, dt, frames", [(24.0, 1 / 24, 240), (30.0, 1 / 30, 301), (24.0, 1 / 48, 97)])
def test_flock_and_scene_exports_put_frames_on_integer_time_codes(tmp_path, fps, dt, frames):
    from flockkit.io.usd import write_meshes

    motion = flockkit.simulate(n_agents=3, steps=frames - 1, dt=dt, seed=1)
    flockkit.io.export(motion, tmp_path / "flock.usdc", fps=fps)
    write_meshes(tmp_path / "scene.usdc", [("/Scene/Object0", motion.positions, None, {})], dt=dt, n_frames=frames,
                 fps=fps)  # fmt: skip
    for name, prim, attribute in (("flock", "/Flock/Agents", "positions"), ("scene", "/Scene/Object0", "points")):
        stage = Usd.Stage.Open(str(tmp_path / f"{name}.usdc"))
        times = np.array(stage.GetPrimAtPath(prim).GetAttribute(attribute).GetTimeSamples())
        expected = np.arange(frames) * dt * fps
        assert times[0] == 0 and stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == times[-1]
        np.testing.assert_allclose(times, expected, atol=1e-9)
        whole = np.abs(expected - np.round(expected)) < 1e-6
        assert np.array_equal(times[whole], np.round(times[whole]))  # 239, not 238.99999999999997
        np.testing.assert_allclose(np.array(stage.GetPrimAtPath(prim).GetAttribute(attribute).Get(times[-1]))[:, :2],
                                   motion.positions[-1], atol=1e-5)  # fmt: skip


def test_bad_exports_are_refused_by_name_and_write_nothing(shared_data, tmp_path):
    path = tmp_path / "crowd.usdc"
    robot = read_skin(shared_data / ROBOT)
    with pytest.raises(ValidationError, match="mesh"):
        export_usd(fox_crowd(shared_data / FOX, n=2), path, 0.5, mesh=robot)
    with pytest.raises(ValidationError, match="SkinnedMesh"):
        export_usd(fox_crowd(shared_data / FOX, n=2), path, 0.5, mesh="Fox.glb")
    with pytest.raises(ValidationError, match="at least one frame"):
        export_usd(fox_crowd(shared_data / FOX, n=2), path, 0.01)
    with pytest.raises(ValidationError, match="unknown agent id 5"):
        export_usd(fox_crowd(shared_data / FOX, n=2), path, 0.5, agents=[5])
    with pytest.raises(ValidationError, match="Crowd or a crowd Driver"):
        export_usd("crowd", path, 0.5)
    assert list(tmp_path.iterdir()) == []


BLENDER_PYTHON = os.environ.get("FLOCKKIT_BPY_PYTHON")  # a Python with Blender's bpy module (pip install bpy)
BLENDER_CROWD = """
import json, sys
import bpy
path, frames = sys.argv[1], [int(f) for f in sys.argv[2:]]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=path)
scene = bpy.context.scene
meshes = sorted([o for o in scene.objects if o.type == "MESH"], key=lambda o: o.parent.name if o.parent else o.name)
found = {"fps": scene.render.fps / scene.render.fps_base, "range": [scene.frame_start, scene.frame_end],
         "modifiers": [[m.type for m in o.modifiers] for o in meshes],
         "parents": [o.parent.name if o.parent else None for o in meshes], "frames": {}}
for frame in frames:
    scene.frame_set(frame)
    graph = bpy.context.evaluated_depsgraph_get()
    found["frames"][frame] = [[list(o.matrix_world @ v.co) for v in o.evaluated_get(graph).data.vertices]
                              for o in meshes]
print("RESULT" + json.dumps(found))
"""


@pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to import in Blender"
)
def test_blender_imports_deforming_meshes_where_the_crowd_puts_them(fox):
    frames = [0, 13, 35]
    done = subprocess.run([BLENDER_PYTHON, "-c", BLENDER_CROWD, str(fox["usd"]), *map(str, frames)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert "RESULT" in done.stdout, done.stderr[-2000:]
    found = json.loads(done.stdout.split("RESULT", 1)[1])
    assert found["fps"] == FPS and found["range"] == [0, round(SECONDS * FPS) - 1]
    assert len(found["modifiers"]) == 12 and all(m == ["ARMATURE"] for m in found["modifiers"])
    world = fox["recording"].world()
    mesh = fox["mesh"]
    size = np.ptp(world[..., :3, 3], axis=2).max() * 0.01  # metres: the stage is in centimetres
    by_agent = {int(parent.split("_")[1].split(".")[0]): k for k, parent in enumerate(found["parents"])}
    for frame in frames:
        for agent, k in by_agent.items():
            vertices = np.array(found["frames"][str(frame)][k])
            expected = mesh.skinned(world[frame, agent]) * 0.01  # Blender converts to metres
            assert np.abs(vertices - expected).max() <= 1e-5 * size
    moved = np.abs(np.array(found["frames"]["13"][0]) - np.array(found["frames"]["0"][0])).max()
    assert moved > 0.05 * size  # deforming, not a still mesh
