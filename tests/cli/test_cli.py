import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import flockkit
from flockkit.cli import main

SCENARIOS = Path(__file__).resolve().parents[2] / "examples" / "scenarios"


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_plugins_lists_kind_name_plugin_distribution_version(capsys):
    code, out, _ = run(capsys, "plugins")
    assert code == 0
    header, *rows = out.splitlines()
    assert header.split() == ["kind", "name", "plugin", "distribution", "version"]
    assert ["behavior", "boids", "boids", "flockkit", flockkit.__version__] in [row.split() for row in rows]


def test_simulate_writes_motion_and_picture(capsys, tmp_path):
    out_file, picture = tmp_path / "flock.npz", tmp_path / "flock.png"
    code, out, err = run(
        capsys,
        "simulate",
        "--agents",
        "12",
        "--steps",
        "30",
        "--seed",
        "4",
        "-o",
        str(out_file),
        "--picture",
        str(picture),
        "--param",
        "cohesion_weight=2.5",
    )
    assert code == 0, err
    motion = flockkit.Motion.load(out_file)
    assert motion == flockkit.simulate(n_agents=12, steps=30, seed=4, cohesion_weight=2.5)
    assert picture.read_bytes().startswith(b"\x89PNG") and str(picture) in out


def test_check_runs_the_kit_and_reports_what_it_skipped(capsys, tmp_path):
    code, out, _ = run(capsys, "check", "behavior", "boids")
    from flockkit.testing import checks_for

    assert code == 0 and f"behavior 'boids': {len(checks_for('behavior'))} passed" in out and "skipped" not in out
    code, out, _ = run(capsys, "check", "walk", "random")
    assert code == 0 and "passed" in out
    code, out, _ = run(capsys, "check", "behavior", "vicsek")
    assert code == 0 and "5 skipped (check_guide: the component does not declare Capabilities.guide" in out
    code, out, _ = run(capsys, "check", "builder", "kovar", "--partner", "metric=icp-hungarian")
    assert code == 0 and "passed" in out
    code, _, err = run(capsys, "check", "builder", "kovar", "--partner", "metric")
    assert code == 1 and "--partner expects metric=NAME" in err


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["simulate", "--agents", "0", "--steps", "5", "-o", "{tmp}/a.npz"], "n_agents must be an integer >= 1"),
        (["simulate", "--agents", "3", "--steps", "5", "-o", "{tmp}/a.csv"], "unknown extension '.csv'"),
        (["simulate", "--agents", "3", "--steps", "5", "-o", "{tmp}/missing/a.npz"], "does not exist"),
        (["simulate", "--agents", "3", "--steps", "5", "-o", "{tmp}/a.npz", "--picture", "{tmp}/a.gif"], "'.gif'"),
        (
            ["simulate", "--agents", "3", "--steps", "5", "--behavior", "boidz", "-o", "{tmp}/a.npz"],
            "Did you mean 'boids'",
        ),
        (
            ["simulate", "--agents", "3", "--steps", "5", "--param", "speed=2", "-o", "{tmp}/a.npz"],
            "its parameters are",
        ),
        (["check", "behavior", "nothing"], "no behavior named 'nothing'"),
    ],
)
def test_errors_are_one_line_and_nothing_is_written(capsys, tmp_path, argv, expected):
    code, out, err = run(capsys, *[a.format(tmp=tmp_path) for a in argv])
    assert code == 1
    assert err.count("\n") == 1 and expected in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_failing_check_is_one_line(capsys, monkeypatch):
    from flockkit import registry

    from ..testing.fakes import PrefersNoise

    class Plugin:
        @flockkit.hookimpl
        def flockkit_register_behaviors(self, registry):
            registry.add("contrarian", PrefersNoise)

    registry.reset()
    registry.register(Plugin(), name="contrarian-plugin")
    try:
        code, _, err = run(capsys, "check", "behavior", "contrarian")
    finally:
        registry.reset()
    assert code == 1 and err.count("\n") == 1 and "check_log_plausibility_prefers_forward" in err


def test_console_script_is_installed():
    exe = shutil.which("flockkit")
    assert exe is not None
    result = subprocess.run([exe, "--version"], capture_output=True, text=True)
    assert result.returncode == 0 and flockkit.__version__ in result.stdout
    result = subprocess.run([exe, "simulate"], capture_output=True, text=True)
    assert result.returncode == 2 and "required" in result.stderr


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "flock.npz"
    flockkit.simulate(n_agents=8, steps=300, seed=6).save(path)
    return path


