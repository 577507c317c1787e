"""Boids forward simulation: milliseconds per step and peak memory, against Mesa's BoidFlockers.

    bench/run                      # makes bench/.venv with mesa 3.3.x, then runs this
    python bench/boids_step.py     # flockkit only, if mesa is not importable

Per N (2D): the mean time of one step over a run (after a warm-up run from the same documented
random flock), the peak memory traced by tracemalloc during a 10-step run and that peak per agent
(constant per agent = memory linear in N), and the mean number of neighbors each agent perceives
(within the perception radius, before the field of view: the work per agent). Mesa's BoidFlockers
runs at its own default density (100 agents per 100 x 100, vision 10), with its width and height
scaled with sqrt(N).
"""

from __future__ import annotations

import argparse
import platform
import time
import tracemalloc

import numpy as np
from scipy.spatial import cKDTree

import flockkit

TARGETS_MS = {100: 0.5, 1000: 5.0, 10000: 60.0}


def flockkit_case(n: int, steps: int):
    model = flockkit.get("behavior", "boids")
    rng = np.random.default_rng(1)
    warm = model.forward(flockkit.random_flock(n_agents=n, rng=rng), 20, rng)
    start = warm.state(-1)
    begin = time.perf_counter()
    motion = model.forward(start, steps, rng)
    per_step = (time.perf_counter() - begin) / steps * 1e3
    tracemalloc.start()
    model.forward(start, 10, rng)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    pairs = cKDTree(motion.positions[-1]).query_pairs(model.perception_radius)
    return per_step, peak, 2 * len(pairs) / n


def mesa_case(n: int, steps: int):
    from mesa.examples.basic.boid_flockers.model import BoidFlockers

    side = int(10 * np.sqrt(n)) + 10
    model = BoidFlockers(population_size=n, width=side, height=side, seed=1)
    for _ in range(3):
        model.step()
    begin = time.perf_counter()
    for _ in range(steps):
        model.step()
    per_step = (time.perf_counter() - begin) / steps * 1e3
    neighbors = (
        np.mean([len(agent.neighbors) for agent in model.agents])
        if hasattr(next(iter(model.agents)), "neighbors")
        else float("nan")
    )
    return per_step, neighbors


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[20, 100, 1000, 10000])
    parser.add_argument("--mesa-max", type=int, default=1000, help="largest N to run Mesa at (it is slow)")
    args = parser.parse_args()
    try:
        import mesa

        mesa_version = mesa.__version__
    except ImportError:
        mesa_version = None
    print(
        f"python {platform.python_version()}, numpy {np.__version__}, flockkit {flockkit.__version__}, "
        f"mesa {mesa_version or 'not installed (run bench/run)'}; {platform.machine()}, {platform.processor() or '?'}"
    )
    header = f"{'N':>6} {'flockkit ms/step':>17} {'target':>7} {'peak MB':>8} {'B/agent':>8} {'neighbors':>9}"
    if mesa_version:
        header += f" {'mesa ms/step':>13} {'mesa nbrs':>9} {'speed-up':>9}"
    print(header)
    for n in args.sizes:
        steps = max(10, min(500, 20000 // n))
        per_step, peak, neighbors = flockkit_case(n, steps)
        target = TARGETS_MS.get(n)
        bar = f"<={target:g}" if target else "-"
        row = f"{n:>6} {per_step:>17.3f} {bar:>7} {peak / 2**20:>8.2f} {peak / n:>8.0f} {neighbors:>9.1f}"
        if mesa_version and n <= args.mesa_max:
            mesa_ms, mesa_neighbors = mesa_case(n, max(5, min(100, 2000 // n)))
            row += f" {mesa_ms:>13.3f} {mesa_neighbors:>9.1f} {mesa_ms / per_step:>8.1f}x"
        print(row, flush=True)


if __name__ == "__main__":
    main()
