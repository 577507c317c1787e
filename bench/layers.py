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

Then short cycles (``--part cycles`` prints only these): for a generated 42-frame flapping cycle
of four parts (two wings, a tail, a body) and the short cycles of the data folder (Fox Walk and
Run, RobotExpressive Walking and Running; segmented by ``ica-kmeans``, seed 0, their arrows held
at zero), a scene of 20 duplicates in a square 10 footprint diagonals wide (the bird's: 30 x 30;
and 40 birds, twice as dense), walked for 60 s (seed 3). It prints, with the windowed builder's
defaults and with the baseline ``loops=False, shift_blend=0`` (the plain loop flockkit played
before): the share of distinct part-frame states (per object and part, the source frame each
output frame plays, or the frames blended and the weight inside a blend; distinct ones over the
scene's frames), least and mean; the share of neighbour pairs in step (in some part, source
frames at most one frame apart, on more than 5% of frames) before and after de-synchronisation,
as the scene reports them, and after, counted around the loop of a looping part (frame 41 one
frame from frame 0); the parts warned about; and the seconds to build the layers
and to synthesize the scene. Bar (42-frame cycle): at least 80% distinct states, at most 5% of
pairs in step.
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
            layers = flockkit.build_layers(mesh, segmenter="ica-kmeans", seed=0, weld=weld)
            played = flockkit.synthesize(layers, flockkit.walk(layers, duration=60, seed=1))
            figures += [crack_width(played, mesh), crack_width(played, mesh, statistic="mean")]
        copies = int(np.sum(weld_map(mesh) != np.arange(mesh.motion.n_agents)))
        print(f"{mesh.name[-34:]:>34} {mesh.motion.n_agents:>8} {mesh.motion.n_frames:>6} {copies:>6} "
              f"{layers.n_parts:>5} {figures[0]:>14.2e} {figures[1]:>8.1e} {figures[2]:>12.2e} {figures[3]:>8.1e}",
              flush=True)  # fmt: skip


def flapping(period: int = 42, points: int = 12) -> tuple[flockkit.Motion, flockkit.Segmentation]:
    """One beat of a bird, `period` frames at 30 fps (frame 0 follows the last): two wings beating
    a little apart, a tail wagging twice a beat and a bobbing body, `points` points each."""
    phase = 2 * np.pi * np.arange(period)[:, None] / period
    s = np.linspace(0.1, 1.0, points)[None, :]
    zero = 0 * phase + 0 * s
    parts = [
        np.stack([-s + zero, zero, 0.6 * s * np.sin(phase)], axis=2),
        np.stack([s + zero, zero, 0.6 * s * np.sin(phase + 0.3)], axis=2),
        np.stack([0.2 * s * np.sin(2 * phase) + zero, -0.5 - s + zero, 0.1 * np.cos(phase) + zero], axis=2),
        np.stack([zero, 0.5 * s - 0.2 + zero, 0.05 * np.sin(phase + 1.0) + zero], axis=2),
    ]
    motion = flockkit.Motion(positions=np.concatenate(parts, axis=1), dt=1 / 30)
    return motion, flockkit.Segmentation(labels=np.repeat(np.arange(4), points), n_parts=4)


def distinct_states(layers, animation) -> list[float]:
    """Per object and part, the share of distinct part-frame states (module docstring)."""
    shares = []
    for walk in animation.walks:
        for graph, part in zip(layers.graphs, walk.walks):
            new, old, weight = (a[: animation.n_frames] for a in flockkit.graphs.blended_frames(graph, part))
            states = {(int(n),) if w == 1 else (int(o), int(n), float(w)) for n, o, w in zip(new, old, weight)}
            shares.append(len(states) / animation.n_frames)
    return shares


def pairs_in_step(frames, neighbours, periods) -> float:
    """The share of neighbour pairs in step (module docstring), looping parts around the loop."""
    from flockkit.scene.desync import in_step

    pairs = sorted({(min(i, j), max(i, j)) for i, near in enumerate(neighbours) for j in near})
    return float(np.mean([in_step(frames[i], frames[[j]], periods)[0] > 0.05 for i, j in pairs]))


