"""Background-scene analysis (paper 002, section 4): read, segment and build graph layers of an
animated mesh, then synthesize a minute of it.

    python bench/layers.py [--data ../shared/data]

For the Fox's Survey clip (1 728 vertices), RobotExpressive's Idle clip (7 214 vertices) and a
synthetic flag of 10 000 vertices and 300 frames (a 100 x 100 grid waving in two independent
halves) it prints the seconds of each stage, the peak memory of the analysis (tracemalloc, in a
second, untimed pass), and the cost of synthesizing 60 s (the best of 3 runs), in milliseconds per
second of output per 1 000 vertices, with the seams smoothed (the default) and without
(``flockkit.scene.layers.SEAM_PASSES = 0``).
Targets (2 cores): the whole analysis of the 10 000-vertex, 300-frame object under 10 s;
synthesis at most 1 ms per second of output per 1 000 vertices.

Then cracks (``--part cracks`` prints only these): for every clip of every animated mesh in the
data folder (Fox, RobotExpressive, MorphStressTest), a triangle soup of each asset's first clip
(every face given its own corners) and of a 2 500-vertex flag, the layers are built (segmented by
``ica-kmeans``, seed 0), walked for 60 s (seed 1) and synthesized with the seams smoothed; it
prints ``flockkit.scene.crack_width`` (the largest and the mean distance between copies of one
surface point, relative to the object's size) without welding (``weld=False``, the baseline) and
with the default welding. Target: every crack 0 to 1e-6 of the object's size.
"""

from __future__ import annotations

import argparse
import tracemalloc
from pathlib import Path

import numpy as np
from timing import timed  # bench/timing.py: the scripts run from bench/

import flockkit


def flag(vertices: int = 10_000, frames: int = 300) -> flockkit.AnimatedMesh:
    """A square grid whose two halves wave at different rates: two parts to find."""
    side = int(round(np.sqrt(vertices)))
    u, v = np.meshgrid(np.linspace(0, 1, side), np.linspace(0, 1, side))
    t = np.arange(frames)[:, None] / 30
    u, v = u.ravel(), v.ravel()
    left = u < 0.5
    wave = np.where(left, 0.1 * np.sin(2 * np.pi * (0.7 * t + u)), 0.15 * np.sin(2 * np.pi * (1.3 * t + 2 * u)))
    positions = np.stack([np.broadcast_to(u, wave.shape), np.broadcast_to(v, wave.shape), wave * u], axis=2)
    index = np.arange(side * side).reshape(side, side)
    quads = np.stack([index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1]], axis=2).reshape(-1, 4)
    return flockkit.AnimatedMesh(motion=flockkit.Motion(positions=positions, dt=1 / 30), faces=quads, name="flag")


# every animated mesh of ../shared/data (its README)
ANIMATED = (
    "fox-gltf/Fox.glb",
    "robot-expressive-gltf/RobotExpressive.glb",
    "morph-stress-test-gltf/MorphStressTest.gltf",
)


def soup(mesh: flockkit.AnimatedMesh) -> flockkit.AnimatedMesh:
    """`mesh` with every face given its own corners: no two faces share a vertex."""
    faces = mesh.faces
    motion = flockkit.Motion(positions=mesh.motion.positions[:, faces.ravel()], dt=mesh.motion.dt)
    return flockkit.AnimatedMesh(motion=motion, faces=np.arange(faces.size).reshape(faces.shape),
                                 name=f"{mesh.name} soup")  # fmt: skip


