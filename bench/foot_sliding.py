"""Foot sliding of Foxes driven by a boids flock: speed-matched playback against fixed-rate.

    python bench/foot_sliding.py [--data ../shared/data] [--agents 60] [--seconds 10]

The Fox (``fox-gltf/Fox.glb``, modelled in centimetres; its joints span 116 units from nose to
tail tip) follows a 2D boids flock (about 1 m/s) at three scales (world metres per Fox unit:
0.78, 1.16 and 1.74 m from nose to tail tip; a red fox is about 1.1 m). Two crowds play its Walk
clip: fixed-rate, one stream at rate 1; speed-matched, 24 streams at rates 0.5 to 3, each agent
on the one whose ground speed (``flockkit.crowd.ground_speed``: how fast the clip pushes its
lowest foot back, times the rate) is nearest its own, switching rates in step
(``Crowd.matching_offsets``). Each runs the Walk as the file has it and planted
(``flockkit.crowd.plant_feet``: each paw, while down, moved back in a line at one speed by
two-joint inverse kinematics). It prints, per clip and scale, the clip's ground speed, the foot
sliding of each (``flockkit.crowd.foot_sliding``: the mean horizontal speed of the lowest foot,
each foot's height counted from its own lowest) and their ratio; and per clip its floor: the
mean deviation of its lowest foot's backward speed from its median, as a share of the median,
which no playback rate removes. Issue 17 asks for a ratio of at least 3.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import flockkit
from flockkit.cli.demo import FOX_FEET as FEET
from flockkit.cli.demo import FOX_LEGS
from flockkit.crowd import driven_sliding, ground_speed, plant_feet


def floor(clip) -> float:
    """The clip's own unevenness: mean |s - median(s)| / median(s) over frames, s the lowest
    foot's backward speed (forward differences between frames with the same lowest foot)."""
    positions = clip.skeleton.positions(flockkit.Pose(rotations=clip.rotations, translations=clip.translations))
    index = [clip.skeleton.index(f) for f in FEET]
    heights = positions[:, index, 1] - positions[:, index, 1].min(axis=0)
    lowest = heights.argmin(axis=1)
    speed = -np.diff(positions[:, index, 2], axis=0)[np.arange(len(lowest) - 1), lowest[:-1]] * clip.fps
    speed = speed[lowest[1:] == lowest[:-1]]
    middle = np.median(speed)
    return float(np.mean(np.abs(speed - middle)) / middle)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    parser.add_argument("--agents", type=int, default=60)
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    fps = 24.0
    raw = flockkit.io.read_clips(Path(args.data) / "fox-gltf" / "Fox.glb")
    flock = flockkit.simulate(n_agents=args.agents, steps=int(args.seconds * fps), dt=1 / fps, seed=1)
    low, high = np.percentile(np.linalg.norm(flock.velocities(), axis=-1), [5, 95])
    print(f"{args.agents} Foxes on a boids flock ({low:.2f}..{high:.2f} m/s), {args.seconds:g} s at {fps:g} fps")
    print(f"{'Walk':>8} {'floor':>6} {'scale':>7} {'ground m/s':>10} {'fixed m/s':>9} {'matched m/s':>11} {'ratio':>6}")
    for name, walk in (("raw", raw["Walk"]), ("planted", plant_feet(raw["Walk"], FOX_LEGS))):
        for scale in (0.0067, 0.01, 0.015):
            natural = ground_speed(walk, FEET, scale=scale)
            fixed = driven_sliding(flock, walk, raw["Survey"], FEET, [1.0], scale=scale)
            matched = driven_sliding(flock, walk, raw["Survey"], FEET, list(np.geomspace(0.5, 3.0, 24)), scale=scale)
            print(f"{name:>8} {floor(walk):>6.1%} {scale:>7} {natural:>10.3f} {fixed:>9.3f} {matched:>11.3f} "
                  f"{fixed / matched:>6.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
