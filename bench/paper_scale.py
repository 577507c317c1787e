"""A motion graph at the scale of paper 000's Table 1 (2D, 20 agents, 7 200 transitions: built in
2 200 s, 50 MB there). Target here: < 120 s and < 200 MB.

    python bench/paper_scale.py [--candidates 1300] [--transitions 7200] [--jobs 2]

Records boids long enough for the candidates (one every 0.2 s) and builds with the paper's own rule
(`per_second`: the lowest local minima, as many as wanted), which computes the whole difference
matrix. Prints the build time, the transitions left after dead-end trimming, the saved graph's
size, and the peak memory of the build: its own process, and the largest of its joblib workers.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

import flockkit


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--candidates", type=int, default=1300)
    parser.add_argument("--transitions", type=int, default=7200)
    parser.add_argument("--agents", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    recording = flockkit.simulate(n_agents=args.agents, steps=args.candidates * 2 + 25, seed=1)
    metric = flockkit.get("metric", "icp-hungarian")
    # the lowest minima, a few more than wanted: dead-end trimming removes some
    builder = flockkit.get(
        "builder", "kovar", per_second=1.02 * args.transitions / recording.duration, n_jobs=args.jobs
    )
    begin = time.perf_counter()
    graph = builder.build(recording, metric, np.random.default_rng(0))
    seconds = time.perf_counter() - begin
    from joblib.externals.loky import get_reusable_executor

    get_reusable_executor().shutdown(wait=True)  # so that the workers' peak memory is counted
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "graph.npz"
        graph.save(path)
        size = path.stat().st_size / 2**20
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    worker = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    stats = graph.stats()
    print(
        f"{args.agents} agents, 2D, {graph.params['candidates']} candidates ({recording.duration:.0f} s of "
        f"recording), n_jobs={args.jobs}"
    )
    print(
        f"built in {seconds:.1f} s: {stats['transitions']} transitions, {stats['nodes']} nodes, "
        f"{stats['fraction_kept']:.0%} of frames kept, threshold {graph.params['threshold']:.4g}"
    )
    print(
        f"graph file {size:.1f} MB; peak memory {own:.0f} MB in the build's process, {worker:.0f} MB in the largest "
        "worker"
    )


if __name__ == "__main__":
    main()
