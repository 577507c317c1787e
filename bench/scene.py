"""Scenes of many duplicates (paper 002, sections 5-6): seconds to place, walk and de-synchronise
N objects of a 1 000-point template in 2 parts for 2 minutes at 30 fps, per object (wall, and
CPU of this process and its workers), and peak memory; with --backend dask, the same on a local
Dask cluster through joblib.

    python bench/scene.py --objects 100 200 --jobs 2
    python bench/scene.py --objects 100 --jobs 2 --backend dask
"""

from __future__ import annotations

import argparse
import contextlib
import os
import resource

import joblib
import numpy as np
from scene_assets import cpu_seconds
from timing import timed

import flockkit
from flockkit.scene import Arrow, FlowField
from flockkit.testing import inputs


def template():
    # flutter periods of whole frames at 30 fps, and transitions enough that each part's graph
    # keeps the whole cycle of wind directions (with fewer, a part keeps one hold and cannot turn)
    motion, labels, wind = inputs.plants(dt=1 / 30, seconds=24.0, points=500, rates=(1.5, 3.0))
    segmentation = flockkit.Segmentation(labels=labels, n_parts=2)
    return flockkit.build_layers(motion, segmentation=segmentation, features=wind, seed=1, transitions_per_minute=2000)


def following(scene, animation, layers) -> float:
    """The share of (object, frame) pairs on which every part plays an arrow within 0.2 of the
    object's target (turned into the world)."""
    targets, frames = scene.targets(animation.placement), animation.source_frames()
    within = []
    for i, heading in enumerate(animation.placement.headings):
        c, s = np.cos(heading), np.sin(heading)
        played = np.zeros((*frames[i].shape, 3))
        played[..., :2] = layers.features.vectors[frames[i]][..., :2] @ np.array([[c, -s], [s, c]]).T
        within.append(np.linalg.norm(played - targets[i][None], axis=2).max(axis=0) <= 0.2)
    return float(np.mean(within))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", type=int, nargs="+", default=[100, 200])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--backend", choices=("loky", "dask"), default="loky")
    args = parser.parse_args()
    layers, build = timed(template)
    print(f"template: {layers.source.n_agents} points in {layers.n_parts} parts, built in {build:.1f} s")
    flow = FlowField(arrows=[Arrow(position=[0, 0], keyframes=[(0, [0.8, 0]), (60, [0.8, 0]), (62, [0, 0.8])])])
    print("| objects | seconds | per object (ms) | CPU per object (ms) | frames within 0.2 | in step before / after "
          "| walked again | peak RSS (MiB) | load average |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    for count in args.objects:
        side = 6.0 * np.sqrt(count)
        region = flockkit.Polygon(vertices=[[-side, -side], [side, -side], [side, side], [-side, side]])
        scene = flockkit.Scene(templates=[layers], region=region, counts=[count], duration=120, constraints=[flow],
                               seed=1, headings="aligned", n_jobs=args.jobs)  # fmt: skip
        if args.backend == "dask":
            from dask.distributed import Client

            backend = contextlib.ExitStack()
            backend.enter_context(Client(n_workers=args.jobs, threads_per_worker=1))
            backend.enter_context(joblib.parallel_config("dask", n_jobs=args.jobs))
        else:
            backend = contextlib.nullcontext()
        with backend:
            cpu = cpu_seconds()
            animation, seconds = timed(scene.synthesize)
            cpu = cpu_seconds() - cpu
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        report = animation.report
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
        print(f"| {count} | {seconds:.1f} | {1000 * seconds / count:.0f} | {1000 * cpu / count:.0f} | "
              f"{following(scene, animation, layers):.1%} | {report['in_step_before']:.1%} / "
              f"{report['in_step_after']:.1%} | {report['walked_again']} | {peak:.0f} | {load} |")  # fmt: skip


if __name__ == "__main__":
    main()