def test_build_walk_and_info(capsys, tmp_path, recording):
    graph_file, walked, boxed = tmp_path / "graph.npz", tmp_path / "walk.npz", tmp_path / "boxed.npz"
    code, out, err = run(capsys, "build", str(recording), "-o", str(graph_file), "--jobs", "1", "--quiet")
    assert code == 0, err
    graph = flockkit.MotionGraph.load(graph_file)
    assert f"{len(graph.transitions)} transitions" in out
    code, out, err = run(capsys, "walk", str(graph_file), "--duration", "20", "--seed", "3", "-o", str(walked))
    assert code == 0, err
    expected = flockkit.synthesize(graph, flockkit.walk(graph, duration=20, seed=3))
    assert flockkit.Motion.load(walked) == expected
    code, _, err = run(
        capsys,
        "walk",
        str(graph_file),
        "--duration",
        "20",
        "--strategy",
        "region",
        "--region",
        "box:-100,-100,100,100",
        "-o",
        str(boxed),
    )
    assert code == 0, err
    code, out, _ = run(capsys, "info", str(graph_file))
    document = json.loads(out)
    assert code == 0 and document["transitions"] == len(graph.transitions)
    assert document["params"]["threshold"] == graph.params["threshold"]  # objects, not repr strings
    assert document["provenance"] == {**graph.provenance, "builder_params": {}, "metric_params": {}}
    code, out, _ = run(capsys, "info", str(walked))
    assert code == 0 and json.loads(out)["kind"] == "motion"


def test_build_with_a_threshold_that_leaves_nothing_says_what_would_work(capsys, tmp_path, recording):
    code, _, err = run(capsys, "build", str(recording), "-o", str(tmp_path / "g.npz"), "--threshold", "1e-9", "--quiet")
    assert code == 1 and "threshold=" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "g.npz").exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["walk", "GRAPH", "--duration", "5", "--strategy", "region", "--region", "box:1,2", "-o", "OUT.npz"],
            "--region",
        ),
        (["build", "GRAPH", "-o", "OUT.npz"], "expected a 'motion' file"),
        (["walk", "GRAPH", "--duration", "5", "-o", "OUT.gif"], "unknown extension"),
        (["info", "MISSING.npz"], "no such file"),
    ],
)
def test_graph_commands_reject_bad_input_in_one_line(capsys, tmp_path, recording, argv, message):
    graph_file = tmp_path / "graph.npz"
    flockkit.build_graph(flockkit.Motion.load(recording)).save(graph_file)
    argv = [
        str(graph_file) if a == "GRAPH" else str(tmp_path / a) if a in ("OUT.npz", "OUT.gif", "MISSING.npz") else a
        for a in argv
    ]
    code, _, err = run(capsys, *argv)
    assert code == 1 and message in err and len(err.strip().splitlines()) == 1


def test_solve_writes_the_solution(capsys, tmp_path):
    scenario = tmp_path / "scenario.toml"
    scenario.write_text(
        "[problem]\nagents = 6\nduration = 2.0\n[solve]\nseed = 3\n"
        "[[point]]\nagent = 0\ntime = 0.5\nposition = [0.0, 0.0]\nvelocity = [1.0, 0.0]\n"
        "[[shape]]\ntime = 2.0\nvelocity = [1.0, 0.0]\nbox = { lower = [0.0, -2.0], upper = [3.0, 2.0] }\n"
    )
    out_file = tmp_path / "solution.npz"
    code, out, err = run(capsys, "solve", str(scenario), "--iterations", "20", "-o", str(out_file), "--quiet")
    assert code == 0, err
    motion = flockkit.Motion.load(out_file)
    assert motion.n_frames == 21 and abs(motion.positions[5, 0]).max() <= 1e-9 and "residual" in out
    # --refine 0 samples from the initial trajectories as they are: another motion, same constraints
    unrefined = tmp_path / "unrefined.npz"
    code, _, err = run(capsys, "solve", str(scenario), "--iterations", "20", "--refine", "0", "-o", str(unrefined),
                       "--quiet")  # fmt: skip
    assert code == 0, err
    other = flockkit.Motion.load(unrefined)
    assert abs(other.positions[5, 0]).max() <= 1e-9 and not np.array_equal(other.positions, motion.positions)


