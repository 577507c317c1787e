"""Region walks on short recordings, with and without solver-made bridges.

    python bench/bridges.py [--seeds 20] [--seconds 60]

Per seed s: a default 20-boid flock simulated for `--seconds` (seed s), its default kovar graph
(seed s), and a region walk of 300 s (seed s) in a box 40 units across centred on the group's
start; then the same graph bridged (``flockkit.graphs.bridge`` along ``bridge_plan``, boids) and
the same walk. Prints per seed whether each walk succeeded, the stretches tried and made, the time
to make them, and the largest step of the bridged walk over the recording's largest; then the
totals.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import flockkit
from flockkit.errors import FlockkitWarning, ValidationError


def region_walk(graph, region, seed):
    """The walk's motion, or None where the walk is refused."""
    try:
        return flockkit.synthesize(graph, flockkit.walk(graph, strategy="region", region=region, duration=300,
                                                        seed=seed))  # fmt: skip
    except ValidationError:
        return None


def largest_step(positions) -> float:
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=-1).max())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    warnings.simplefilter("ignore", FlockkitWarning)
    before = after = 0
    ratios, times, made_total = [], [], 0
    for seed in range(args.seeds):
        recording = flockkit.simulate(n_agents=20, steps=round(args.seconds / 0.1), seed=seed)
        graph = flockkit.build_graph(recording, seed=seed, n_jobs=1)
        start = recording.center_of_mass()[0]
        region = flockkit.Box(lower=start - 20, upper=start + 20)
        plain = region_walk(graph, region, seed)
        began = time.perf_counter()
        bridged = flockkit.graphs.bridge(graph, flockkit.graphs.bridge_plan(graph), behavior="boids", seed=seed)
        took = time.perf_counter() - began
        stretches = bridged.params["bridges"]["stretches"]
        made = sum(s["made"] for s in stretches)
        walked = region_walk(bridged, region, seed)
        ratio = largest_step(walked.positions) / largest_step(recording.positions) if walked is not None else None
        before, after, made_total = before + (plain is not None), after + (walked is not None), made_total + made
        times.append(took)
        if ratio is not None:
            ratios.append(ratio)
        shown = "-" if ratio is None else f"{ratio:.3f}"
        verdict = f"plain {'ok' if plain is not None else 'FAIL'}, bridged {'ok' if walked is not None else 'FAIL'}"
        print(f"seed {seed:2d}: {verdict}; {made}/{len(stretches)} stretches made in {took:.1f} s; "
              f"largest step ratio {shown}", flush=True)  # fmt: skip
    print(f"region walks succeeded: {before}/{args.seeds} without bridges, {after}/{args.seeds} with them")
    print(f"stretches made: {made_total}; seconds to make a graph's: median {np.median(times):.1f}, "
          f"max {max(times):.1f}")  # fmt: skip
    if ratios:
        print(f"largest step over the recording's: at most {max(ratios):.3f}")


if __name__ == "__main__":
    main()
