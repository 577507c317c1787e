"""Parts of skinned characters: skin-parts (joints merged by how they move) against ica-kmeans
(motion alone) on the same clips, and both on a generated body with two limbs whose parts are known.

    python bench/skinparts.py [--data ../shared/data]

For the Fox (Survey, Walk, Run) and RobotExpressive (Idle, Walking, Running), read at 30 fps and
segmented through ``flockkit.segment`` (welded, seed 0) by ``skin-parts`` with its defaults (the
number of parts chosen by its threshold) and with 8 parts, and by ``ica-kmeans`` with the same
number of parts as each, it prints per part: the joints that dominate its vertices (largest
weight), its vertex count, whether those joints are one connected piece of the skeleton (joined
through joints that dominate no vertex), and its rigidity residual (the root-mean-square
distance of its vertices from their best rigid motion from the first frame, Kabsch per frame,
over vertices and frames, in % of the object's size; computed here with ``flockkit.rigid.kabsch``,
not by the plugin). A summary line per segmentation gives the parts whose joints are not
connected, the parts mixing the head with a leg or the tail (the gait-phase groupings of the
issue), the vertex-weighted mean residual and the seconds taken. The generated case is
``flockkit.testing.inputs.limbs``: the adjusted Rand index of each segmenter against the truth.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import flockkit
from flockkit.testing import inputs

CLIPS = [("fox-gltf/Fox.glb", ("Survey", "Walk", "Run")),
         ("robot-expressive-gltf/RobotExpressive.glb", ("Idle", "Walking", "Running"))]  # fmt: skip
HEAD = ("Head", "Neck")
LIMBS = ("Leg", "Foot", "Arm", "Hand", "Tail")


def residual(positions: np.ndarray) -> float:
    """RMS distance of (T, n, 3) points from their best rigid motion from the first frame."""
    centred = positions - positions.mean(axis=1, keepdims=True)
    turns = flockkit.rigid.kabsch(centred, centred[:1])
    placed = np.einsum("tij,tnj->tni", turns, np.broadcast_to(centred[:1], centred.shape))
    return float(np.sqrt(np.mean(np.sum((centred - placed) ** 2, axis=2))))


def connected(skin, joints: set) -> bool:
    """Whether `joints` are one piece of the skeleton, joined through joints that dominate no vertex."""
    occupied = set(np.unique(skin.dominant()).tolist())
    allowed = joints | (set(range(skin.n_joints)) - occupied)
    root = skin.n_joints  # a common root above the skeleton's roots
    neighbours = {j: set() for j in [*range(skin.n_joints), root]}
    for child, parent in enumerate(skin.parents.tolist()):
        parent = root if parent < 0 else parent
        neighbours[child].add(parent)
        neighbours[parent].add(child)
    start = next(iter(joints))
    seen, stack = {start}, [start]
    while stack:
        for other in neighbours[stack.pop()]:
            if other not in seen and (other in allowed or other == root):
                seen.add(other)
                stack.append(other)
    return joints <= seen


def report(mesh, labels, what: str, seconds: float) -> None:
    skin, positions = mesh.skin, mesh.motion.positions
    size = flockkit.mesh.object_size(mesh)
    dominant = skin.dominant()
    names = skin.joint_names
    apart, mixed, total = 0, 0, 0.0
    print(f"  {what}: {labels.max() + 1} parts")
    for k in range(labels.max() + 1):
        points = np.flatnonzero(labels == k)
        joints = set(dominant[points].tolist())
        whole = connected(skin, joints)
        shown = [names[j] for j in sorted(joints)]
        head = any(h in n for n in shown for h in HEAD)
        limb = any(m in n for n in shown for m in LIMBS)
        apart += not whole
        mixed += head and limb
        rms = residual(positions[:, points]) / size
        total += rms * len(points)
        listed = ", ".join(shown[:6]) + (f", ... ({len(shown)} joints)" if len(shown) > 6 else "")
        print(f"    {len(points):>5} vertices  residual {100 * rms:6.2f}%  {'connected' if whole else 'APART    '}  "
              f"{'HEAD+LIMB ' if head and limb else ''}{listed}")  # fmt: skip
    print(f"    summary {what}: joints apart in {apart} parts, head with a leg or tail in {mixed}, mean residual "
          f"{100 * total / len(labels):.2f}% of the size, {seconds:.2f} s")  # fmt: skip


def timed(call):
    start = time.perf_counter()
    out = call()
    return out, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    data = Path(parser.parse_args().data)
    flockkit.segment(inputs.parts()[0], segmenter="ica-kmeans", seed=0)  # imports scikit-learn before timing
    for path, clips in CLIPS:
        if not (data / path).exists():
            print(f"{data / path} not found: skipped")
            continue
        for clip in clips:
            mesh = flockkit.io.read_mesh_animation(data / path, clip=clip, fps=30)
            print(f"\n{Path(path).stem} {clip}: {mesh.motion.n_agents} vertices, {mesh.motion.n_frames} frames, "
                  f"{mesh.skin.n_joints} joints")  # fmt: skip
            for params in ({}, {"n_parts": 8}):
                found, took = timed(lambda mesh=mesh, params=params: flockkit.segment(mesh, segmenter="skin-parts",
                                                                                      seed=0, **params))  # fmt: skip
                report(mesh, found.labels, f"skin-parts {params or '(threshold)'}", took)
                other, took = timed(lambda mesh=mesh, n=found.n_parts: flockkit.segment(mesh, segmenter="ica-kmeans",
                                                                                        seed=0, n_parts=n))  # fmt: skip
                report(mesh, other.labels, f"ica-kmeans n_parts={found.n_parts}", took)
    from sklearn.metrics import adjusted_rand_score

    print("\ngenerated body with two limbs (inputs.limbs): adjusted Rand index against the known parts")
    for dims in (2, 3):
        mesh, truth = inputs.limbs(dims=dims)
        skin = flockkit.segment(mesh, seed=0)
        ica = flockkit.segment(mesh, segmenter="ica-kmeans", seed=0)
        ica3 = flockkit.segment(mesh, segmenter="ica-kmeans", seed=0, n_parts=3)
        print(f"  {dims}D: skin-parts {skin.n_parts} parts ARI {adjusted_rand_score(truth, skin.labels):.3f}; "
              f"ica-kmeans {ica.n_parts} parts ARI {adjusted_rand_score(truth, ica.labels):.3f}, with 3 parts "
              f"ARI {adjusted_rand_score(truth, ica3.labels):.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
