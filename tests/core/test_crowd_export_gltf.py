"""glTF crowd exports (flockkit.crowd.export_gltf): the Khronos validator has nothing to say;
flockkit's own glTF reader reads every agent's joints back where the crowd's own poses put them
(record() of an identical run); agents on one stream at one offset share its frames; a crowd
over the size limit is refused by name before anything is written; Blender imports skinned,
deforming agents."""

import json
import os
import subprocess

import numpy as np
import pytest

import flockkit
from flockkit.crowd import export_gltf, read_skin, record
from flockkit.errors import ValidationError
from flockkit.io import gltf_crowd

from .test_crowd_export_usd import FOX, FPS, SECONDS, fox_crowd, script

# float32 keys: joints within this share of the character's size (measured 2e-7)
TOLERANCE = 2e-6


@pytest.fixture(scope="module")
def fox(shared_data, tmp_path_factory):
    path = shared_data / FOX
    mesh = read_skin(path)
    glb = tmp_path_factory.mktemp("gltf") / "foxes.glb"
    summary = export_gltf(fox_crowd(path), glb, SECONDS, mesh=mesh, on_frame=script)
    recording = record(fox_crowd(path), SECONDS, on_frame=script)
    return {"path": path, "mesh": mesh, "glb": glb, "summary": summary, "recording": recording}


def test_flockkits_reader_reads_every_agents_joints_back_as_the_crowds_poses(fox):
    recording, summary = fox["recording"], fox["summary"]
    assert summary["agents"] == 12 and summary["frames"] == recording.n_frames == round(SECONDS * FPS)
    assert (summary["sharing"], summary["own"]) == (5, 7)  # agents 7-11 read one stream at one offset
    assert summary["bytes"] == fox["glb"].stat().st_size
    clips = flockkit.io.read_clips(fox["glb"], fps=FPS)
    assert sorted(clips) == sorted(f"Agent_{k}/crowd" for k in range(12))
    world = recording.world()[..., :3, 3]
    size = np.ptp(world, axis=2).max()
    for agent in range(12):
        clip = clips[f"Agent_{agent}/crowd"]
        skeleton = clip.skeleton  # the agent's root node above the character's joints
        assert skeleton.names[0] == f"Agent_{agent}"
        joints = [skeleton.index(name) for name in recording.skeleton.names]
        positions = skeleton.positions(clip.sample(np.arange(recording.n_frames) / FPS))[:, joints]
        assert np.abs(positions - world[:, agent]).max() <= TOLERANCE * size


def test_the_mesh_is_stored_once_and_shared_streams_add_no_frames(fox, tmp_path):
    document = flockkit.io.gltf.Document(fox["glb"])
    assert len(document.json["meshes"]) == 1 and len(document.json["skins"]) == 12
    assert {skin["inverseBindMatrices"] for skin in document.json["skins"]} == {
        document.json["skins"][0]["inverseBindMatrices"]
    }
    # 24 more agents on one stream at their own offsets add JSON (nodes, channels), not frames
    binary = {}
    for n in (6, 30):
        crowd = fox_crowd(fox["path"], n=n)
        export_gltf(crowd, tmp_path / f"{n}.glb", SECONDS, mesh=fox["mesh"])
        binary[n] = flockkit.io.gltf.Document(tmp_path / f"{n}.glb").json["buffers"][0]["byteLength"]
    assert binary[30] == binary[6]  # an agent's own frames would be 36 frames x 24 joints x 28 bytes


def test_a_crowd_over_the_limit_is_refused_naming_it(fox, tmp_path, monkeypatch):
    monkeypatch.setattr(gltf_crowd, "GLTF_CROWD_LIMIT", 100_000)
    with pytest.raises(ValidationError, match="GLTF_CROWD_LIMIT"):
        export_gltf(fox_crowd(fox["path"]), tmp_path / "big.glb", SECONDS, mesh=fox["mesh"])
    with pytest.raises(ValidationError, match="SkinnedMesh"):
        export_gltf(fox_crowd(fox["path"]), tmp_path / "big.glb", SECONDS, mesh=None)
    assert list(tmp_path.iterdir()) == []


VALIDATOR = os.environ.get("FLOCKKIT_GLTF_VALIDATOR")  # a folder with node_modules/gltf-validator (npm install)
VALIDATE = """
const validator = require(process.argv[1] + "/node_modules/gltf-validator");
const data = new Uint8Array(require("fs").readFileSync(process.argv[2]));
validator.validateBytes(data).then((r) => console.log(JSON.stringify(r.issues)));
"""


@pytest.mark.skipif(not VALIDATOR, reason="set FLOCKKIT_GLTF_VALIDATOR to a folder where npm installed gltf-validator")
def test_the_khronos_validator_finds_nothing_to_say(fox):
    done = subprocess.run(["node", "-e", VALIDATE, VALIDATOR, str(fox["glb"])], capture_output=True, text=True,
                          timeout=120)  # fmt: skip
    issues = json.loads(done.stdout)
    assert (issues["numErrors"], issues["numWarnings"], issues["numInfos"]) == (0, 0, 0), issues["messages"][:5]


BLENDER_PYTHON = os.environ.get("FLOCKKIT_BPY_PYTHON")  # a Python with Blender's bpy module (pip install bpy)
BLENDER_GLTF = """
import json, sys, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[1])
scene = bpy.context.scene
meshes = sorted((o for o in scene.objects if o.type == "MESH" and o.name.endswith(" body")), key=lambda o: o.name)
found = {"modifiers": [[m.type for m in o.modifiers] for o in meshes], "frames": {},
         "shapes": len([o for o in scene.objects if o.type == "MESH"]) - len(meshes)}  # Blender's bone shapes
for frame in map(int, sys.argv[2:]):
    scene.frame_set(frame)
    graph = bpy.context.evaluated_depsgraph_get()
    found["frames"][frame] = [[list(o.matrix_world @ v.co) for v in o.evaluated_get(graph).data.vertices]
                              for o in meshes]
print("RESULT" + json.dumps(found))
"""


@pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to import in Blender"
)
def test_blender_imports_skinned_agents_that_deform(fox):
    done = subprocess.run([BLENDER_PYTHON, "-c", BLENDER_GLTF, str(fox["glb"]), "1", "14"], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert "RESULT" in done.stdout, done.stderr[-2000:]
    found = json.loads(done.stdout.split("RESULT", 1)[1])
    assert len(found["modifiers"]) == 12 and all("ARMATURE" in m for m in found["modifiers"])
    size = np.ptp(fox["recording"].world()[..., :3, 3], axis=2).max()
    for k in range(12):
        first, later = (np.array(found["frames"][f][k]) for f in ("1", "14"))
        # Blender turns glTF's y-up into its z-up: compare extents, which the turn keeps
        assert 0.5 * size < np.ptp(later, axis=0).max() < 2 * size
        assert np.abs(later - first).max() > 0.02 * size  # deforming
