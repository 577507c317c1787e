"""Synthesis from a motion graph against simulating the same motion (paper 000's claim: a tiny
fraction of the cost).

    python bench/synthesis.py [--agents 20] [--seconds 60] [--flocks 1000]

Builds a graph from a boids recording of the same length (build time printed: paid once), then
times (a) one 20-agent flock for 60 s by boids simulation and by synthesizing a random walk,
(b) 1 000 independent flocks: synthesize_many over 1 000 walks against 1 000 boids simulations
(timed over 20 of them and scaled; they are independent).
"""

from __future__ import annotations

import argparse

from timing import timed  # bench/timing.py: the scripts run from bench/

import flockkit


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--flocks", type=int, default=1000)
    args = parser.parse_args()
    steps = round(args.seconds / 0.1)
    recording = flockkit.simulate(n_agents=args.agents, steps=steps, seed=1)
    graph, build = timed(lambda: flockkit.build_graph(recording, seed=1, n_jobs=-1))
    stats = graph.stats()
    print(
        f"graph from {args.seconds:g} s of {args.agents} boids: built in {build:.1f} s (once); "
        f"{stats['transitions']} transitions, {stats['fraction_kept']:.0%} of frames kept"
    )

    walk = flockkit.walk(graph, duration=args.seconds, seed=2)
    _, one_sim = timed(lambda: flockkit.simulate(n_agents=args.agents, steps=steps, seed=3), repeat=5)
    _, one_syn = timed(lambda: flockkit.synthesize(graph, walk), repeat=20)
    print(
        f"one flock, {args.seconds:g} s (best of repeats): simulate {one_sim * 1e3:.1f} ms, synthesize "
        f"{one_syn * 1e3:.2f} ms = {one_syn * 1e3 / args.seconds:.4f} ms per second of output "
        f"({one_sim / one_syn:.0f}x cheaper)"
    )

    walks = [flockkit.walk(graph, duration=args.seconds, seed=s) for s in range(args.flocks)]
    crowd, many_syn = timed(lambda: flockkit.synthesize_many(graph, walks))
    sample = 20
    _, sims = timed(lambda: [flockkit.simulate(n_agents=args.agents, steps=steps, seed=s) for s in range(sample)])
    many_sim = sims / sample * args.flocks
    print(
        f"{args.flocks} flocks ({crowd.n_agents} agents, {crowd.n_frames} frames): synthesize_many {many_syn:.2f} s "
        f"= {crowd.n_frames / many_syn:.0f} output frames per second, {args.flocks * crowd.n_frames / many_syn:.0f} "
        "flock-frames "
        f"per second; simulate {many_sim:.1f} s (from {sample} runs) ({many_sim / many_syn:.0f}x cheaper)"
    )


if __name__ == "__main__":
    main()