@pytest.mark.parametrize(
    "text, message",
    [
        ("[problem]\nagents = 3\n", "duration"),
        (
            "[problem]\nagents = 3\nduration = 1.0\n[[point]]\nagent = 9\ntime = 0.5\nposition = [0, 0]\nvelocity = "
            "[1, 0]\n",
            "agent 9 does not exist",
        ),
        (
            "[problem]\nagents = 3\nduration = 1.0\n[[shape]]\ntime = 0.5\nvelocity = [1, 0]\n",
            "exactly one of polygon, box or ball",
        ),
        ("[problem]\nagents = 3\nduration = 1.0\ncolour = 'red'\n", "unknown key 'colour'"),
        ("[problem\n", "not a TOML scenario"),
    ],
)
def test_bad_scenarios_are_named_in_one_line(capsys, tmp_path, text, message):
    scenario = tmp_path / "bad.toml"
    scenario.write_text(text)
    code, _, err = run(capsys, "solve", str(scenario), "-o", str(tmp_path / "out.npz"))
    assert code == 1 and message in err and "bad.toml" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out.npz").exists()


def test_export_and_import_round_trip(capsys, tmp_path, recording):
    table = tmp_path / "flock.csv"
    code, _, err = run(capsys, "export", str(recording), "-o", str(table))
    assert code == 0, err
    code, _, err = run(capsys, "import", str(table), "--fps", "10", "-o", str(tmp_path / "back.npz"))
    assert code == 0, err
    np.testing.assert_array_equal(
        flockkit.Motion.load(tmp_path / "back.npz").positions, flockkit.Motion.load(recording).positions
    )
    code, _, err = run(capsys, "export", str(recording), "-o", str(tmp_path / "flock.usda"))
    assert code == 0 and (tmp_path / "flock.usda").read_text().startswith("#usda")


@pytest.mark.parametrize(
    "argv, message",
    [
        (["export", "MOTION", "-o", "OUT.fbx"], "unknown extension"),
        (["export", "GRAPH", "-o", "OUT.csv"], "expected a 'motion' file"),
        (["export", "MOTION", "-o", "NOWHERE/out.csv"], "does not exist"),
        (["import", "MOTION", "--fps", "10", "-o", "OUT.npz"], "not all fields are numbers"),
    ],
)
def test_export_and_import_reject_bad_input_in_one_line(capsys, tmp_path, recording, argv, message):
    graph_file = tmp_path / "graph.npz"
    flockkit.build_graph(flockkit.Motion.load(recording)).save(graph_file)
    names = {"MOTION": str(recording), "GRAPH": str(graph_file)}
    argv = [names.get(a) or (str(tmp_path / a) if a.startswith(("OUT", "NOWHERE")) else a) for a in argv]
    code, _, err = run(capsys, *argv)
    assert code == 1 and len(err.strip().splitlines()) == 1 and message in err
    assert not any(p.name.startswith("OUT") for p in tmp_path.iterdir())


def test_render_draws_motions_and_refuses_graphs(capsys, tmp_path, recording):
    code, _, err = run(capsys, "render", str(recording), "-o", str(tmp_path / "flock.gif"))
    assert code == 0 and (tmp_path / "flock.gif").read_bytes()[:3] == b"GIF", err
    code, _, err = run(capsys, "render", str(recording), "-o", str(tmp_path / "flock.png"))
    assert code == 0 and (tmp_path / "flock.png").exists(), err
    graph_file = tmp_path / "graph.npz"
    flockkit.build_graph(flockkit.Motion.load(recording)).save(graph_file)
    code, _, err = run(capsys, "render", str(graph_file), "-o", str(tmp_path / "graph.gif"))
    assert code == 1 and "expected a 'motion' file" in err and not (tmp_path / "graph.gif").exists()


DEMO_STEPS = [
    "simulate 60 s of 20 boids",
    "build the motion graph",
    "draw the recording, its differences and its graph",
    "synthesize 2 min in a box",
    "draw the synthesized flock (png, gif)",
    "solve come-from-behind",
    "draw come-from-behind and its trace",
    "a scene of 12 flocks for 40 s",
    "draw the scene (png, gif)",
    "a crowd of 48 for 5 s",
    "draw the crowd (gif) and its offsets",
    "sticklebacks: read, graph and a 60 s walk",
    "draw the sticklebacks (png, gif)",
    "read the Fox's clips and simulate a 2 000-boid flock",
    "2 000 Foxes driven by a boids flock for 10 s",
    "100 of the Foxes written to USD, skinned",
    "draw 100 of the Foxes (gif)",
    "a scene of 8 walking Foxes for 8 s",
    "the Foxes' scene written to USD",
]
DEMO_RENDERS = {"render-flock.png": ("the flock", "at 60 s"), "render-fox-scene.png": ("the Foxes' scene", "at 6 s"),
                "render-fox-scene.gif": ("the Foxes' scene as they turn", "2 to 6 s"),
                "render-foxes.png": ("the crowd of Foxes", "at 6 s")}  # fmt: skip


