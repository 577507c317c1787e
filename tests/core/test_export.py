import json
import os
import subprocess

import numpy as np
import pytest

import flockkit
from flockkit.errors import ValidationError


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def motion(request):
    return flockkit.simulate(n_agents=6, steps=25, dims=request.param, seed=8)


def test_csv_round_trips_through_the_long_reader(motion, tmp_path):
    flockkit.io.export(motion, tmp_path / "flock.csv")
    back = flockkit.io.read_long(tmp_path / "flock.csv", dt=motion.dt, dims=motion.dims)
    np.testing.assert_array_equal(back.positions, motion.positions)


def test_json_holds_the_positions(motion, tmp_path):
    flockkit.io.export(motion, tmp_path / "flock.json")
    document = json.loads((tmp_path / "flock.json").read_text())
    assert document["format"] == "flockkit-motion" and document["dt"] == motion.dt
    np.testing.assert_array_equal(np.array(document["positions"]), motion.positions)


@pytest.mark.parametrize("suffix, fps", [(".usda", None), (".usdc", 24.0), (".usda", 30.0)])
def test_usd_has_a_time_sample_per_frame_facing_the_velocity(motion, tmp_path, suffix, fps):
    pytest.importorskip("pxr", reason="usd-core (flockkit[usd]) is not installed")
    from pxr import Gf, Usd, UsdGeom

    path = tmp_path / f"flock{suffix}"
    flockkit.io.export(motion, path, fps=fps, meters_per_unit=0.5)
    stage = Usd.Stage.Open(str(path))
    rate = 1 / motion.dt if fps is None else fps
    assert stage.GetTimeCodesPerSecond() == pytest.approx(rate) and stage.GetFramesPerSecond() == pytest.approx(rate)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z and UsdGeom.GetStageMetersPerUnit(stage) == 0.5
    times = np.arange(motion.n_frames) * motion.dt * rate
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == pytest.approx((0, times[-1]))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Flock/Agents"))
    np.testing.assert_allclose(instancer.GetPositionsAttr().GetTimeSamples(), times)
    assert list(instancer.GetIdsAttr().Get()) == list(range(motion.n_agents))
    velocities = motion.velocities()
    for frame in (0, 11, motion.n_frames - 1):
        time = Usd.TimeCode(float(times[frame]))
        points = np.array(instancer.GetPositionsAttr().Get(time))
        np.testing.assert_allclose(points[:, : motion.dims], motion.positions[frame], atol=1e-5)
        speeds = np.array(instancer.GetVelocitiesAttr().Get(time))
        np.testing.assert_allclose(speeds[:, : motion.dims], velocities[frame], rtol=1e-6, atol=1e-5)
        for agent, q in enumerate(instancer.GetOrientationsAttr().Get(time)):
            facing = np.array(Gf.Rotation(Gf.Quatd(q)).TransformDir(Gf.Vec3d(1, 0, 0)))
            heading = np.zeros(3)
            heading[: motion.dims] = velocities[frame, agent] / np.linalg.norm(velocities[frame, agent])
            np.testing.assert_allclose(facing, heading, atol=2e-3)  # half-precision quaternions


def test_unknown_extensions_are_refused_and_nothing_is_written(tmp_path):
    motion = flockkit.simulate(n_agents=3, steps=5, seed=1)
    with pytest.raises(ValidationError, match="unknown export extension"):
        flockkit.io.export(motion, tmp_path / "flock.fbx")
    assert list(tmp_path.iterdir()) == []


