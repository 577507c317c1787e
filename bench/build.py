"""Motion-graph build time: prune=False against the default (pruned), same recording, one run.

    python bench/build.py [--candidates 2000] [--agents 20] [--jobs 2]
    python bench/build.py --growth 1000 2000 4000 [--agents 20] [--jobs 2] [--progress]

Records boids (2D) long enough for the given number of candidate frames (one every 0.2 s), builds
with prune=False and with the default, checks that both graphs are identical, and prints the
seconds, the exact evaluations each needed and the speed-up. Target (issue 3): at 2 000 candidates
the pruned build >= 10x faster.

With --growth, only the pruned build, at each size in turn (a recording of its own): seconds,
exact evaluations, the exponents of both against the size before (time ~ size^exponent), and the
process's peak resident memory so far (the matrix lives in this process; workers get chunks).
Targets (issue 19): exponent <= 1.3; one hour (18 000 candidates) in one pass, memory linear.
"""

from __future__ import annotations

import argparse
import math
import resource
import time

import numpy as np

import flockkit


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--candidates", type=int, default=2000)
    parser.add_argument("--agents", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--growth", type=int, nargs="+", help="pruned builds only, at these numbers of candidates")
    parser.add_argument("--progress", action="store_true", help="draw the build's progress bars (--growth)")
    args = parser.parse_args()
    if args.growth:
        return growth(args)
    steps = args.candidates * 2 + 25  # a candidate every 2 frames, plus room for the last blend
    recording = flockkit.simulate(n_agents=args.agents, steps=steps, seed=1)
    metric = flockkit.get("metric", "icp-hungarian")
    results = {}
    for prune in (False, True):
        builder = flockkit.get("builder", "kovar", prune=prune, n_jobs=args.jobs)
        begin = time.perf_counter()
        graph = builder.build(recording, metric, np.random.default_rng(0))
        results[prune] = (time.perf_counter() - begin, graph)
    (full_time, full), (pruned_time, pruned) = results[False], results[True]
    same = (
        list(full.nodes) == list(pruned.nodes) and full.clips == pruned.clips and full.transitions == pruned.transitions
    )
    cells = pruned.params["candidates"] * (pruned.params["candidates"] - 1) // 2
    print(
        f"{args.agents} agents, {pruned.params['candidates']} candidates ({cells} cells), n_jobs={args.jobs}; "
        f"threshold {pruned.params['threshold']:.4g}, {len(pruned.transitions)} transitions; identical graphs: {same}"
    )
    print(f"prune=False: {full_time:.1f} s, {full.params['evaluated']} exact evaluations")
    print(
        f"default    : {pruned_time:.1f} s, {pruned.params['evaluated']} exact evaluations "
        f"({full_time / pruned_time:.2f}x faster)"
    )


def growth(args):
    print(f"{args.agents} agents, n_jobs={args.jobs}, pruned builds")
    print(f"{'candidates':>10} {'seconds':>8} {'evaluations':>12} {'time exp':>8} {'eval exp':>8} {'peak MB':>8}")
    before = None
    for candidates in args.growth:
        recording = flockkit.simulate(n_agents=args.agents, steps=candidates * 2 + 25, seed=1)
        begin = time.perf_counter()
        graph = flockkit.build_graph(recording, n_jobs=args.jobs, progress=args.progress, seed=0)
        seconds = time.perf_counter() - begin
        k, evaluated = graph.params["candidates"], graph.params["evaluated"]
        exponents = ("", "")
        if before is not None:
            scale = math.log(k / before[0])
            exponents = [f"{math.log(now / then) / scale:.2f}" for now, then in zip((seconds, evaluated), before[1:])]
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{k:>10} {seconds:>8.1f} {evaluated:>12} {exponents[0]:>8} {exponents[1]:>8} {peak:>8.0f}", flush=True)
        before = (k, seconds, evaluated)


if __name__ == "__main__":
    main()