def cracks(data: Path) -> None:
    """The crack table (module docstring)."""
    from flockkit.mesh import weld_map
    from flockkit.scene import crack_width

    meshes = []
    for path in ANIMATED:
        if not (data / path).exists():
            print(f"{data / path} not found: skipped")
            continue
        clips = list(flockkit.io.list_clips(data / path))
        meshes += [flockkit.io.read_mesh_animation(data / path, clip=clip) for clip in clips]
        meshes.append(soup(meshes[-len(clips)]))
    meshes.append(soup(flag(2_500, 120)))
    print(f"\n{'object':>34} {'vertices':>8} {'frames':>6} {'copies':>6} {'parts':>5} "
          f"{'crack unwelded':>14} {'mean':>8} {'crack welded':>12} {'mean':>8}")  # fmt: skip
    for mesh in meshes:
        figures = []
        for weld in (False, None):
            layers = flockkit.build_layers(mesh, seed=0, weld=weld)
            played = flockkit.synthesize(layers, flockkit.walk(layers, duration=60, seed=1))
            figures += [crack_width(played, mesh), crack_width(played, mesh, statistic="mean")]
        copies = int(np.sum(weld_map(mesh) != np.arange(mesh.motion.n_agents)))
        print(f"{mesh.name[-34:]:>34} {mesh.motion.n_agents:>8} {mesh.motion.n_frames:>6} {copies:>6} "
              f"{layers.n_parts:>5} {figures[0]:>14.2e} {figures[1]:>8.1e} {figures[2]:>12.2e} {figures[3]:>8.1e}",
              flush=True)  # fmt: skip


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    parser.add_argument("--part", choices=("all", "timing", "cracks"), default="all")
    args = parser.parse_args()
    data = Path(args.data)
    if args.part != "timing":
        cracks(data)
    if args.part == "cracks":
        return
    flockkit.segment(flag(400, 30), seed=0)  # imports scikit-learn before anything is timed
    cases = [
        ("Fox Survey", lambda: flockkit.io.read_mesh_animation(data / "fox-gltf" / "Fox.glb", clip="Survey")),
        (
            "Robot Idle",
            lambda: flockkit.io.read_mesh_animation(
                data / "robot-expressive-gltf" / "RobotExpressive.glb", clip="Idle"
            ),
        ),  # fmt: skip
        ("flag 10 000 x 300", flag),
    ]
    print(f"{'object':>18} {'vertices':>8} {'frames':>6} {'read s':>7} {'segment s':>9} {'graphs s':>8} "
          f"{'analysis s':>10} {'peak MB':>8} {'parts':>5} {'synth 60 s':>10} {'ms/s/1k vertices':>16} "
          f"{'no seams':>8}")  # fmt: skip
    for name, read in cases:
        mesh, reading = timed(read)
        parts, segmenting = timed(lambda mesh=mesh: flockkit.segment(mesh, seed=0))
        layers, building = timed(lambda mesh=mesh, parts=parts: flockkit.build_layers(mesh, segmentation=parts, seed=0))
        # peak memory in a second pass: tracing every allocation slows the first's Python-heavy parts
        tracemalloc.start()
        traced = read()
        flockkit.build_layers(traced, segmentation=flockkit.segment(traced, seed=0), seed=0)
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
        walk = flockkit.walk(layers, duration=60, seed=1)
        # the best of 3 runs: on a virtual machine a large fresh allocation's page faults vary a lot
        played, synthesis = timed(lambda layers=layers, walk=walk: flockkit.synthesize(layers, walk), repeat=3)
        per = synthesis * 1000 / played.duration / (mesh.motion.n_agents / 1000)
        passes, flockkit.scene.layers.SEAM_PASSES = flockkit.scene.layers.SEAM_PASSES, 0
        _, plain = timed(lambda layers=layers, walk=walk: flockkit.synthesize(layers, walk), repeat=3)
        flockkit.scene.layers.SEAM_PASSES = passes
        plain = plain * 1000 / played.duration / (mesh.motion.n_agents / 1000)
        analysis = reading + segmenting + building
        row = (
            f"{name:>18} {mesh.motion.n_agents:>8} {mesh.motion.n_frames:>6} {reading:>7.2f} {segmenting:>9.2f} "
            f"{building:>8.2f} {analysis:>10.2f} {peak:>8.0f} {parts.n_parts:>5} {synthesis:>10.2f} {per:>16.2f} "
        )
        print(row + f"{plain:>8.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