def test_the_demo_solves_the_shipped_come_from_behind():
    """The demo's race is examples/scenarios/come-from-behind.toml, constraints and solve settings,
    so the main job shows the scenario the examples ship (within the model's reach: no warning)."""
    from flockkit.cli.demo import come_from_behind
    from flockkit.constrained.scenario import load_scenario

    problem, settings = come_from_behind()
    shipped, shipped_settings = load_scenario(SCENARIOS / "come-from-behind.toml")
    assert settings == shipped_settings
    assert (problem.n_agents, problem.duration) == (shipped.n_agents, shipped.duration)
    assert [type(c) for c in problem.constraints] == [type(c) for c in shipped.constraints]
    for mine, theirs in zip(problem.constraints, shipped.constraints, strict=True):
        for field in ("agent", "agents", "time", "position", "velocity"):
            assert np.array_equal(np.asarray(getattr(mine, field, None)), np.asarray(getattr(theirs, field, None)))


def test_demo_writes_every_picture_and_the_summary(capsys, tmp_path, shared_data):
    """Every picture and file, the summary's figures, every step timed in order (drawing and
    rendering included); the renders where FLOCKKIT_BPY_PYTHON names a Python with bpy (as in
    .ci/run), else the summary says they were skipped and why."""
    from PIL import Image

    code, out, err = run(capsys, "demo", "-o", str(tmp_path / "demo"), "--data", str(shared_data), "--quiet")
    assert code == 0, err
    names = {p.name for p in (tmp_path / "demo").iterdir()}
    summary = json.loads((tmp_path / "demo" / "summary.json").read_text())
    rendered = bool(os.environ.get("FLOCKKIT_BPY_PYTHON"))
    assert names == set(DEMO_RENDERS if rendered else ()) | {
        "recording.png",
        "difference-matrix.png",
        "graph.png",
        "synthesized.png",
        "synthesized.gif",
        "come-from-behind.png",
        "come-from-behind.gif",
        "trace.png",
        "sticklebacks.png",
        "sticklebacks.gif",
        "scene.png",
        "scene.gif",
        "crowd.gif",
        "crowd-offsets.png",
        "foxes.gif",
        "foxes.usdc",
        "fox-scene.usdc",
        "summary.json",
    }
    assert summary["synthesized"]["seconds"] >= 120 and summary["synthesized"]["center of mass in the box"]
    assert min(summary["synthesized"]["share of the box crossed"]) > 0.6  # the box binds: the walk turns at its walls
    assert summary["sticklebacks"]["center kept in the video frame"]
    least, median = summary["scene"]["share of frames heading within 30 degrees of the arrow (least, median)"]
    assert median >= 0.8 and least >= 0.7, summary["scene"]
    assert summary["scene"]["neighbours in step (first walks, end)"][1] <= 0.05
    crowd = summary["crowd"]
    assert crowd["memory (bytes, Equation 5)"][0] == crowd["memory (bytes, Equation 5)"][1]
    assert crowd["cheer stream running (at the cheer, at the end)"] == [True, False]
    start, spread = crowd["distinct offsets among the cheering half (at the start, at 3.5 s)"]
    assert start == 1 and spread >= 12  # all at the head, then spread out by time dilation
    foxes = summary["foxes"]
    assert foxes["agents"] == 2000 and foxes["roots on their trajectories"] and foxes["usd"] == "foxes.usdc"
    just_after, later = foxes["runners in step with another (just after the cue, 2 s later)"]
    assert just_after == 1.0 and later < 0.05  # the cue's dilation spreads the runners within its 2 s
    assert max(summary["come-from-behind"]["residuals"]) <= 0.3 and summary["sticklebacks"]["transitions"] >= 3
    assert str((tmp_path / "demo").resolve()) in out
    assert foxes["shown and written"] == 100
    assert summary["fox scene"]["foxes"] == 8 and summary["fox scene"]["usd"] == "fox-scene.usdc"
    assert summary["fox scene"]["neighbours in step (first walks, end)"][1] <= 0.05
    steps = summary["seconds"]  # every step is timed, drawing and rendering included, and the whole
    renders = [f"render {name} in Blender" for name, _ in DEMO_RENDERS.values()] if rendered else []
    assert list(steps) == DEMO_STEPS + renders + ["the whole demo"]
    assert all(isinstance(v, float) and v >= 0 for v in steps.values())
    assert sum(v for k, v in steps.items() if k != "the whole demo") <= steps["the whole demo"]
    if rendered:
        assert summary["renders"] == {name: f"{file} ({when})" for file, (name, when) in DEMO_RENDERS.items()}
        for file in DEMO_RENDERS:
            with Image.open(tmp_path / "demo" / file) as image:
                assert image.size == ((320, 180) if file.endswith(".gif") else (480, 270))
                assert np.asarray(image.convert("L")).std() > 5  # not blank
                assert file.endswith(".png") or image.n_frames == 33  # 2 to 6 s at 8 fps
    else:
        assert summary["renders"].startswith("skipped:") and "FLOCKKIT_BPY_PYTHON" in summary["renders"]


