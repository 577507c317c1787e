"""A crowd driven by a boids simulation: the whole pipeline, simulation to poses (issue 17).

    python bench/crowd_driven.py [--agents 10000] [--seconds 60] [--fps 30]

A 2D boids flock of N agents is simulated for the given seconds at the given frame rate; a crowd of N
walkers (`flockkit.testing.inputs.walker`) follows it through a `Driver`: four streams (idle, and
the walk at three playback rates matched to speed) and a Stopped "cheer" stream that half the
crowd plays for 4 s from the middle of the run (a cue, with 2 s of time dilation). It prints the
seconds of the simulation and of the crowd runtime (driver and crowd, every frame), per frame and
their shares, and, in the same run, the cost of every agent evaluating its own clip each frame
(timed on a sample of agents and scaled). Target: the crowd runtime costs less than the
simulation that drives it.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import flockkit
from flockkit.crowd import Crowd, Cue, Driver, Gait, StateMachine, Stream, StreamPool, ground_speed
from flockkit.testing import inputs


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=10_000)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fps", type=float, default=30.0)
    args = parser.parse_args()
    n, frames = args.agents, int(round(args.seconds * args.fps))

    begin = time.perf_counter()
    flock = flockkit.simulate(n_agents=n, steps=frames, seed=1, dt=1.0 / args.fps)
    simulation = time.perf_counter() - begin

    walker = inputs.walker()
    natural = ground_speed(walker, ["foot.L", "foot.R"], up="z", forward="y")
    rates = (0.8, 1.0, 1.25)
    play = lambda **k: flockkit.get("controller", "clip", clip=walker, **k)  # noqa: E731
    streams = [Stream(controller=play(rate=0.1), history=60, name="idle")]
    streams += [Stream(controller=play(rate=r), history=60, name=f"walk x{r}") for r in rates]
    streams.append(Stream(controller=play(rate=2.5), history=90, default="Stopped", name="cheer"))
    walking = Gait(name="walk", streams=[1, 2, 3], speeds=[natural * r for r in rates], low=0.2)
    machine = StateMachine([Gait(name="idle", streams=0, high=0.2), walking])
    cue = Cue(time=args.seconds / 2, agents=np.arange(0, n, 2), stream=4, duration=4.0, time_to_dilate=2.0, name="goal")

    begin = time.perf_counter()
    crowd = Crowd(StreamPool(streams, fps=args.fps), n_agents=n, clusters={"body": 1}, seed=2)
    driver = Driver(crowd, flock, machine, up="z", forward="y", cues=[cue])
    for _ in range(frames):
        driver.step()
    runtime = time.perf_counter() - begin

    sample = [s.controller for s in streams[1:4]] * 500
    begin = time.perf_counter()
    for k, controller in enumerate(sample):
        controller.pose([k / args.fps])
    per_agent = (time.perf_counter() - begin) / len(sample)
    unshared = per_agent * n * frames

    total = simulation + runtime
    print(f"{n} agents, {args.seconds:g} s at {args.fps:g} fps ({frames} frames), 5 streams, a cheer cue for half")
    per_frame = simulation / frames * 1000
    print(f"boids simulation: {simulation:.1f} s ({per_frame:.2f} ms per frame, {simulation / total:.0%})")
    print(f"crowd runtime (driver + crowd): {runtime:.1f} s ({runtime / frames * 1000:.2f} ms per frame, "
          f"{runtime / total:.0%}); {driver.switches} stream switches")  # fmt: skip
    print(f"every agent evaluating its own clip: {per_agent * 1e6:.0f} us per agent-frame x {n} x {frames} = "
          f"{unshared:.0f} s, {unshared / runtime:.0f}x the shared runtime")  # fmt: skip
    print(f"target (crowd runtime < simulation): {'met' if runtime < simulation else 'NOT met'}")


if __name__ == "__main__":
    main()
