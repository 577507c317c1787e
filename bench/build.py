"""Motion-graph build time: prune=False against the default (pruned), on the same recordings.

    python bench/build.py [--candidates 300 600 1000 2000] [--agents 20] [--jobs 2]
    python bench/build.py --agents 20 50 100 --candidates 290          # 60 s recordings
    python bench/build.py --growth 1000 2000 4000 8000 [--agents 20] [--jobs 2] [--progress]

For each number of agents and of candidate frames (one every 0.2 s), records a boids flock (2D,
default parameters, seed 1), builds its graph with prune=False and with the default, checks that
both graphs are identical and prints one row: seconds and exact evaluations (both triangles of the
symmetric matrix) of each, and the speed-up. Targets (issue 19): >= 10x from 1 000 candidates up;
a 60 s recording of 100 agents pruned in <= 10 s.

With --growth, only the pruned build, at each size in turn (a recording of its own): seconds,
exact evaluations, the exponents of both against the size before and from the first size (time ~
size^exponent), and the process's peak resident memory so far (the matrix lives in this process;
workers get chunks). Targets (issue 19): exponent <= 1.3; one hour (18 000 candidates) in one
pass, memory linear.

Before anything is timed, a small build starts the workers and loads the compiled code, so that
no row pays for them.
"""

from __future__ import annotations

import argparse
import math
import resource
import time

import flockkit


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--candidates", type=int, nargs="+", default=[2000])
    parser.add_argument("--agents", type=int, nargs="+", default=[20])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--growth", type=int, nargs="+", help="pruned builds only, at these numbers of candidates")
    parser.add_argument("--progress", action="store_true", help="draw the build's progress bars (--growth)")
    args = parser.parse_args()
    build(recording(20, 300), prune=True, jobs=args.jobs)  # workers started, compiled code loaded
    if args.growth:
        return growth(args)
    print(f"n_jobs={args.jobs}; boids (2D), one candidate every 0.2 s; seconds and exact evaluations")
    print(
        f"{'agents':>6} {'candidates':>10} {'threshold':>9} {'transitions':>11} {'identical':>9} "
        f"{'full s':>8} {'full evals':>10} {'pruned s':>8} {'pruned evals':>12} {'speed-up':>8}"
    )
    for agents in args.agents:
        for candidates in args.candidates:
            motion = recording(agents, candidates)
            (full_time, full), (pruned_time, pruned) = (build(motion, prune, args.jobs) for prune in (False, True))
            same = (
                list(full.nodes) == list(pruned.nodes)
                and full.clips == pruned.clips
                and full.transitions == pruned.transitions
            )
            print(
                f"{agents:>6} {pruned.params['candidates']:>10} {pruned.params['threshold']:>9.4g} "
                f"{len(pruned.transitions):>11} {str(same):>9} {full_time:>8.1f} {full.params['evaluated']:>10} "
                f"{pruned_time:>8.1f} {pruned.params['evaluated']:>12} {full_time / pruned_time:>7.2f}x",
                flush=True,
            )


def recording(agents: int, candidates: int) -> flockkit.Motion:
    """A boids flock long enough for `candidates` candidate frames (one every 2 frames, plus room
    for the last blend)."""
    return flockkit.simulate(n_agents=agents, steps=candidates * 2 + 25, seed=1)


def build(motion, prune: bool, jobs: int, progress: bool = False):
    """(seconds, graph) of kovar with icp-hungarian."""
    begin = time.perf_counter()
    graph = flockkit.build_graph(motion, prune=prune, n_jobs=jobs, progress=progress, seed=0)
    return time.perf_counter() - begin, graph


def growth(args):
    agents = args.agents[0]
    print(f"{agents} agents, n_jobs={args.jobs}, pruned builds")
    print(
        f"{'candidates':>10} {'seconds':>8} {'evaluations':>12} {'time exp':>8} {'eval exp':>8} "
        f"{'from first':>10} {'peak MB':>8}"
    )
    first = before = None
    for candidates in args.growth:
        seconds, graph = build(recording(agents, candidates), True, args.jobs, progress=args.progress)
        now = (graph.params["candidates"], seconds, graph.params["evaluated"])
        exponents = [f"{_exponent(now, then, field):.2f}" if then else "" for then, field in
                     ((before, 1), (before, 2), (first, 1))]  # fmt: skip
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(
            f"{now[0]:>10} {seconds:>8.1f} {now[2]:>12} {exponents[0]:>8} {exponents[1]:>8} {exponents[2]:>10} "
            f"{peak:>8.0f}",
            flush=True,
        )
        first, before = first or now, now


def _exponent(now, then, field: int) -> float:
    """The exponent of growth of `field` (1: seconds, 2: evaluations) from `then` to `now`."""
    return math.log(now[field] / then[field]) / math.log(now[0] / then[0])


if __name__ == "__main__":
    main()
