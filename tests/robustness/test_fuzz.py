"""Hypothesis over value types, file bytes and CLI arguments, with a bounded budget: every input
works or gets a named flockkit error; never a raw exception, a traceback or a hang."""

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import flockkit
from flockkit.testing import strategies as fst

from .harness import cli_outcome, outcome

BUDGET = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# value type -> how it is called with one field replaced by an arbitrary value
_BASE = {
    "Motion": lambda **f: flockkit.Motion(**{"positions": np.zeros((3, 2, 2)), "dt": 0.1, **f}),
    "State": lambda **f: flockkit.State(**{"positions": np.zeros((2, 2)), "velocities": np.ones((2, 2)), **f}),
    "Ball": lambda **f: flockkit.Ball(**{"center": [0.0, 0.0], "radius": 1.0, **f}),
    "Box": lambda **f: flockkit.Box(**{"lower": [0.0, 0.0], "upper": [1.0, 1.0], **f}),
    "Polygon": lambda **f: flockkit.Polygon(**{"vertices": [[0, 0], [1, 0], [0, 1]], **f}),
    "PointConstraint": lambda **f: flockkit.PointConstraint(**{"agent": 0, "time": 0.5, "position": [0, 0], **f}),
    "ComConstraint": lambda **f: flockkit.ComConstraint(**{"time": 0.5, "position": [0, 0], **f}),
    "Problem": lambda **f: flockkit.Problem(**{"n_agents": 3, "duration": 1.0, **f}),
    "Alignment": lambda **f: flockkit.Alignment(
        **{"distance": 0.0, "assignment": [0, 1], "rotation": np.eye(2), "translation": [0, 0], **f}
    ),
    "Walk": lambda **f: flockkit.Walk(**{"start": 0, "edges": [("clip", 0)], **f}),
    "Capabilities": lambda **f: flockkit.Capabilities(**f),
    "simulate": lambda **f: flockkit.simulate(**{"n_agents": 3, "steps": 3, **f}),
    "get boids": lambda **f: flockkit.get("behavior", "boids", **f),
}
_FIELDS = {
    "Motion": ["positions", "dt", "channels"],
    "State": ["positions", "velocities", "extra"],
    "Ball": ["center", "radius"],
    "Box": ["lower", "upper"],
    "Polygon": ["vertices"],
    "PointConstraint": ["agent", "time", "position", "velocity"],
    "ComConstraint": ["agents", "time", "position", "velocity"],
    "Problem": [
        "n_agents",
        "dims",
        "dt",
        "duration",
        "constraints",
        "obstacles",
        "flocks",
        "sigma_com",
        "clearance",
        "follow",
    ],
    "Alignment": ["distance", "assignment", "rotation", "translation"],
    "Walk": ["start", "edges", "rotation", "translation"],
    "Capabilities": ["dims", "guide", "plausibility_reach", "pairs_within"],
    "simulate": ["n_agents", "steps", "dims", "dt", "seed", "initial", "behavior"],
    "get boids": ["dt", "perception_radius", "field_of_view", "obstacles", "kdtree_above"],
}
CALLS = [(name, field) for name, fields in _FIELDS.items() for field in fields]


def _junk(value) -> bool:
    """Not a real workload: counts from ten thousand to a billion are work, and take its time."""
    return not (isinstance(value, int) and 10_000 < abs(value) < 10**9)


@pytest.mark.parametrize("name, field", CALLS, ids=[f"{n}.{f}" for n, f in CALLS])
@settings(max_examples=25, deadline=None)
@given(value=fst.anything().filter(_junk))
def test_value_types_take_anything_or_name_the_field(name, field, value):
    kind, what = outcome(lambda: _BASE[name](**{field: value}), seconds=20)
    assert kind in ("ok", "named"), f"{name}({field}={value!r}): {kind}: {what}"


@pytest.fixture(scope="module")
def saved():
    folder = Path(tempfile.mkdtemp(prefix="flockkit-fuzz-"))
    motion = flockkit.simulate(n_agents=4, steps=40, seed=2)
    motion.save(folder / "motion.npz")
    flockkit.build_graph(flockkit.simulate(n_agents=4, steps=150, seed=2), seed=0).save(folder / "graph.npz")
    return folder


