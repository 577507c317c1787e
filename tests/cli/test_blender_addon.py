"""The Blender add-on: `flockkit blender-addon` builds an extension Blender installs; the worker it
runs answers its jobs through flockkit's API; and, where FLOCKKIT_BPY_PYTHON names a Python with
bpy, a fresh Blender installs it and every operator makes the objects, keys and frame range it
should (a solve from keyframed empties meeting them as Blender reads the agents back)."""

import ast
import json
import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

import flockkit
from flockkit.cli import blender as worker
from flockkit.cli import main

BLENDER_PYTHON = os.environ.get("FLOCKKIT_BPY_PYTHON")  # a Python with Blender's bpy module (pip install bpy)
SESSION = Path(__file__).with_name("blender_session.py")


@pytest.fixture(scope="module")
def addon(tmp_path_factory):
    path = tmp_path_factory.mktemp("addon") / "flockkit_addon.zip"
    assert main(["blender-addon", "-o", str(path)]) == 0
    return path


def test_the_command_writes_an_extension_blender_reads(addon):
    with zipfile.ZipFile(addon) as archive:
        names = set(archive.namelist())
        manifest = tomllib.loads(archive.read("blender_manifest.toml").decode())
        sources = {n: archive.read(n).decode() for n in names if n.endswith(".py")}
    assert {"__init__.py", "_ops.py", "_ui.py", "_props.py", "_bridge.py", "_job.py"} <= names
    assert manifest["id"] == "flockkit" and manifest["type"] == "add-on"
    assert manifest["version"] == flockkit.__version__ and manifest["blender_version_min"] == "4.2.0"
    assert manifest["schema_version"] == "1.0.0" and manifest["permissions"]["files"]
    for name, text in sources.items():  # Blender's numpy is not flockkit's: the add-on never imports flockkit
        imported = {
            a.name.split(".")[0]
            for node in ast.walk(ast.parse(text))
            if isinstance(node, ast.Import)
            for a in node.names
        } | {
            node.module.split(".")[0]
            for node in ast.walk(ast.parse(text))
            if isinstance(node, ast.ImportFrom) and node.module and not node.level
        }
        assert "flockkit" not in imported, name
    assert "def register" in sources["__init__.py"] and "def unregister" in sources["__init__.py"]


def test_the_command_refuses_another_suffix(tmp_path, capsys):
    assert main(["blender-addon", "-o", str(tmp_path / "addon.tar")]) == 1
    assert "expected a .zip" in capsys.readouterr().err
    assert not (tmp_path / "addon.tar").exists()


def _run(tmp_path, job):
    path = tmp_path / f"{job['task']}.json"
    path.write_text(json.dumps(dict(job, output=str(tmp_path / f"{job['task']}-result"))))
    result = worker.run(path)
    with np.load(tmp_path / f"{job['task']}-result.npz") as data:
        return {k: data[k] for k in data.files}, result


PROBLEM = {
    "n_agents": 5, "dims": 2, "dt": 1 / 24, "duration": 2.0, "obstacles": [],
    "constraints": [
        {"kind": "point", "agent": 0, "time": 0.0, "position": [0.0, 0.0], "name": "A @ 1"},
        {"kind": "point", "agent": 0, "time": 1.0, "position": [1.0, 0.3], "name": "A @ 25"},
        {"kind": "point", "agent": 0, "time": 2.0, "position": [2.1, 0.0], "name": "A @ 49"},
        {"kind": "point", "agent": 2, "time": 1.5, "position": [30.0, 0.0], "velocity": [1.0, 0.0], "name": "B"},
        {"kind": "shape", "agents": [3, 4], "time": 1.0, "velocity": [1.0, 0.0], "name": "S",
         "shape": {"kind": "polygon", "vertices": [[0, -1], [2, -1], [2, 1], [0, 1]]}},
    ],
}  # fmt: skip


