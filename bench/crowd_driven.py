"""A crowd driven by a boids simulation: the whole pipeline, simulation to poses, beside a direct
evaluation of every agent's own clip.

    python bench/crowd_driven.py [--agents 10000] [--seconds 60] [--fps 30]
    python bench/crowd_driven.py --quick     # 2 000 agents, 10 s

A 2D boids flock of N agents is simulated for the given seconds at the given frame rate; a crowd of N
walkers (`flockkit.testing.inputs.walker`) follows it through a `Driver`: four streams (idle, and
the walk at three playback rates matched to speed) and a Stopped "cheer" stream that half the
crowd plays for 4 s from the middle of the run (a cue, with 2 s of time dilation). It prints the
seconds of the simulation and of the crowd runtime (`Driver.step`: states, transitions, roots,
`Crowd.update`; no per-agent pose), per frame and their shares.

Then, every frame of the same run, every agent's local pose two ways: flockkit's `update` +
`poses()`, and a vectorized numpy direct evaluation of each agent's own clip at its own time,
the agents in transition blending two (`crowd.Direct`, the strongest baseline we know without
shared streams), checked equal to `poses()` every 10th frame. Target: the crowd runtime costs
less than the simulation that drives it.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from crowd import Direct, Gaps, part_state, reading_between  # bench/crowd.py: the scripts run from bench/

import flockkit
from flockkit.crowd import Crowd, Cue, Driver, Gait, StateMachine, Stream, StreamPool, ground_speed
from flockkit.testing import inputs


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=10_000)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--quick", action="store_true", help="2 000 agents for 10 s")
    args = parser.parse_args()
    if args.quick:
        args.agents, args.seconds = 2000, 10.0
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
    setup = time.perf_counter() - begin
    update = crowd.update
    spent = {"update": 0.0}

    def timed_update(*a, **k):  # Driver.step calls it: its share of the step
        start = time.perf_counter()
        result = update(*a, **k)
        spent["update"] += time.perf_counter() - start
        return result

    crowd.update = timed_update
    direct, agents, joints = Direct(crowd.pool), np.arange(n), walker.skeleton.n_joints
    steps, ours, theirs, gaps = [], [], [], Gaps()
    for frame in range(frames):
        begin = time.perf_counter()
        driver.step()
        steps.append(time.perf_counter() - begin)
        begin = time.perf_counter()
        mine = crowd.poses(agents, "body")
        ours.append(time.perf_counter() - begin)
        state = part_state(crowd, agents, "body")  # what a direct system keeps per agent: not timed
        clock, now = crowd.pool.clock.copy(), crowd.time
        begin = time.perf_counter()
        other = direct.poses(clock, now, state, joints)
        theirs.append(time.perf_counter() - begin)
        if frame % 10 == 0:
            gaps.add(mine, other, *reading_between(direct, clock, state))
    runtime, updates = sum(steps), spent["update"]
    ours, theirs = np.array(ours) * 1000, np.array(theirs) * 1000
    gaps.check()

    total = simulation + runtime
    per = lambda seconds: seconds / frames * 1000  # noqa: E731 - ms per frame
    print(f"{n} agents, {args.seconds:g} s at {args.fps:g} fps ({frames} frames), 5 streams, a cheer cue for half; "
          f"crowd set up in {setup:.1f} s")  # fmt: skip
    print(f"boids simulation: {simulation:.1f} s ({per(simulation):.2f} ms per frame, {simulation / total:.0%})")
    print(f"crowd runtime (Driver.step: states, transitions, roots, update; no per-agent pose): {runtime:.1f} s "
          f"({per(runtime):.2f} ms per frame, {runtime / total:.0%}), of which Crowd.update {per(updates):.2f} ms; "
          f"{driver.switches} stream switches")  # fmt: skip
    produced = per(updates) + ours.mean()
    print(f"every agent's local pose, per frame ({n} agents x {joints} joints; mean over {frames} frames):")
    print(f"  flockkit update + poses(): {per(updates):.2f} + {ours.mean():.2f} = {produced:.2f} ms")
    print(f"  direct numpy evaluation of each agent's own clip: {theirs.mean():.2f} ms; "
          f"direct / flockkit = {theirs.mean() / produced:.2f}")  # fmt: skip
    print(gaps.report("agent-frames (every 10th frame)"))
    print(f"target (crowd runtime < simulation): {'met' if runtime < simulation else 'NOT met'}; with every "
          f"agent's pose (+ poses()): {'met' if runtime + ours.sum() / 1000 < simulation else 'NOT met'}")  # fmt: skip


if __name__ == "__main__":
    main()
