"""Background scenes on every animated asset: a corpus of ../shared/data plus generated cases.

    python bench/scenes_corpus.py [--data ../shared/data] [--objects 8] [--seconds 60]

For every clip of every animated mesh in the data folder (Fox, RobotExpressive, MorphStressTest:
glTF), the CMU BVH take (a skeleton: its joints are the points, read at 30 fps; no faces, so no
cracks), triangle soups (the Fox's Survey clip and a 2 500-vertex flag with every face given its
own corners) and short cycles (a generated 42-frame flapping bird and a 22-frame one), it reads
the asset in flockkit's axes at its true size (the Fox is modelled in centimetres, the BVH take in
the CMU conversion's units of 1 / 0.45 inch), segments it (``ica-kmeans``, seed 0), builds graph
layers (welded, seams smoothed) with still arrows, and prints:

- read s: seconds to read the clip; up: the axis the file holds up (flockkit turns it to z);
  height m: the tallest frame's height along z, in metres;
- parts; crack: ``flockkit.scene.crack_width`` of one object's 60 s walk (seed 1), the largest
  distance between copies of one surface point over the minute, relative to the object's size;
- distinct: in a scene of `objects` duplicates in a square 10 footprint diagonals wide, walked
  for `seconds` (seed 3), per object and part the share of output frames in distinct states (the
  source frame played, or the frames blended and the weight inside a blend), least and mean;
- in step: the scene report's share of true-nearest-neighbour pairs in step on more than 5% of
  frames, within one frame (around the loop for looping parts; ``nearest_pairs_in_step``) and
  within a fortieth of the cycle for looping parts (``nearest_pairs_in_phase``);
- build s, scene s: seconds to segment and build, and to walk the scene.

Bars: every crack 0 to 1e-6 of the object's size; the 42-frame cycle at least 80% distinct
states and at most 5% of neighbour pairs within one frame of each other (checked at the end).
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
from layers import distinct_states, flag, flapping, soup  # bench/layers.py: the scripts run from bench/

import flockkit
from flockkit.scene import crack_width
from flockkit.scene.templates import footprint

# The animated meshes of ../shared/data (its README) and the unit each is modelled in where the
# file's own (glTF: metres) is wrong.
MESHES = (
    ("fox-gltf/Fox.glb", "cm"),
    ("robot-expressive-gltf/RobotExpressive.glb", None),
    ("morph-stress-test-gltf/MorphStressTest.gltf", None),
)
BVH = "cmu-mocap-bvh/01_01.bvh"
BVH_METERS_PER_UNIT = 0.0254 / 0.45  # the CMU conversion's unit (its README: inches, rescaled)


def corpus(data: Path):
    """(name, read seconds, up axis of the file, reader of the asset in flockkit's axes) for each
    asset; a reader returns an AnimatedMesh or a (Motion, None)."""
    cases = []
    for path, unit in MESHES:
        if not (data / path).exists():
            print(f"{data / path} not found: skipped")
            continue
        for clip in flockkit.io.list_clips(data / path):

            def read(path=path, clip=clip, unit=unit):
                mesh = flockkit.io.read_mesh_animation(data / path, clip=clip)
                return mesh.up_axis, mesh.to_flockkit_axes(meters_per_unit=unit)

            cases.append((f"{Path(path).stem}:{clip}", read))
    if (data / "fox-gltf/Fox.glb").exists():

        def fox_soup():
            mesh = flockkit.io.read_mesh_animation(data / "fox-gltf/Fox.glb", clip="Survey")
            return mesh.up_axis, soup(mesh.to_flockkit_axes(meters_per_unit="cm"))

        cases.append(("Fox:Survey soup", fox_soup))
    if (data / BVH).exists():
        cases.append(("01_01.bvh joints", lambda: bvh_joints(data / BVH)))
    else:
        print(f"{data / BVH} not found: skipped")
    cases.append(("flag 2 500 soup", lambda: ("z", soup(flag(2_500, 120)))))
    cases.append(("bird 42 frames", lambda: ("z", flapping(42))))
    cases.append(("bird 22 frames", lambda: ("z", flapping(22))))
    return cases


def bvh_joints(path: Path):
    """The BVH take's joints as points (a Motion) in flockkit's axes, in metres."""
    from flockkit.mesh import conversion_matrix
    from flockkit.skeleton import Pose

    (clip,) = flockkit.io.read_clips(path, fps=30).values()
    joints = clip.skeleton.positions(Pose._adopt(clip.rotations, clip.translations))
    turn = conversion_matrix(clip.skeleton.up_axis, BVH_METERS_PER_UNIT)
    return clip.skeleton.up_axis, flockkit.Motion(positions=joints @ turn.T, dt=1 / clip.fps)


def measure(name, read, objects: int, seconds: float) -> dict:
    (up, source), reading = timed(read)
    parts_given = None
    if isinstance(source, tuple):  # the bird: a motion and its parts
        source, parts_given = source
    motion = source.motion if isinstance(source, flockkit.AnimatedMesh) else source
    height = float(np.ptp(motion.positions[..., 2], axis=1).max())
    start = time.perf_counter()
    parts = parts_given if parts_given is not None else flockkit.segment(source, segmenter="ica-kmeans", seed=0)
    still = flockkit.Features(vectors=np.zeros((motion.n_frames, 3)), dt=motion.dt)
    layers = flockkit.build_layers(source, segmentation=parts, features=still, seed=0)
    building = time.perf_counter() - start
    crack = None
    if isinstance(source, flockkit.AnimatedMesh):
        played = flockkit.synthesize(layers, flockkit.walk(layers, duration=seconds, seed=1))
        crack = crack_width(played, source)
    side = 10 * 2 * np.linalg.norm(footprint(layers)[1])
    region = flockkit.Polygon(vertices=[[0, 0], [side, 0], [side, side], [0, side]])
    scene = flockkit.Scene(templates=[layers], region=region, counts=[objects], duration=seconds, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", flockkit.errors.FlockkitWarning)
        animation, walking = timed(scene.synthesize)
    shares = distinct_states(layers, animation)
    report = animation.report
    return {"name": name, "points": motion.n_agents, "frames": motion.n_frames, "read": reading, "up": up,
            "height": height, "parts": layers.n_parts, "crack": crack, "distinct min": min(shares),
            "distinct mean": float(np.mean(shares)), "in step": report["nearest_pairs_in_step"],
            "in phase": report["nearest_pairs_in_phase"], "pairs": report["nearest_pairs"], "build": building,
            "scene": walking}  # fmt: skip


def timed(call):
    start = time.perf_counter()
    result = call()
    return result, time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    parser.add_argument("--objects", type=int, default=8)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    flockkit.segment(flag(400, 30), seed=0)  # imports scikit-learn before anything is timed
    print(f"{'asset':>28} {'points':>6} {'frames':>6} {'read s':>6} {'up':>2} {'height m':>8} {'parts':>5} "
          f"{'crack':>8} {'distinct min':>12} {'mean':>6} {'pairs':>5} {'in step':>7} {'phase':>6} {'build s':>7} "
          f"{'scene s':>7}")  # fmt: skip
    rows = []
    for name, read in corpus(Path(args.data)):
        row = measure(name, read, args.objects, args.seconds)
        rows.append(row)
        crack = "n/a" if row["crack"] is None else f"{row['crack']:.1e}"
        print(f"{name[-28:]:>28} {row['points']:>6} {row['frames']:>6} {row['read']:>6.2f} {row['up']:>2} "
              f"{row['height']:>8.3f} {row['parts']:>5} {crack:>8} {row['distinct min']:>12.1%} "
              f"{row['distinct mean']:>6.1%} {row['pairs']:>5} {row['in step']:>7.1%} {row['in phase']:>6.1%} "
              f"{row['build']:>7.2f} {row['scene']:>7.2f}", flush=True)  # fmt: skip
    cracked = [r["name"] for r in rows if r["crack"] is not None and r["crack"] > 1e-6]
    bird = next(r for r in rows if r["name"] == "bird 42 frames")
    print(f"\ncracks above 1e-6 of the object's size: {cracked or 'none'} "
          f"(of {sum(r['crack'] is not None for r in rows)} meshes)")  # fmt: skip
    print(f"42-frame cycle: {bird['distinct min']:.1%} distinct states at least (bar 80%), "
          f"{bird['in step']:.1%} of nearest pairs within one frame (bar 5%): "
          f"{'met' if bird['distinct min'] >= 0.8 and bird['in step'] <= 0.05 else 'NOT met'}")  # fmt: skip


if __name__ == "__main__":
    main()
