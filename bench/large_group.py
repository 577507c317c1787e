"""A large group's motion graph: time and memory (issue 19: 500 agents work at all).

    python bench/large_group.py [--agents 500] [--interval 1.0] [--jobs 2] [--perception 8] [--seconds 50]

Default boids (perception radius 3 m) do not stay one group at 500 agents: the group spreads for
minutes and nothing recurs, so a 20 s recording has no local minimum of E at all and no graph
(``--perception 3 --seconds 20`` measures how long the build takes to say so). By default the
group is recorded with a perception radius of 8 m, under which it gathers into one flock (its
mean squared radius falls from 41 to 11 m^2 in a minute), for 90 s, and its last 50 s are built
with one candidate frame every `--interval` seconds, keeping 10 transitions (the default 30 would
take every local minimum up to the group's mean squared radius). Prints each stage as it starts,
then seconds, exact evaluations (both triangles), transitions, the threshold and this process's
peak resident memory (the matrix lives here; workers get chunks of configurations).
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

import flockkit


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=500)
    parser.add_argument("--interval", type=float, default=1.0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--perception", type=float, default=8.0, help="the boids' perception radius (m)")
    parser.add_argument("--seconds", type=float, default=50.0, help="the last seconds of 90 built from")
    args = parser.parse_args()
    recording = flockkit.simulate(n_agents=args.agents, steps=900, seed=1, perception_radius=args.perception)
    last = round(args.seconds / recording.dt) + 1
    settled = flockkit.Motion(positions=recording.positions[-last:], dt=recording.dt)
    begin, stage = time.perf_counter(), [None]

    def progress(done, total, name):
        if name != stage[0]:
            print(f"{time.perf_counter() - begin:8.1f} s  {name} ({total})", flush=True)
            stage[0] = name

    # 48 candidates cannot keep kovar's default 30 transitions below the group's spread
    builder = flockkit.get(
        "builder",
        "kovar",
        n_jobs=args.jobs,
        candidate_interval=args.interval,
        min_transitions=10,
        transitions_per_minute=10,
    )
    try:
        graph = builder.build(
            settled, flockkit.get("metric", "icp-hungarian"), np.random.default_rng(0), progress=progress
        )
    except flockkit.errors.ValidationError as error:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"no graph after {time.perf_counter() - begin:.1f} s (peak memory {peak:.0f} MB): {error}")
        return
    seconds = time.perf_counter() - begin
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"{args.agents} agents, {graph.params['candidates']} candidates: {seconds:.1f} s, "
        f"{graph.params['evaluated']} exact evaluations, {len(graph.transitions)} transitions "
        f"(threshold {graph.params['threshold']:.4g}), peak memory {peak:.0f} MB"
    )


if __name__ == "__main__":
    main()
