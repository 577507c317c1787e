"""How far flockkit's clip sampling is from the file formats' own definitions, per clip.

For every skeletal clip of the glTF files in ../shared/data (Fox, RobotExpressive), of generated
glTF clips (LINEAR, STEP, CUBICSPLINE and a mix, keys at uneven times) and of the CMU BVH take, it
compares the world positions of every joint that ``flockkit.io.read_clips`` + ``clip.sample``
give with those of tests/core/animation_spec.py, an evaluator written from the glTF 2.0
specification (Appendix C) and the BVH definition that shares no code with flockkit. Times: every
key of the clip, the midpoint between consecutive keys, and 200 random times. Errors are the
largest joint distance over those times, absolute and as a share of the skeleton's size (the
diagonal of its joints' bounding box at rest; BVH: over the take).

    python bench/sampling.py [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.append(str(ROOT))  # the reference evaluator lives with the tests

import flockkit  # noqa: E402
from tests.core import animation_spec as spec  # noqa: E402


def _diagonal(points) -> float:
    points = points.reshape(-1, 3)
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def _times(keys, duration, rng):
    keys = np.unique(keys)
    middles = (keys[:-1] + keys[1:]) / 2
    return keys, np.concatenate([middles, rng.uniform(0, duration, 200)])


def gltf_rows(path, label, rng):
    gltf = spec.GltfAnimation(path)
    rows = []
    for name, clip in flockkit.io.read_clips(path).items():
        animation = gltf.names.index(name.rpartition("/")[2])
        nodes = [spec.node_of(gltf, n) for n in clip.skeleton.names]
        rest = gltf.world(None, np.zeros(1))
        size = _diagonal(np.array([rest[n][0, :3, 3] for n in nodes]))
        found = []
        for times in _times(gltf.key_times(animation), gltf.duration(animation), rng):
            ours = clip.skeleton.positions(clip.sample(times))
            world = gltf.world(animation, times)
            theirs = np.stack([world[n][:, :3, 3] for n in nodes], axis=1)
            found.append(float(np.linalg.norm(ours - theirs, axis=-1).max()))
        rows.append((label, name, size, *found))
    return rows


def bvh_rows(path, rng):
    clip = next(iter(flockkit.io.read_clips(path).values()))
    frame_time = float(path.read_text().split("Frame Time:")[1].split()[0])
    rate = round(1.0 / frame_time, 2)  # flockkit's documented reading of a rounded frame time
    reference = spec.BvhMotion(path, rate)
    keys = np.arange(len(reference.frames)) / rate
    size = _diagonal(reference.positions(keys[::40]))
    found = []
    for times in (keys[::7], np.concatenate([(keys[:-1:7] + keys[1::7]) / 2, rng.uniform(0, keys[-1], 200)])):
        found.append(float(np.linalg.norm(clip.skeleton.positions(clip.sample(times)) - reference.positions(times),
                                          axis=-1).max()))  # fmt: skip
    return [("CMU BVH 01_01", clip.name, size, *found)]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    args = parser.parse_args()
    data = Path(args.data)
    rng = np.random.default_rng(0)
    rows = []
    for label, relative in (
        ("Fox", "fox-gltf/Fox.glb"),
        ("RobotExpressive", "robot-expressive-gltf/RobotExpressive.glb"),
    ):
        if (data / relative).exists():
            rows += gltf_rows(data / relative, label, rng)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "generated.glb"
        spec.write_clips(path, spec.generated_clips(seed=0))
        rows += gltf_rows(path, "generated", rng)
    bvh = data / "cmu-mocap-bvh" / "01_01.bvh"
    if bvh.exists():
        rows += bvh_rows(bvh, rng)
    print(f"{'asset':<16} {'clip':<12} {'size':>8} {'at keys':>10} {'/ size':>9} {'between':>10} {'/ size':>9}")
    for label, name, size, at_keys, between in rows:
        print(f"{label:<16} {name:<12} {size:8.3f} {at_keys:10.3g} {at_keys / size:9.2g} {between:10.3g} "
              f"{between / size:9.2g}")  # fmt: skip
    worst = max(max(r[3], r[4]) / r[2] for r in rows)
    print(f"worst: {worst:.2g} of the skeleton's size (bar: 1e-05)")


if __name__ == "__main__":
    main()