def test_the_issue_region_walk_on_a_default_flock_from_the_command_line(capsys, tmp_path):
    """`flockkit walk graph.npz --duration 120 --strategy region --region box:-20,-20,20,20` on a
    flock from `flockkit simulate` failed after 12 s; turns make it work. A box the group cannot
    turn in is refused in one line, with the numbers."""
    recording, graph_file, walked = tmp_path / "flock.npz", tmp_path / "graph.npz", tmp_path / "walk.npz"
    code, _, err = run(capsys, "simulate", "--agents", "20", "--steps", "1500", "--seed", "0", "-o", str(recording),
                       "--quiet")  # fmt: skip
    assert code == 0, err
    code, _, err = run(capsys, "build", str(recording), "-o", str(graph_file), "--jobs", "1", "--quiet")
    assert code == 0, err
    region = ["--strategy", "region", "--region", "box:-20,-20,20,20", "-o", str(walked)]
    code, _, err = run(capsys, "walk", str(graph_file), "--duration", "120", "--seed", "0", *region)
    assert code == 0, err
    motion = flockkit.Motion.load(walked)
    assert (
        motion.duration >= 120
        and flockkit.Box(lower=[-20, -20], upper=[20, 20]).contains(motion.center_of_mass()).all()
    )
    code, _, err = run(capsys, "walk", str(graph_file), "--duration", "60", "--strategy", "region", "--region",
                       "box:-1,-1,1,1", "-o", str(tmp_path / "no.npz"))  # fmt: skip
    assert code == 1 and len(err.strip().splitlines()) == 1 and "tightest circle is about" in err
    assert not (tmp_path / "no.npz").exists()


def test_render_draws_regions_and_scenarios(capsys, tmp_path, recording):
    from PIL import Image

    for name in ("boxed.png", "boxed.gif"):
        regions = ["--region", "box:-30,-30,30,30", "--region", "ball:0,0,10"]
        scenario = ["--scenario", str(SCENARIOS / "come-from-behind.toml")]
        code, _, err = run(capsys, "render", str(recording), "-o", str(tmp_path / name), *regions, *scenario,
                           "--size", "300x200")  # fmt: skip
        assert code == 0, err
    with Image.open(tmp_path / "boxed.gif") as image:
        assert image.size == (300, 200)
    code, _, err = run(capsys, "render", str(recording), "-o", str(tmp_path / "x.png"), "--region", "box:1")
    assert code == 1 and "--region 'box:1'" in err


def test_simulate_in_an_arena_and_around_obstacles(capsys, tmp_path):
    out = tmp_path / "arena.npz"
    code, _, err = run(capsys, "simulate", "--agents", "12", "--steps", "400", "--seed", "2", "--arena", "8",
                       "--obstacle", "ball:4,4,1", "-o", str(out), "--quiet")  # fmt: skip
    assert code == 0, err
    motion = flockkit.Motion.load(out)
    assert np.linalg.norm(motion.positions, axis=2).max() < 8.0  # 40 s of flight, and the fence turned them back
    obstacles = [*flockkit.fence(8.0), flockkit.Ball(center=[4, 4], radius=1)]
    assert motion == flockkit.simulate(n_agents=12, steps=400, seed=2, obstacles=obstacles)
    code, _, err = run(capsys, "simulate", "--agents", "3", "--steps", "3", "--obstacle", "ball:0,0", "-o", str(out))
    assert code == 1 and "--obstacle 'ball:0,0'" in err
    code, _, err = run(capsys, "simulate", "--agents", "3", "--steps", "3", "--behavior", "vicsek", "--arena", "5",
                       "-o", str(tmp_path / "v.npz"))  # fmt: skip
    assert code == 1 and not (tmp_path / "v.npz").exists()
    assert "declaring Capabilities(obstacles=True); behavior vicsek does not declare it" in err
    assert "unexpected keyword" not in err and len(err.strip().splitlines()) == 1


