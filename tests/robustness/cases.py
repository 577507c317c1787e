"""The hand-written cases of the robustness suite: every input the hardening review found to end in
a traceback, a raw exception, a silent accept or a hang, replayed. Each is (name, call) for the
library or (name, argv) for the CLI; the tests expect ``named`` (or ``ok`` where stated)."""

from __future__ import annotations

import numpy as np

import flockkit
from flockkit import io as fio

POLYGON = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]
JUMP = "0,0,1,1\n1,0,2,2\n1000000000,0,2,2\n"  # frames 2 .. 999 999 999 missing
WIDE = "0,1,1,2,2\n1,1,1,2,2\n"  # two agents


def _problem(**changes):
    fields = {
        "n_agents": 6,
        "duration": 2.0,
        "constraints": [flockkit.PointConstraint(agent=0, time=1.0, position=[0.0, 0.0], velocity=[1.0, 0.0])],
    }
    return flockkit.Problem(**{**fields, **changes})


def _shape_problem(vertices):
    shape = flockkit.ShapeConstraint(time=1.0, shape=flockkit.Polygon(vertices=vertices), velocity=[1.0, 0.0])
    return _problem(constraints=[shape])


def library(tmp) -> list[tuple[str, object]]:
    """(name, call) for every bad value the review found accepted, or raising a raw exception."""
    small = flockkit.simulate(n_agents=5, steps=150, seed=1)
    graph = flockkit.build_graph(small, seed=0)
    motion = flockkit.simulate(n_agents=3, steps=5, seed=1)

    def table(name, text):
        path = tmp / name
        path.write_text(text)
        return path

    return [
        ("simulate seed -1", lambda: flockkit.simulate(n_agents=3, steps=3, seed=-1)),
        ("simulate seed 'x'", lambda: flockkit.simulate(n_agents=3, steps=3, seed="x")),
        ("simulate seed 1.5", lambda: flockkit.simulate(n_agents=3, steps=3, seed=1.5)),
        ("walk seed -1", lambda: flockkit.walk(graph, duration=5, seed=-1)),
        ("build_graph seed -1", lambda: flockkit.build_graph(small, seed=-1)),
        ("solve seed -1", lambda: flockkit.solve(_problem(), iterations=1, seed=-1)),
        ("simulate obstacles=5", lambda: flockkit.simulate(n_agents=3, steps=3, obstacles=5)),
        ("simulate initial='x'", lambda: flockkit.simulate(n_agents=3, steps=3, initial="x")),
        ("simulate dt 1e300", lambda: flockkit.simulate(n_agents=5, steps=20, dt=1e300)),
        ("simulate 1e8 steps", lambda: flockkit.simulate(n_agents=20, steps=100_000_000)),
        ("simulate 10 million agents", lambda: flockkit.simulate(n_agents=10_000_000, steps=3)),
        ("random_flock 1e13 agents", lambda: flockkit.random_flock(n_agents=10**13, rng=np.random.default_rng(0))),
        ("walk 1e7 s", lambda: flockkit.walk(graph, duration=1e7)),
        ("walk 1e9 s", lambda: flockkit.walk(graph, duration=1e9)),
        ("solve 1e13 iterations", lambda: flockkit.solve(_problem(), iterations=10**13)),
        ("solve dt 1e-7", lambda: flockkit.solve(_problem(dt=1e-7), iterations=1)),
        ("solve proposals [1, 2]", lambda: flockkit.solve(_problem(), proposals=[1, 2])),
        ("Problem dims 2.0", lambda: flockkit.Problem(n_agents=3, duration=1.0, dims=2.0)),
        ("PointConstraint position None", lambda: flockkit.PointConstraint(agent=0, time=0.0, position=None)),
        ("Ball radius 1e308", lambda: flockkit.Ball(center=[0.0, 0.0], radius=1e308)),
        ("Polygon closed", lambda: flockkit.Polygon(vertices=[*POLYGON, POLYGON[0]])),
        ("Polygon repeated vertex", lambda: flockkit.Polygon(vertices=[POLYGON[0], *POLYGON])),
        ("Polygon at 1e200", lambda: flockkit.Polygon(vertices=np.array(POLYGON) * 1e200)),
        ("solve thin polygon", lambda: flockkit.solve(_shape_problem([[0, 0], [4, 4], [4, 4.00000001]]), iterations=1)),
        ("Alignment distance 'abc'", lambda: flockkit.Alignment(distance="abc", assignment=[0], rotation=np.eye(2),
                                                                translation=[0, 0])),
        ("Walk edges [5]", lambda: flockkit.Walk(start=0, edges=[5])),
        ("Box.contains('ab')", lambda: flockkit.Box(lower=[0, 0], upper=[1, 1]).contains("ab")),
        ("Motion[::0]", lambda: motion[::0]),
        ("read_long frame 1e20", lambda: fio.read_long(table("huge.csv", "0,0,1,1\n1e20,0,2,2\n"), fps=10)),
        ("read_long frame jump to 1e9", lambda: fio.read_long(table("jump.csv", JUMP), fps=10)),
        ("read_long repeated row", lambda: fio.read_long(table("twice.csv", "0,0,1,1\n0,0,2,2\n1,0,3,3\n"), fps=10)),
        ("read_wide agents [5]", lambda: fio.read_wide(table("wide.csv", WIDE), fps=10, agents=[5])),
        ("read_wide agents [-1]", lambda: fio.read_wide(table("wide2.csv", WIDE), fps=10, agents=[-1])),
        ("read_wide repeated frame", lambda: fio.read_wide(table("wide3.csv", "0,1,1\n0,2,2\n1,3,3\n"), fps=10)),
        ("load a folder", lambda: flockkit.Motion.load(tmp)),
        ("load /dev/null", lambda: flockkit.Motion.load("/dev/null")),
    ]  # fmt: skip