def test_usd_without_usd_core_names_the_extra(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pxr", None)  # as if usd-core were not installed
    motion = flockkit.simulate(n_agents=3, steps=5, seed=1)
    with pytest.raises(flockkit.errors.MissingDependencyError, match=r"flockkit\[usd\]"):
        flockkit.io.export(motion, tmp_path / "flock.usdc")
    assert list(tmp_path.iterdir()) == []


def test_usd_angular_velocities_turn_each_heading_onto_the_next(motion, tmp_path):
    pytest.importorskip("pxr", reason="usd-core (flockkit[usd]) is not installed")
    from pxr import Usd, UsdGeom
    from scipy.spatial.transform import Rotation

    flockkit.io.export(motion, tmp_path / "flock.usdc", fps=None)
    stage = Usd.Stage.Open(str(tmp_path / "flock.usdc"))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Flock/Agents"))
    velocities = np.zeros((motion.n_frames, motion.n_agents, 3))
    velocities[..., : motion.dims] = motion.velocities()
    heading = velocities / np.linalg.norm(velocities, axis=2, keepdims=True)
    for frame in (3, 20):
        spin = np.radians(np.array(instancer.GetAngularVelocitiesAttr().Get(Usd.TimeCode(frame)))) * motion.dt
        turned = Rotation.from_rotvec(spin).apply(heading[frame])
        np.testing.assert_allclose(turned, heading[frame + 1], atol=1e-5)


BLENDER_PYTHON = os.environ.get("FLOCKKIT_BPY_PYTHON")  # a Python with Blender's bpy module (pip install bpy)
BLENDER_CHECK = """
import json, sys, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=sys.argv[1], relative_path=False)
scene, agents = bpy.context.scene, bpy.data.objects["Agents"]
found = {"fps": scene.render.fps / scene.render.fps_base, "scale": list(agents.scale), "frames": {}}
for frame in map(int, sys.argv[2:]):
    scene.frame_set(frame)
    graph = bpy.context.evaluated_depsgraph_get()
    found["frames"][frame] = [
        [list(i.matrix_world.translation), list(i.matrix_world.to_3x3().col[0])]
        for i in graph.object_instances if i.is_instance and i.parent and i.parent.name == "Agents"
    ]
print("RESULT" + json.dumps(found))
"""


@pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to import in Blender"
)
def test_blender_imports_the_usd_at_the_right_size_speed_and_facing(motion, tmp_path):
    path = tmp_path / "flock.usdc"
    flockkit.io.export(motion, path)  # the default 24 fps time line: Blender's own
    seconds = (0.0, 1.0, 2.5)
    frames = [round(24 * t) for t in seconds]
    done = subprocess.run([BLENDER_PYTHON, "-c", BLENDER_CHECK, str(path), *map(str, frames)], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    found = json.loads(done.stdout.split("RESULT", 1)[1])
    assert found["fps"] == 24 and found["scale"] == [1.0, 1.0, 1.0]  # metersPerUnit = 1: no 0.01 scale
    velocities = motion.velocities()
    for t, frame in zip(seconds, frames):
        placed = sorted(found["frames"][str(frame)], key=lambda p: p[0])  # Blender orders instances its own way
        source = round(t / motion.dt)
        expected = sorted(range(motion.n_agents), key=lambda a: list(motion.positions[source, a]) + [0.0])
        for (position, facing), agent in zip(placed, expected):
            np.testing.assert_allclose(position[: motion.dims], motion.positions[source, agent], atol=1e-4)
            heading = velocities[source, agent] / np.linalg.norm(velocities[source, agent])
            np.testing.assert_allclose(np.array(facing[: motion.dims]) / np.linalg.norm(facing), heading, atol=3e-3)


def _y_up(points):
    """flockkit's z-up (x, y, z) in glTF's y-up frame: (x, z, -y)."""
    full = np.zeros((*points.shape[:-1], 3))
    full[..., : points.shape[-1]] = points
    return np.stack([full[..., 0], full[..., 2], -full[..., 1]], axis=-1)


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_gltf_has_a_node_per_agent_animated_along_the_motion(motion, tmp_path, suffix):
    pygltflib = pytest.importorskip("pygltflib", reason="the glTF reader pygltflib (test extra) is not installed")
    from scipy.spatial.transform import Rotation

    path = tmp_path / f"flock{suffix}"
    flockkit.io.export(motion, path)
    document = pygltflib.GLTF2().load(str(path))
    blob = document.binary_blob() if suffix == ".glb" else document.decode_data_uri(document.buffers[0].uri)

    def read(index, width):
        accessor = document.accessors[index]
        view = document.bufferViews[accessor.bufferView]
        data = np.frombuffer(blob, dtype=np.float32, count=accessor.count * width, offset=view.byteOffset)
        return data.reshape(accessor.count, width) if width > 1 else data

    agents = [node for node in document.nodes if node.name.startswith("Agent ")]
    assert len(agents) == motion.n_agents and all(node.mesh == 0 for node in agents)
    (animation,) = document.animations
    assert len(animation.channels) == 2 * motion.n_agents
    velocities = _y_up(motion.velocities())
    for channel in animation.channels:
        sampler = animation.samplers[channel.sampler]
        np.testing.assert_allclose(read(sampler.input, 1), np.arange(motion.n_frames) * motion.dt, rtol=1e-6)
        agent = int(document.nodes[channel.target.node].name.split()[1])
        if channel.target.path == "translation":
            np.testing.assert_allclose(read(sampler.output, 3), _y_up(motion.positions[:, agent]), atol=1e-5)
        else:
            facing = Rotation.from_quat(read(sampler.output, 4)).apply([1.0, 0.0, 0.0])  # glTF quaternions: x, y, z, w
            heading = velocities[:, agent] / np.linalg.norm(velocities[:, agent], axis=1, keepdims=True)
            np.testing.assert_allclose(facing, heading, atol=1e-5)


VALIDATOR = os.environ.get("FLOCKKIT_GLTF_VALIDATOR")  # a folder with node_modules/gltf-validator (npm install)
VALIDATE = """
const validator = require(process.argv[1] + "/node_modules/gltf-validator");
const data = new Uint8Array(require("fs").readFileSync(process.argv[2]));
validator.validateBytes(data).then((r) => console.log(JSON.stringify(r.issues)));
"""


@pytest.mark.skipif(not VALIDATOR, reason="set FLOCKKIT_GLTF_VALIDATOR to a folder where npm installed gltf-validator")
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_the_khronos_validator_finds_nothing_to_say(motion, tmp_path, suffix):
    flockkit.io.export(motion, tmp_path / f"flock{suffix}")
    done = subprocess.run(["node", "-e", VALIDATE, VALIDATOR, str(tmp_path / f"flock{suffix}")], capture_output=True,
                          text=True, timeout=120)  # fmt: skip
    issues = json.loads(done.stdout)
    assert (issues["numErrors"], issues["numWarnings"], issues["numInfos"], issues["numHints"]) == (0, 0, 0, 0), issues


BLENDER_GLTF = """
import json, sys, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[1])
scene, found = bpy.context.scene, {}
agents = sorted((o for o in bpy.data.objects if o.name.startswith("Agent ")), key=lambda o: int(o.name.split()[1]))
for frame in map(int, sys.argv[2:]):
    scene.frame_set(frame)
    found[frame] = [[list(o.matrix_world.translation), list(o.matrix_world.to_3x3().col[0])] for o in agents]
print("RESULT" + json.dumps({"fps": scene.render.fps / scene.render.fps_base, "frames": found}))
"""


@pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to import in Blender"
)
def test_blenders_gltf_importer_places_and_turns_every_agent(motion, tmp_path):
    flockkit.io.export(motion, tmp_path / "flock.glb")
    seconds = (0.0, 1.0, 2.5)
    frames = [str(round(24 * t)) for t in seconds]
    argv = [BLENDER_PYTHON, "-c", BLENDER_GLTF, str(tmp_path / "flock.glb"), *frames]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    found = json.loads(done.stdout.split("RESULT", 1)[1])
    velocities = motion.velocities()
    for t in seconds:
        source = round(t / motion.dt)
        for agent, (position, facing) in enumerate(found["frames"][str(round(24 * t))]):  # Blender is z up again
            np.testing.assert_allclose(position[: motion.dims], motion.positions[source, agent], atol=1e-4)
            heading = velocities[source, agent] / np.linalg.norm(velocities[source, agent])
            np.testing.assert_allclose(np.array(facing[: motion.dims]) / np.linalg.norm(facing), heading, atol=1e-3)