def test_the_worker_solves_what_the_add_on_sends(tmp_path):
    arrays, result = _run(tmp_path, {"task": "solve", "problem": PROBLEM, "iterations": 30, "refine": 10, "seed": 2,
                                     "motion": str(tmp_path / "flock.npz")})  # fmt: skip
    location = arrays["location"]
    assert location.shape == (49, 5, 3) and np.all(location[..., 2] == 0)
    for c in PROBLEM["constraints"][:4]:
        np.testing.assert_allclose(location[round(c["time"] * 24), c["agent"], :2], c["position"], atol=1e-9)
    inside = location[24, 3:, :2]
    assert np.all((inside >= [0, -1]) & (inside <= [2, 1]))
    motion = flockkit.Motion.load(tmp_path / "flock.npz")
    np.testing.assert_array_equal(motion.positions, location[..., :2])
    # the rotation turns each agent's +x along its velocity (XYZ Euler, no roll)
    x, pitch, yaw = np.moveaxis(arrays["rotation"], -1, 0)
    assert np.all(x == 0) and np.all(pitch == 0)
    velocity = motion.velocities()
    heading = np.stack([np.cos(yaw), np.sin(yaw)], axis=-1)
    np.testing.assert_allclose(heading, velocity / np.linalg.norm(velocity, axis=-1, keepdims=True), atol=1e-9)
    assert result["residual"] < 1e-9 and any("30" in w or "speed" in w for w in result["warnings"])


def test_the_worker_hints_at_speeds_beyond_the_model(tmp_path):
    _, result = _run(tmp_path, {"task": "hints", "problem": PROBLEM, "seed": 1})
    model = result["model"]
    assert 0 < model["p10"] <= model["p90"] <= model["p99"]
    legs = {leg["name"]: leg for leg in result["legs"]}
    assert set(legs) == {"A @ 25", "A @ 49", "B"}  # a track's first key is judged by the leg after it
    np.testing.assert_allclose(legs["A @ 25"]["speed"], np.hypot(1.0, 0.3))  # from A @ 1, one second before
    assert legs["A @ 25"]["source"].startswith("from A @ 1")
    assert not legs["A @ 25"]["beyond"] and not legs["B"]["beyond"]  # B's own velocity, 1 m/s
    far = json.loads(json.dumps(PROBLEM))
    far["constraints"][2]["position"] = [40.0, 0.0]
    _, result = _run(tmp_path, {"task": "hints", "problem": far, "seed": 1})
    legs = {leg["name"]: leg for leg in result["legs"]}
    assert legs["A @ 49"]["beyond"] and legs["A @ 49"]["ratio"] > 10
    assert any("constraint 2" in w for w in result["warnings"])


def test_the_worker_reports_an_error_in_one_line(tmp_path, capsys):
    job = tmp_path / "job.json"
    job.write_text(json.dumps({"task": "solve", "output": str(tmp_path / "out"),
                               "problem": dict(PROBLEM, n_agents=2)}))  # fmt: skip
    assert worker.main([str(job)]) == 1
    out = capsys.readouterr().out.strip().splitlines()
    assert out[-1].startswith("ERROR ") and "agent 2 does not exist" in out[-1]
    assert not (tmp_path / "out.npz").exists()


@pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to run the add-on"
)
def test_the_add_on_in_a_fresh_blender(addon, tmp_path):
    environment = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender"))  # a fresh user: no add-ons
    environment.pop("PYTHONPATH", None)
    done = subprocess.run([BLENDER_PYTHON, str(SESSION), str(addon), sys.executable, str(tmp_path)],
                          capture_output=True, text=True, timeout=600, env=environment)  # fmt: skip
    assert "RESULT" in done.stdout, done.stdout[-3000:] + done.stderr[-3000:]
    found = json.loads(done.stdout.split("RESULT", 1)[1])
    assert found["addon"] == "bl_ext.user_default.flockkit"
    assert found["parameters"] and all(isinstance(v, float) for v in found["parameters"].values())

    # simulate: six instances of the chosen mesh keyed every frame of the range, where flockkit put them
    simulated = found["simulate"]
    assert simulated["agents"] == [f"Agent {k}" for k in range(6)] and simulated["meshes"] == ["Cube"]
    assert simulated["range"] == [1, 49]
    assert sorted(simulated["keys"]) == [f"{p}[{i}]" for p in ("location", "rotation_euler") for i in range(3)]
    assert all([k[0] for k in keys] == list(range(1, 50)) for keys in simulated["keys"].values())
    motion = flockkit.Motion.load(simulated["motion"])
    for frame, placed in simulated["places"].items():
        for k in range(6):
            np.testing.assert_allclose(placed[f"Agent {k}"][:2], motion.positions[int(frame) - 1, k], atol=1e-5)

    # hints: the last key 40 m away is flagged; after the edit nothing is
    assert found["hints far"][0][0].startswith("unconstrained:") and not found["hints far"][0][1]
    assert any(alert and "Point @ 49" in text for text, alert in found["hints far"])
    assert not any(alert for _, alert in found["hints near"])

    # the worker's progress, as the modal timer reads it, climbs to the end
    progress = found["polled"]["progress"]
    assert progress[-1] == 1.0 and progress == sorted(progress) and len(set(progress)) > 2

    # solve, and solve again after an edit: every key met as Blender reads the agents back
    for key, edited in (("solve", (1.0, 0.3)), ("resolve", (1.0, 0.6))):
        solved = found[key]
        assert solved["range"] == [1, 49] and solved["agents"] == 6 and solved["status"].startswith("solved 6")
        for name, (wanted, agent) in solved["points"].items():
            np.testing.assert_allclose(agent, wanted, atol=1e-5, err_msg=f"{key}: {name}")
        np.testing.assert_allclose(solved["points"]["Point 25"][0][:2], edited, atol=1e-6)
        for frame, (wanted, centre) in solved["centres"].items():
            assert np.linalg.norm(np.subtract(wanted, centre)[:2]) <= 3 * 0.1 + 1e-6, (key, frame)

    # analyse and scatter: parts as vertex groups; three animated copies on the ground, waving
    analysed = found["analyse"]
    assert analysed["parts"] >= 1
    assert analysed["groups"] == [f"flockkit part {k}" for k in range(analysed["parts"])]
    scattered = found["scatter"]
    assert len(scattered["meshes"]) == 3 and scattered["range"] == [1, 49]
    shapes = {int(frame): np.array(points) for frame, points in scattered["shapes"].items()}
    assert all(s.shape == (3, scattered["vertices"], 3) for s in shapes.values())
    for points in shapes.values():
        assert np.all(np.abs(points[..., 0] - 30) <= 10) and np.all(np.abs(points[..., 1]) <= 10)
    assert np.abs(shapes[1] - shapes[20]).max() > 1e-3  # the copies move
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(tmp_path / "scene.usdc"))  # Blender frame f plays the stage's time code f - 1
    for frame, points in shapes.items():
        for name, placed in zip(scattered["meshes"], points):
            written = np.array(UsdGeom.Mesh(stage.GetPrimAtPath(f"/Scene/{name}")).GetPointsAttr().Get(frame - 1))
            np.testing.assert_allclose(placed, written, atol=1e-5)

    # the crowd: a shared armature per agent on the flock's trajectories, its bone keyed every frame
    crowd = found["crowd"]
    assert crowd["objects"] == [f"Armature {k}" for k in range(6)] and len(crowd["armatures"]) == 1
    assert crowd["range"] == [1, 49]
    bone = crowd["keys"]['pose.bones["Bone"].rotation_euler[0]']
    assert [k[0] for k in bone] == list(range(1, 50)) and all(-1e-6 <= k[1] <= 0.5 + 1e-6 for k in bone)
    assert max(k[1] for k in bone) > 0.05
    assert Path(crowd["motion"]).name == "solved.npz"  # the last flock: the solve's
    last = flockkit.Motion.load(crowd["motion"])
    for frame, placed in crowd["places"].items():
        for k in range(6):
            np.testing.assert_allclose(placed[f"Armature {k}"][:2], last.positions[int(frame) - 1, k], atol=1e-5)