def test_meshes_from_the_command_line(capsys, tmp_path, shared_data):
    """segment, build --layers, walk on layers, info and render of an animated mesh."""
    fox = str(shared_data / "fox-gltf" / "Fox.glb")
    parts, layers, walked = tmp_path / "parts.npz", tmp_path / "layers.npz", tmp_path / "walked.npz"
    code, out, err = run(capsys, "segment", fox, "--clip", "Survey", "--seed", "0", "-o", str(parts))
    assert code == 0 and "parts of" in out, err
    found = flockkit.Segmentation.load(parts)
    assert found == flockkit.segment(flockkit.io.read_mesh_animation(fox, clip="Survey"), seed=0)
    code, _, err = run(capsys, "build", fox, "--clip", "Survey", "--parts", str(parts), "-o", str(layers))
    assert code == 0, err
    code, out, _ = run(capsys, "info", str(layers))
    document = json.loads(out)
    assert (
        code == 0 and document["kind"] == "layers" and document["parts"] == found.n_parts and document["faces"] == 576
    )
    code, _, err = run(capsys, "walk", str(layers), "--duration", "5", "--seed", "2", "-o", str(walked))
    assert code == 0, err
    mesh = flockkit.AnimatedMesh.load(walked)
    assert mesh.motion.duration >= 5 and mesh.motion.n_agents == 1728 and len(mesh.faces) == 576
    code, out, _ = run(capsys, "info", str(walked))
    assert json.loads(out)["kind"] == "mesh"
    code, out, _ = run(capsys, "info", str(parts))
    assert json.loads(out) == {"kind": "segmentation", "parts": found.n_parts, "points": 1728,
                               "points_per_part": [len(p) for p in found.parts()]}  # fmt: skip
    for name in ("fox.png", "fox.gif"):
        code, _, err = run(capsys, "render", str(walked), "--parts", str(parts), "-o", str(tmp_path / name))
        assert code == 0 and (tmp_path / name).stat().st_size > 1000, err
    code, _, err = run(capsys, "render", fox, "--clip", "Walk", "-o", str(tmp_path / "walk.gif"))
    assert code == 0, err
    code, _, err = run(capsys, "segment", fox, "--clip", "Trot", "-o", str(tmp_path / "x.npz"))
    assert code == 1 and "no clip 'Trot'" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.npz").exists()


SCENE = """
duration = 8
seed = 2
region = [[0, 0], [30, 0], [30, 20], [0, 20]]
headings = "aligned"

[[templates]]
layers = "plants.npz"
count = 6

[[arrows]]
position = [15, 10]
keyframes = [[0, [0.8, 0]], [4, [0.8, 0]], [6, [0, 0.8]]]
"""


@pytest.fixture(scope="module")
def plants_file(tmp_path_factory):
    from flockkit.testing import inputs

    motion, labels, wind = inputs.plants()
    segmentation = flockkit.Segmentation(labels=labels, n_parts=2)
    path = tmp_path_factory.mktemp("scene") / "plants.npz"
    flockkit.build_layers(motion, segmentation=segmentation, features=wind, seed=1, transitions_per_minute=400).save(
        path
    )
    return path


