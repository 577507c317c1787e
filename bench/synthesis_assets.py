"""Synthesis of graph layers on every animated asset of the data folder, against a
straightforward vectorized numpy evaluation of the same output.

    python bench/synthesis_assets.py [--data ../shared/data] [--seconds 60]

For every clip of Fox.glb, RobotExpressive.glb and MorphStressTest.gltf (layers by the default
segmenter, seed 0; a 60 s walk, seed 1) it prints the milliseconds per second of output per
1 000 vertices of ``flockkit.synthesize(layers, walk)`` (seams smoothed, welded copies played at
one position; the best of 3) and of the peer, which computes the same frames plainly: each
part's blended frames ((1 - w) old + w new, ``flockkit.graphs.blended_frames``) put in place for
every frame, every welded copy given its point's position, then SEAM_PASSES passes of the
documented smoothing over all frames at once (each zone point's displacement from its mean source
position replaced by the mean of its neighbours', a sparse matrix product per pass), and the
largest difference between the two relative to the object's size. Beside them, the floor: making
and filling an array of the output's size (``numpy.empty`` then ``fill``: the fresh pages and the
bytes written, which any synthesis into new memory pays), and the load average when the clip
ran (the machine is shared). Target: at most 1 ms per second of output per 1 000 vertices.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
from scipy.sparse import diags
from timing import timed  # bench/timing.py: the scripts run from bench/

import flockkit
from flockkit.graphs import blended_frames
from flockkit.mesh import object_size
from flockkit.scene import layers as module

ASSETS = ("fox-gltf/Fox.glb", "robot-expressive-gltf/RobotExpressive.glb",
          "morph-stress-test-gltf/MorphStressTest.gltf")  # fmt: skip


def plainly(layers, walk) -> np.ndarray:
    """The frames synthesize_layers plays, computed the plain way (module docstring)."""
    parts = layers.segmentation.parts()
    played = []
    for graph, part in zip(layers.graphs, walk.walks):
        new, old, weight = blended_frames(graph, part)
        source = graph.motion.positions
        w = weight[:, None, None]
        played.append((1 - w) * source[old] + w * source[new])
    frames = min(len(p) for p in played)
    positions = np.empty((frames, layers.source.n_agents, layers.source.dims))
    for points, own in zip(parts, played):
        positions[:, points] = own[:frames]
    if layers.welds is not None:
        positions = positions[:, layers.welds]
    if module._seams(layers) is None:
        return positions
    adjacency = module._adjacency(layers.source.n_agents, module.welded_faces(layers))
    zone = np.zeros(layers.source.n_agents, dtype=bool)
    zone[module.seam_points(layers)] = True
    for _ in range(module.SEAM_RINGS):
        zone |= (adjacency @ zone.astype(float)) > 0
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    mean = diags(1.0 / np.maximum(degree, 1)) @ adjacency
    rest = layers.source.positions.mean(axis=0)
    shifted = (positions - rest).transpose(1, 0, 2).reshape(layers.source.n_agents, -1)
    for _ in range(module.SEAM_PASSES):
        shifted[zone] = mean[zone] @ shifted
    positions = shifted.reshape(layers.source.n_agents, frames, -1).transpose(1, 0, 2) + rest
    return positions[:, layers.welds] if layers.welds is not None else positions


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    data = Path(args.data)
    print(f"{'clip':>28} {'vertices':>8} {'frames':>6} {'parts':>5} {'flockkit ms/s/1k':>16} {'peer ms/s/1k':>12} "
          f"{'largest difference':>18} {'fill ms/s/1k':>12} {'load':>5}")  # fmt: skip
    for asset in ASSETS:
        for clip in flockkit.io.list_clips(data / asset):
            mesh = flockkit.io.read_mesh_animation(data / asset, clip=clip)
            layers = flockkit.build_layers(mesh, seed=0)
            walk = flockkit.walk(layers, duration=args.seconds, seed=1)
            played, ours = timed(lambda layers=layers, walk=walk: flockkit.synthesize(layers, walk), repeat=3)
            expected, peer = timed(lambda layers=layers, walk=walk: plainly(layers, walk), repeat=3)
            _, fill = timed(lambda shape=played.positions.shape: np.empty(shape).fill(0.0), repeat=3)
            scale = 1000 / played.duration / (mesh.motion.n_agents / 1000)
            gap = np.abs(played.positions - expected).max() / object_size(mesh)
            print(f"{mesh.name[-28:]:>28} {mesh.motion.n_agents:>8} {mesh.motion.n_frames:>6} {layers.n_parts:>5} "
                  f"{ours * scale:>16.2f} {peer * scale:>12.2f} {gap:>18.1e} {fill * scale:>12.2f} "
                  f"{os.getloadavg()[0]:>5.2f}", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
