"""Motion-graph build time: prune=False against the default (pruned), same recording, one run.

    python bench/build.py [--candidates 2000] [--agents 20] [--jobs 2]

Records boids (2D) long enough for the given number of candidate frames (one every 0.2 s), builds
with prune=False and with the default, checks that both graphs are identical, and prints the
seconds, the exact evaluations each needed and the speed-up. Target (issue 3): at 2 000 candidates
the pruned build >= 10x faster.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import flockkit


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--candidates", type=int, default=2000)
    parser.add_argument("--agents", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
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


if __name__ == "__main__":
    main()