def test_scene_writes_the_animation_its_usd_and_a_top_view(capsys, plants_file):
    folder = plants_file.parent
    (folder / "scene.toml").write_text(SCENE)
    code, out, _ = run(capsys, "scene", str(folder / "scene.toml"), "-o", str(folder / "out"), "--quiet")
    assert code == 0 and "6 objects, 80 frames" in out and "after" in out
    animation = flockkit.SceneAnimation.load(folder / "out" / "scene.npz")
    assert animation.placement.n_objects == 6 and animation.n_frames == 80
    from pxr import Usd

    stage = Usd.Stage.Open(str(folder / "out" / "scene.usda"))
    assert len(stage.GetPseudoRoot().GetChild("Scene").GetChildren()) == 6
    assert (folder / "out" / "scene.png").stat().st_size > 0
    from PIL import Image

    assert Image.open(folder / "out" / "scene.gif").n_frames == 80


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (SCENE.replace("duration = 8", ""), "missing 'duration'"),
        ("colour = 'red'\n" + SCENE, "unknown entry 'colour'"),
        (SCENE + "colour = 'red'\n", "[[arrows]] 0: unknown key 'colour'"),
        (SCENE.replace("count = 6", "count = 0"), "counts[0]"),
        (SCENE.replace("[4, [0.8, 0]], [6,", "[6, [0.8, 0]], [4,"), "must increase"),
        (SCENE.replace("[0, [0.8, 0]], [4, [0.8, 0]], [6, [0, 0.8]]", "[0, [0, 0]]"), "zero length"),
        (SCENE.replace("[30, 20], [0, 20]", "[0, 20], [30, 20]"), "simple polygon"),
        (SCENE.replace("plants.npz", "nothere.npz"), "nothere.npz"),
        (SCENE.replace("count = 6", "count = 5000"), "cover at least"),
        ("duration = [\n", "not a TOML scene"),
    ],
)
def test_bad_scenes_are_named_in_one_line_and_nothing_is_written(capsys, plants_file, text, message):
    folder = plants_file.parent
    (folder / "bad.toml").write_text(text)
    code, _, err = run(capsys, "scene", str(folder / "bad.toml"), "-o", str(folder / "bad"), "--quiet")
    assert code == 1 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (folder / "bad").exists()


CROWD = """
seconds = 3
fps = 24
seed = 1
record = 12

[trajectories]
simulate = { agents = 40, seed = 1 }

[character]
clips = "FOX"
scale = 0.01
legs = [["b_LeftLeg01_015", "b_LeftLeg02_016", "b_LeftFoot02_018"],
        ["b_RightLeg01_019", "b_RightLeg02_020", "b_RightFoot02_022"],
        ["b_RightUpperArm_06", "b_RightForeArm_07", "b_RightHand_08"],
        ["b_LeftUpperArm_09", "b_LeftForeArm_010", "b_LeftHand_011"]]
plant = ["Walk"]

[[streams]]
name = "idle"
clip = "Survey"

[[streams]]
name = "walk"
clip = "Walk"

[[streams]]
name = "cheer"
clip = "Run"
default = "Stopped"

[[states]]
name = "idle"
streams = ["idle"]
high = 0.2

[[states]]
name = "walk"
streams = ["walk"]
low = 0.2
match = true

[[cues]]
name = "goal"
time = 1
stream = "cheer"
agents = "half"
duration = 1
time_to_dilate = 0.5
"""


def test_crowd_drives_foxes_along_a_flock_and_writes_usd_an_animation_and_a_summary(capsys, tmp_path, shared_data):
    scene = tmp_path / "crowd.toml"
    scene.write_text(CROWD.replace("FOX", str(shared_data / "fox-gltf" / "Fox.glb")))
    code, out, err = run(capsys, "crowd", str(scene), "-o", str(tmp_path / "out"), "--quiet")
    assert code == 1 and "character.clips" in err and "is an absolute path" in err  # the file names one
    code, out, err = run(capsys, "crowd", str(scene), "-o", str(tmp_path / "out"), "--quiet", "--allow-outside")
    assert code == 0, err
    assert "40 agents, 72 frames" in out
    summary = json.loads((tmp_path / "out" / "crowd.json").read_text())
    assert summary["recorded"] == 12 and summary["streams"] == ["idle", "walk", "cheer"]
    assert summary["stream switches"] >= 20  # half went to the cheer and came back
    from pxr import Usd

    stage = Usd.Stage.Open(str(tmp_path / "out" / "crowd.usdc"))
    assert len(stage.GetPseudoRoot().GetChild("Crowd").GetChildren()) == 12 and stage.GetFramesPerSecond() == 24
    from PIL import Image

    assert Image.open(tmp_path / "out" / "crowd.gif").n_frames == 72


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace('streams = ["walk"]', 'streams = ["trot"]'), "[[states]] 1: no stream 'trot'"),
        (lambda t: t.replace("time = 1\n", "time = 9\n"), "[[cues]] 0: time 9 is outside the run (0..3 s)"),
        (lambda t: t.replace("high = 0.2", "high = 0.5"), "overlap"),
        (lambda t: t.replace("low = 0.2", "low = 0.4"), "no state covers values 0.2..0.4"),
        (lambda t: t.replace('clip = "Run"', 'clip = "Gallop"'), "no clip 'Gallop'"),
        (lambda t: t.replace("simulate = { agents = 40, seed = 1 }", ""), "exactly one of simulate, motion, walk"),
        (lambda t: "colour = 'red'\n" + t, "unknown key 'colour'"),
        (lambda t: t.replace("FOX", "nothere.glb"), "nothere.glb"),
        (lambda t: t.replace('plant = ["Walk"]', 'plant = ["Trot"]'), "[character] plant: no clip 'Trot'"),
        (
            lambda t: t.replace('"b_LeftFoot02_018"],', '"b_LeftLeg01_015"],'),
            "legs[0]: 'b_LeftLeg01_015' must be below",
        ),
    ],
)
def test_bad_crowd_scenes_are_named_in_one_line_and_nothing_is_written(capsys, tmp_path, shared_data, edit, message):
    scene = tmp_path / "bad.toml"
    scene.write_text(edit(CROWD).replace("FOX", str(shared_data / "fox-gltf" / "Fox.glb")))
    code, _, err = run(capsys, "crowd", str(scene), "-o", str(tmp_path / "out"), "--quiet", "--allow-outside")
    assert code == 1 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "out").exists()