def cycles(data: Path) -> None:
    """The short-cycle table (module docstring)."""
    import warnings

    from flockkit.scene.templates import footprint

    sources = [("bird 42 frames", flapping, 20), ("bird 42, dense", flapping, 40)]
    for path, clip in (("fox-gltf/Fox.glb", "Walk"), ("fox-gltf/Fox.glb", "Run"),
                       ("robot-expressive-gltf/RobotExpressive.glb", "Walking"),
                       ("robot-expressive-gltf/RobotExpressive.glb", "Running")):  # fmt: skip
        if not (data / path).exists():
            print(f"{data / path} not found: skipped")
            continue

        def read(path=path, clip=clip):
            mesh = flockkit.io.read_mesh_animation(data / path, clip=clip)
            return mesh, flockkit.segment(mesh, segmenter="ica-kmeans", seed=0)

        sources.append((f"{Path(path).stem} {clip}", read, 20))
    print(f"\n{'source':>24} {'builder':>8} {'frames':>6} {'parts':>5} {'loops':>5} {'shifts':>6} {'objects':>7} "
          f"{'distinct min':>12} {'mean':>6} {'in step before':>14} {'after':>6} {'around':>6} {'warned':>6} "
          f"{'build s':>7} {'scene s':>7}")  # fmt: skip
    for name, read, count in sources:
        source, parts = read()
        motion = source.motion if isinstance(source, flockkit.AnimatedMesh) else source
        still = flockkit.Features(vectors=np.zeros((motion.n_frames, 3)), dt=motion.dt)
        for label, params in (("default", {}), ("plain", {"loops": False, "shift_blend": 0})):
            layers, building = timed(lambda source=source, parts=parts, still=still, params=params: (
                flockkit.build_layers(source, segmentation=parts, features=still, seed=0, **params)))  # fmt: skip
            side = 10 * 2 * np.linalg.norm(footprint(layers)[1])  # 10 footprint diagonals
            region = flockkit.Polygon(vertices=[[0, 0], [side, 0], [side, side], [0, side]])
            scene = flockkit.Scene(templates=[layers], region=region, counts=[count], duration=60, seed=3)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                animation, seconds = timed(scene.synthesize)
            warned = sum(issubclass(w.category, flockkit.errors.FlockkitWarning) for w in caught)
            periods = [g.period for g in layers.graphs]
            frames, neighbours = animation.source_frames(), animation.neighbours()
            shares = distinct_states(layers, animation)
            report = animation.report
            around = pairs_in_step(frames, neighbours, periods)
            shifts = sum(int(np.count_nonzero(g.shifts)) for g in layers.graphs)
            looping = sum(g.loops for g in layers.graphs)
            print(f"{name:>24} {label:>8} {motion.n_frames:>6} {layers.n_parts:>5} {looping:>5} {shifts:>6} "
                  f"{count:>7} {min(shares):>12.1%} {np.mean(shares):>6.1%} {report['pairs_in_step_before']:>14.1%} "
                  f"{report['pairs_in_step_after']:>6.1%} {around:>6.1%} {warned:>6} {building:>7.2f} "
                  f"{seconds:>7.2f}", flush=True)  # fmt: skip


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    parser.add_argument("--part", choices=("all", "timing", "cracks", "cycles"), default="all")
    args = parser.parse_args()
    data = Path(args.data)
    if args.part in ("all", "cycles"):
        cycles(data)
    if args.part == "cycles":
        return
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
        parts, segmenting = timed(lambda mesh=mesh: flockkit.segment(mesh, segmenter="ica-kmeans", seed=0))
        layers, building = timed(lambda mesh=mesh, parts=parts: flockkit.build_layers(mesh, segmentation=parts, seed=0))
        # peak memory in a second pass: tracing every allocation slows the first's Python-heavy parts
        tracemalloc.start()
        traced = read()
        flockkit.build_layers(traced, segmentation=flockkit.segment(traced, segmenter="ica-kmeans", seed=0), seed=0)
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
