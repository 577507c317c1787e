"""Region walks on short recordings, with and without solver-made bridges.

    python bench/bridges.py [--first 1] [--last 20] [--seconds 60]

Per seed s: a default 20-boid flock simulated for `--seconds` (seed s); its default kovar graph
(seed s) and the same with ``bridges=True`` (solver-made transitions: flockkit.graphs.bridge along
flockkit.graphs.bridge_plan, with kovar's turns over the frames they join); and on each a region
walk of 300 s (seed s) in a box 40 units across centred on the group's start, synthesized.

Printed per seed: whether each walk kept the group inside for 300 s (the baseline is the graph
without bridges, in the same run); the stretches the solver made of those it tried and the range
of their log plausibility per agent-step (a forward boids simulation scores about +0.67; refused
below BRIDGE_PLAUSIBILITY); how many output frames of the bridged walk play a made stretch or blend
into or out of one, the largest step there and over the whole walk, each over the recording's
largest step (the quality bar is 1.5); and the seconds each graph took to build (the bridged one:
everything, bridges included).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import flockkit
from flockkit.errors import FlockkitWarning, ValidationError


def region_walk(graph, region, seed):
    """The walk, or None where the walk is refused."""
    try:
        return flockkit.walk(graph, strategy="region", region=region, duration=300, seed=seed)
    except ValidationError:
        return None


def steps(positions) -> np.ndarray:
    """The largest step of any agent between each frame and the next (F - 1,)."""
    return np.linalg.norm(np.diff(positions, axis=0), axis=-1).max(axis=1)


def timed_build(recording, seed, **options):
    began = time.perf_counter()
    graph = flockkit.build_graph(recording, seed=seed, n_jobs=1, **options)
    return graph, time.perf_counter() - began


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first", type=int, default=1)
    parser.add_argument("--last", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    warnings.simplefilter("ignore", FlockkitWarning)
    seeds = range(args.first, args.last + 1)
    print(f"20 boids, {args.seconds:g} s recordings, region walks of 300 s in a box 40 units across")
    print("seed  plain  bridged  made/tried  log g per agent-step  bridge frames  step/source: bridges  walk"
          "  build s: plain  bridged")  # fmt: skip
    plain_ok = bridged_ok = 0
    worst_through, worst_walk, scores = 0.0, 0.0, []
    for seed in seeds:
        recording = flockkit.simulate(n_agents=20, steps=round(args.seconds / 0.1), seed=seed)
        source_step = steps(recording.positions).max()
        start = recording.center_of_mass()[0]
        region = flockkit.Box(lower=start - 20, upper=start + 20)
        plain, plain_seconds = timed_build(recording, seed)
        bridged, bridged_seconds = timed_build(recording, seed, bridges=True)
        stretches = bridged.params["bridges"]["stretches"]
        made = [s["log_plausibility"] for s in stretches if s["made"]]
        scores += made
        walked_plain = region_walk(plain, region, seed)
        walk = region_walk(bridged, region, seed)
        plain_ok += walked_plain is not None
        bridged_ok += walk is not None
        through = whole = "-"
        playing = 0
        if walk is not None:
            step = steps(flockkit.synthesize(bridged, walk).positions)
            first = bridged.params.get("bridge_frames", bridged.motion.n_frames)
            into, out_of, _ = flockkit.graphs.blended_frames(bridged, walk)
            bridging = (into >= first) | (out_of >= first)
            playing = int(bridging.sum())
            near = bridging[1:] | bridging[:-1]  # a step into, within or out of a bridge's frames
            whole = step.max() / source_step
            worst_walk = max(worst_walk, whole)
            whole = f"{whole:.3f}"
            if near.any():
                ratio = step[near].max() / source_step
                worst_through = max(worst_through, ratio)
                through = f"{ratio:.3f}"
        span = f"{min(made):6.1f} .. {max(made):5.1f}" if made else "-"
        print(f"{seed:4d}  {'ok' if walked_plain is not None else 'FAIL':>5}  {'ok' if walk is not None else 'FAIL':>7}"
              f"  {len(made):4d}/{len(stretches):<5d}  {span:>20}  {playing:13d}  {through:>20}  {whole:>5}"
              f"  {plain_seconds:14.1f}  {bridged_seconds:7.1f}", flush=True)  # fmt: skip
    kept = f"{plain_ok}/{len(seeds)} without bridges, {bridged_ok}/{len(seeds)} with"
    print(f"region walks kept inside for 300 s: {kept}")
    if scores:
        print(f"stretches made: {len(scores)}, log plausibility per agent-step {min(scores):.1f} to {max(scores):.1f} "
              f"(median {np.median(scores):.1f})")  # fmt: skip
    print(f"largest step over the recording's: through bridges {worst_through:.3f}, whole walks {worst_walk:.3f}")


if __name__ == "__main__":
    main()