def test_crowd_without_usd_core_names_the_extra_before_the_run(capsys, tmp_path, shared_data, monkeypatch):
    import flockkit.io.usd
    from flockkit.errors import MissingDependencyError

    def missing():
        raise MissingDependencyError("USD export needs usd-core: pip install 'flockkit[usd]'")

    monkeypatch.setattr(flockkit.io.usd, "require_usd_core", missing)
    scene = tmp_path / "crowd.toml"
    scene.write_text(CROWD.replace("FOX", str(shared_data / "fox-gltf" / "Fox.glb")))
    code, _, err = run(capsys, "crowd", str(scene), "-o", str(tmp_path / "out"), "--quiet", "--allow-outside")
    assert code == 1 and "flockkit[usd]" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
    code, _, err = run(
        capsys,
        "crowd",
        str(scene),
        "-o",
        str(tmp_path / "out"),
        "--quiet",
        "--allow-outside",
        "--no-usd",
        "--no-pictures",
    )
    assert code == 0 and sorted(p.name for p in (tmp_path / "out").iterdir()) == ["crowd.json"]


def test_crowd_exports_to_unwritable_places_are_refused_naming_them(tmp_path):
    from flockkit.crowd import Crowd, Stream, StreamPool, record, write_engine_buffers
    from flockkit.testing import inputs

    pool = StreamPool([Stream(controller=flockkit.get("controller", "clip", clip=inputs.walker()), history=5)])
    crowd = Crowd(pool, n_agents=2, clusters={"body": 0})
    recording = record(crowd, 0.2)
    with pytest.raises(FileNotFoundError, match="nothere"):
        recording.export_usd(tmp_path / "nothere" / "crowd.usda")
    with pytest.raises(FileNotFoundError, match="nothere"):
        write_engine_buffers(crowd, tmp_path / "nothere" / "buffers.npz", 0.2)
    assert list(tmp_path.iterdir()) == []


def test_each_component_takes_its_own_parameters(capsys, tmp_path):
    """--param is the main component's (--builder-param for build); --metric-param reaches the
    metric, as the graph's provenance records; a key a component lacks is one line naming it."""
    recording, graph = tmp_path / "sim.npz", tmp_path / "graph.npz"
    code, _, err = run(capsys, "simulate", "--agents", "8", "--steps", "60", "--seed", "1",
                       "--behavior-param", "cohesion_weight=2", "-o", str(recording))  # fmt: skip
    assert code == 0, err
    assert flockkit.Motion.load(recording) == flockkit.simulate(n_agents=8, steps=60, seed=1, cohesion_weight=2)
    code, _, err = run(capsys, "build", str(recording), "--metric-param", "velocity_weight=0", "--param",
                       "blend_time=0.3", "--quiet", "-o", str(graph))  # fmt: skip
    assert code == 0, err
    built = flockkit.MotionGraph.load(graph)
    assert built.provenance["metric_params"]["velocity_weight"] == 0
    assert built.provenance["builder_params"]["blend_time"] == 0.3
    code, _, err = run(capsys, "build", str(recording), "--metric-param", "bogus=1", "-o", str(tmp_path / "g2.npz"))
    assert code == 1 and "metric 'icp-hungarian'" in err and "'bogus'" in err and len(err.strip().splitlines()) == 1
    code, _, err = run(capsys, "build", str(recording), "--builder-param", "x", "-o", str(tmp_path / "g3.npz"))
    assert code == 1 and "--builder-param expects key=value" in err
