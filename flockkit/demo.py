"""``flockkit demo``: the tour of both papers, writing pictures, animations and a summary.

1. simulate a 20-agent flock turning inside an arena (a fence of round obstacles), 60 s;
2. build its motion graph, and draw the difference matrix with the chosen transitions marked,
   and the graph;
3. synthesize 2 minutes of motion kept inside a box by a region walk;
4. solve the come-from-behind scenario (paper 004, Figure 5) and draw its sampler trace;
5. with the shared captures present, build a graph from the five sticklebacks and walk it.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .constraints import Ball, Box, ComConstraint, PointConstraint, Problem
from .convenience import build_graph, simulate, walk
from .errors import ValidationError
from .synthesis import synthesize

STICKLEBACKS = Path("sticklebacks-5") / "ground_truth.csv"


def come_from_behind() -> Problem:
    """Paper 004, Figure 5: agent 0 starts behind the flock and is in front of it 6 s later."""
    rest = list(range(1, 20))
    return Problem(n_agents=20, duration=8.0, constraints=[
        PointConstraint(agent=0, time=1.0, position=[-2.5, 0.0], velocity=[1.3, 0.0]),
        ComConstraint(agents=rest, time=1.0, position=[0.0, 0.0], velocity=[1.0, 0.0]),
        PointConstraint(agent=0, time=7.0, position=[9.0, 0.0], velocity=[1.3, 0.0]),
        ComConstraint(agents=rest, time=7.0, position=[6.0, 0.0], velocity=[1.0, 0.0]),
    ])


def difference_matrix(motion, *, interval: float, metric: str = "icp-hungarian"):
    """E between frames `interval` seconds apart, (K, K), and the frame stride used."""
    from scipy.spatial.distance import squareform

    from .registry import get

    stride = max(1, round(interval / motion.dt))
    configurations = [motion.configuration(t) for t in range(0, motion.n_frames, stride)]
    return squareform(get("metric", metric).pairwise(configurations)), stride


def shared_data_folder(given=None) -> Path | None:
    """`given`, else ../shared/data beside the working folder or beside this checkout."""
    candidates = [Path(given)] if given else [Path.cwd().parent / "shared" / "data", Path(__file__).resolve().parents[2] / "shared" / "data"]
    for folder in candidates:
        if (folder / STICKLEBACKS).is_file():
            return folder
    if given:
        raise ValidationError(f"--data {given}: no {STICKLEBACKS} there")
    return None


def run_demo(out, *, data=None, progress=False, report=print) -> dict:
    """Run the demo into folder `out` (created if needed); return the summary it writes."""
    from . import viz

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    timings, written = {}, []

    def step(name):
        timings[name] = time.perf_counter()

    def done(name):
        timings[name] = round(time.perf_counter() - timings[name], 2)

    def wrote(path):
        written.append(str(path))
        return path

    fence = [Ball(center=[15 * np.cos(a), 15 * np.sin(a)], radius=2.2) for a in np.linspace(0, 2 * np.pi, 24, endpoint=False)]
    step("simulate 60 s of 20 boids")
    recording = simulate(n_agents=20, steps=600, seed=1, obstacles=fence)
    done("simulate 60 s of 20 boids")
    step("build the motion graph")
    graph = build_graph(recording, seed=1, n_jobs=-1, progress=progress)
    done("build the motion graph")
    viz.plot_motion(recording, wrote(out / "recording.png"), obstacles=fence, title="the recording: 20 boids, 60 s")
    values, stride = difference_matrix(recording, interval=0.5)
    marked = [(t.start // stride, t.end // stride) for t in graph.transitions]
    viz.plot_difference_matrix(values, wrote(out / "difference-matrix.png"), marked=marked,
                               title="E, frames 0.5 s apart (circles: transitions)")
    viz.plot_graph(graph, wrote(out / "graph.png"))

    com = recording.center_of_mass()
    low, high = com.min(axis=0), com.max(axis=0)
    box = Box(lower=(low + high) / 2 - 1.5 * (high - low), upper=(low + high) / 2 + 1.5 * (high - low))
    step("synthesize 2 min in a box")
    synthesized = synthesize(graph, walk(graph, strategy="region", region=box, duration=120, seed=2))
    done("synthesize 2 min in a box")
    viz.plot_motion(synthesized, wrote(out / "synthesized.png"), regions=[box], title="2 minutes synthesized, kept in the box")
    viz.animate(synthesized, wrote(out / "synthesized.gif"), regions=[box], progress=progress)

    from .solve import solve

    problem = come_from_behind()
    step("solve come-from-behind")
    solution = solve(problem, iterations=1000, seed=2, progress=progress)
    done("solve come-from-behind")
    viz.plot_motion(solution.motion, wrote(out / "come-from-behind.png"), problem=problem, title="come from behind to win (paper 004, Fig. 5)")
    viz.animate(solution.motion, wrote(out / "come-from-behind.gif"), problem=problem, progress=progress)
    viz.plot_trace(solution, wrote(out / "trace.png"))

    summary = {
        "graph": graph.stats(),
        "synthesized": {"seconds": synthesized.duration, "agents": synthesized.n_agents, "center of mass in the box": bool(box.contains(synthesized.center_of_mass()).all())},
        "come-from-behind": {"log g": solution.log_g[0], "residuals": list(solution.residuals), "acceptance": solution.acceptance},
    }
    folder = shared_data_folder(data)
    if folder is None:
        summary["sticklebacks"] = "skipped: ../shared/data/sticklebacks-5 not found (use --data)"
    else:
        from .io import read_wide

        fish = read_wide(folder / STICKLEBACKS, fps=15)
        step("sticklebacks graph and 60 s walk")
        fish_graph = build_graph(fish, seed=0)
        fish_walk = synthesize(fish_graph, walk(fish_graph, duration=60, seed=3))
        done("sticklebacks graph and 60 s walk")
        viz.plot_motion(fish_walk, wrote(out / "sticklebacks.png"), title="60 s synthesized from 20 s of five sticklebacks")
        viz.animate(fish_walk, wrote(out / "sticklebacks.gif"), progress=progress)
        summary["sticklebacks"] = fish_graph.stats()
    summary["seconds"] = timings
    summary_path = wrote(out / "summary.json")
    summary_path.write_text(json.dumps(summary, indent=2, default=float))
    for path in written:
        report(f"wrote {path}")
    return summary