def bom_table(tmp):
    """A headerless CSV starting with a UTF-8 byte-order mark: its first row must be read."""
    path = tmp / "bom.csv"
    path.write_bytes("\ufeff0,0,1.0,1.0\n1,0,2.0,2.0\n2,0,3.0,3.0\n".encode())
    return path


RESERVED = ("dt", "n_agents", "seed", "dims", "progress", "behavior")  # simulate's own arguments


def cli(tmp) -> list[tuple[str, list[str]]]:
    """(name, argv) for every CLI invocation the review found ending in a traceback or a silent
    success; files they need are made in `tmp`."""
    motion = tmp / "m.npz"
    flockkit.simulate(n_agents=5, steps=150, seed=1).save(motion)
    graph = tmp / "g.npz"
    flockkit.build_graph(flockkit.Motion.load(motion), seed=0).save(graph)
    infeasible = tmp / "fast.toml"
    infeasible.write_text(
        "[problem]\nagents = 4\nduration = 2.0\n[solve]\niterations = 0\n"
        "[[point]]\nagent = 0\ntime = 2.0\nposition = [0.0, 0.0]\nvelocity = [1.0, 0.0]\n"
        "[[shape]]\ntime = 2.0\nvelocity = [1.0, 0.0]\nbox = {lower = [100.0, 100.0], upper = [101.0, 101.0]}\n"
    )
    bad_seeds = tmp / "seed.toml"
    bad_seeds.write_text("[problem]\nagents = 3\nduration = 1.0\ndims = 2.0\n[solve]\nseed = 'x'\n")
    out = str(tmp / "out.npz")
    sim = ["simulate", "--agents", "3", "--steps", "5", "-o", out]
    return [
        ("simulate --seed -1", [*sim, "--seed", "-1"]),
        ("walk --seed -1", ["walk", str(graph), "--duration", "5", "--seed", "-1", "-o", out]),
        ("solve --seed -1", ["solve", str(infeasible), "--seed", "-1", "-o", out]),
        ("solve --starts 0", ["solve", str(infeasible), "--starts", "0", "-o", out]),
        *((f"simulate --param {k}", [*sim, "--param", f"{k}=5"]) for k in RESERVED),
        ("simulate --param obstacles=5", [*sim, "--param", "obstacles=5"]),
        ("build --param metric", ["build", str(motion), "-o", str(tmp / "g2.npz"), "--param", "metric=x"]),
        ("walk --param duration", ["walk", str(graph), "--duration", "5", "--param", "duration=3", "-o", out]),
        ("simulate --dt 1e300", ["simulate", "--agents", "5", "--steps", "20", "--dt", "1e300", "-o", out]),
        ("simulate --steps 1e8", ["simulate", "--agents", "20", "--steps", "100000000", "-o", out]),
        ("walk --duration 1e9", ["walk", str(graph), "--duration", "1e9", "-o", out]),
        ("scenario with dims 2.0 and seed 'x'", ["solve", str(bad_seeds), "-o", out]),
        ("build from a folder", ["build", str(tmp), "-o", str(tmp / "g3.npz")]),
        ("info /dev/null", ["info", "/dev/null"]),
        ("build -o /proc/g.npz", ["build", str(motion), "-o", "/proc/g.npz"]),
        ("build -o a folder", ["build", str(motion), "-o", str(tmp)]),
        ("solve an infeasible scenario", ["solve", str(infeasible), "-o", out]),
    ]  # fmt: skip