@pytest.mark.parametrize("kind", ["motion", "graph"])
@BUDGET
@given(data=st.data())
def test_damaged_files_load_whole_or_are_named(kind, data, saved):
    original = (saved / f"{kind}.npz").read_bytes()
    damaged = data.draw(fst.damaged(original))
    path = saved / f"damaged-{kind}.npz"
    path.write_bytes(damaged)
    load = flockkit.Motion.load if kind == "motion" else flockkit.MotionGraph.load
    result, what = outcome(lambda: load(path), seconds=20)
    assert result in ("ok", "named"), f"{kind} file damaged: {result}: {what}"


@BUDGET
@given(motion=fst.motions(max_frames=12, max_agents=5, channels=["wander"]), data=st.data())
def test_any_saved_motion_round_trips_and_any_damage_is_named(motion, data, tmp_path_factory):
    folder = tmp_path_factory.mktemp("roundtrip")
    motion.save(folder / "m.npz")
    assert flockkit.Motion.load(folder / "m.npz") == motion
    (folder / "d.npz").write_bytes(data.draw(fst.damaged((folder / "m.npz").read_bytes())))
    result, what = outcome(lambda: flockkit.Motion.load(folder / "d.npz"), seconds=20)
    assert result in ("ok", "named"), what


# CLI arguments: each option's values drawn from those that broke it before, and ordinary ones
_NUMBERS = ["-1", "0", "1", "3", "1.5", "1e300", "nan", "inf", "x", ""]


def _argv(data, folder):
    motion, graph = str(folder / "motion.npz"), str(folder / "graph.npz")
    paths = [motion, graph, str(folder), "/dev/null", str(folder / "missing.npz"), str(folder / "out.txt")]
    out = str(folder / "out.npz")
    pick = data.draw
    command = pick(st.sampled_from(["simulate", "build", "walk", "info", "export", "import", "check", "plugins"]))
    if command == "simulate":
        argv = ["simulate", "--agents", pick(st.sampled_from(_NUMBERS)), "--steps", pick(st.sampled_from(_NUMBERS)),
                "-o", pick(st.sampled_from([out, *paths]))]  # fmt: skip
        params = ("dt=5", "speed=2", "obstacles=5", "x", "seed=1")
        extra = st.sampled_from([*(["--dt", n] for n in _NUMBERS), *(["--seed", n] for n in _NUMBERS),
                                 *(["--param", p] for p in params)])  # fmt: skip
        argv += pick(extra)
    elif command == "build":
        argv = ["build", pick(st.sampled_from(paths)), "-o", pick(st.sampled_from([out, *paths])), "--quiet"]
        argv += pick(st.sampled_from([[], ["--threshold", "-1"], ["--jobs", "0"], ["--param", "metric=x"]]))
    elif command == "walk":
        argv = ["walk", pick(st.sampled_from(paths)), "--duration", pick(st.sampled_from(_NUMBERS)), "-o", out]
        argv += pick(st.sampled_from([[], ["--seed", "-1"], ["--strategy", "region", "--region", "box:0,0"],
                                      ["--strategy", "region", "--region", "ball:0,0,1e308"]]))  # fmt: skip
    elif command in ("info", "export"):
        argv = [command, pick(st.sampled_from(paths))]
        argv += [] if command == "info" else ["-o", pick(st.sampled_from([str(folder / "e.csv"), *paths]))]
    elif command == "import":
        argv = ["import", pick(st.sampled_from(paths)), "-o", out, "--fps", pick(st.sampled_from(_NUMBERS))]
    elif command == "check":
        argv = ["check", pick(st.sampled_from(["behavior", "metric", "walk"])), pick(st.sampled_from(["boids", "x"])),
                "--quiet"]  # fmt: skip
        argv += pick(st.sampled_from([[], ["--partner", "metric"], ["--param", "dt=-1"]]))
    else:
        argv = ["plugins", *pick(st.sampled_from([[], ["--kind", "behavior"]]))]
    return argv


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_cli_arguments_give_a_result_or_one_line(data, saved):
    argv = _argv(data, saved)
    kind, what = cli_outcome(argv, seconds=30)
    assert kind in ("ok", "named"), f"flockkit {' '.join(argv)}: {kind}: {what}"
