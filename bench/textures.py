"""Baked animation textures on the real characters: bake time and bytes, and the reference
skinning against linear blend skinning from the crowd's poses, in the same run.

    python bench/textures.py [--agents 256] [--seconds 60] [--fps 24] [--data ../shared/data]

For the Fox (24 joints skinned, 1 728 vertices; streams Walk, Run, Survey Stopped) and
RobotExpressive (43 joints skinned, 7 214 vertices, most of them rigid parts; streams Idle,
Walking, Running Running; Wave, Dance Stopped), at `--fps` frames a second:

- the time to bake the pool's streams for a crowd run of `--seconds` (best of 3), the textures'
  rows, their bytes on the GPU (animation texture and skeleton texture) and on disk, and which
  streams were kept as one loop; the same with ``loop_tolerance=1e-4``, and how far its loops'
  vertices stray from the exact bake's over the whole run;
- a crowd of `--agents` agents run for 4 s, with three rounds of transitions (blends into
  Running streams, a Stopped stream started with time dilation), and on 8 frames (best of 3
  each) the per-frame cost of every agent's skinned mesh two ways: the textures
  (`instance_buffer` + `skin`, the numpy reference of the shader) and the strongest baseline
  without them, `Crowd.poses(space="world")` (every part's pose, between frames and blends
  included, by forward kinematics) and a vectorized numpy linear blend skinning of the mesh
  (`SkinnedMesh.skinned`, the same kernel, so the difference is how each part's skinning matrices
  are had). The two are checked equal, relative to the character's size; and the error that
  mixing skinning matrices instead of local transforms (what vertex animation textures do between
  frames and in blends) would make on the same parts.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from timing import timed  # bench/timing.py: the scripts run from bench/

import flockkit
from flockkit.crowd import (
    Crowd,
    Stream,
    StreamPool,
    bake_textures,
    instance_buffer,
    instances,
    read_skin,
    skin,
    skinning_matrices,
)
from flockkit.io import read_clips

CHARACTERS = {
    "Fox": ("fox-gltf/Fox.glb", [("Walk", "Running"), ("Run", "Running"), ("Survey", "Stopped")]),
    "RobotExpressive": (
        "robot-expressive-gltf/RobotExpressive.glb",
        [
            ("Idle", "Running"),
            ("Walking", "Running"),
            ("Running", "Running"),
            ("Wave", "Stopped"),
            ("Dance", "Stopped"),
        ],
    ),  # fmt: skip
}
HISTORY = 48  # frames of each stream's ring buffer (2 s at 24 fps)


def matrix_lerp(textures, records) -> np.ndarray:
    """Skinning matrices (n, J, 3, 4) as vertex animation textures make them: the baked matrices
    of rows a and b mixed linearly by the fraction, source and target mixed by α."""
    m = textures.matrices.astype(np.float64)
    rows, f, w = records["rows"], records["fractions"].astype(np.float64), records["weight"].astype(np.float64)
    source = m[rows[:, 0]] + f[:, 0, None, None, None] * (m[rows[:, 1]] - m[rows[:, 0]])
    target = m[np.maximum(rows[:, 2], 0)] + f[:, 1, None, None, None] * (
        m[np.maximum(rows[:, 3], 0)] - m[np.maximum(rows[:, 2], 0)]
    )
    return np.where((w > 0)[:, None, None, None], source + w[:, None, None, None] * (target - source), source)


def run(name: str, data: Path, agents: int, seconds: float, fps: float) -> None:
    path, streams = CHARACTERS[name]
    clips = read_clips(data / path)
    mesh = read_skin(data / path)
    pool = StreamPool(
        [Stream(controller=flockkit.get("controller", "clip", clip=clips[clip]), history=HISTORY, name=clip,
                default=default) for clip, default in streams],
        fps=fps,
    )  # fmt: skip
    textures, bake = timed(lambda: bake_textures(pool, seconds=seconds, inverse_bind=mesh), repeat=3)
    with tempfile.TemporaryDirectory() as folder:
        file = Path(folder) / "textures.bin"
        textures.save(file)
        on_disk = file.stat().st_size
    loops = ", ".join(
        f"{n} {int(k)} rows" + (f" (a loop of {p:g} frames)" if p else " (the whole run)")
        for n, k, p in zip(textures.names, textures.lengths, textures.periods)
    )
    print(f"{name}: {mesh.n_vertices} vertices, {textures.skeleton.n_joints} joints; {len(streams)} streams at "
          f"{fps:g} fps, baked for {seconds:g} s of crowd in {bake * 1000:.1f} ms (best of 3)")  # fmt: skip
    print(f"  textures: {len(textures.texels)} rows of {5 * textures.skeleton.n_joints} RGBA32F texels, "
          f"{textures.nbytes / 1024:.1f} KiB on the GPU, {on_disk / 1024:.1f} KiB on disk; {loops}")  # fmt: skip
    loose, loose_bake = timed(lambda: bake_textures(pool, seconds=seconds, inverse_bind=mesh, loop_tolerance=1e-4))
    drift, size = 0.0, None
    for s in np.flatnonzero((loose.periods > 0) & (textures.periods == 0)):
        frames = np.arange(0, textures.lengths[s], 4)
        exact = skin(textures, instances(textures, np.full(len(frames), s), frames), mesh)
        size = float(np.ptp(exact, axis=1).max()) if size is None else size
        looped = skin(loose, instances(loose, np.full(len(frames), s), frames), mesh)
        drift = max(drift, float(np.abs(exact - looped).max()) / size)
    print(f"  with loop_tolerance=1e-4: {len(loose.texels)} rows, {loose.nbytes / 1024:.1f} KiB, baked in "
          f"{loose_bake * 1000:.1f} ms; loops {', '.join(f'{p:g}' for p in loose.periods)} frames; over the whole "
          f"run its vertices are within {drift:.1e} of the character's size of the exact bake's")  # fmt: skip

    crowd = Crowd(pool, n_agents=agents, clusters={"body": np.arange(agents) % 2}, seed=1)
    every = np.arange(agents)
    plan = {
        12: (every[: agents // 4], 1, 0.5, None),  # a blend into a Running stream
        36: (every[agents // 4 : agents // 2], len(streams) - 1, 1.0, 2.0),  # a Stopped one, dilated
        60: (every[::5], 0, 0.75, None),
    }
    checked = {"at whole frames": 0.0, "between frames or blending": 0.0, "matrix lerp": 0.0}
    rows = []
    for frame in range(int(4 * fps)):
        if frame in plan:
            ids, stream, blend, dilate = plan[frame]
            crowd.transition_to_streamed(ids, "body", stream, blend, time_to_dilate=dilate)
        crowd.update()
        if frame % int(fps / 2) != 5:
            continue
        records, buffer_time = timed(lambda: instance_buffer(crowd, textures), repeat=3)
        positions, skin_time = timed(lambda r=records: skin(textures, r, mesh), repeat=3)
        world, poses_time = timed(lambda: crowd.poses(space="world"), repeat=3)
        direct, lbs_time = timed(lambda w=world: mesh.skinned(w), repeat=3)
        _, palette_time = timed(lambda r=records: skinning_matrices(textures, r), repeat=3)
        size = float(np.ptp(direct, axis=1).max())
        error = np.abs(positions - direct).max(axis=(1, 2)) / size
        mixed = (records["weight"] > 0) | (records["fractions"][:, 0] > 0)
        checked["at whole frames"] = max(checked["at whole frames"], float(error[~mixed].max(initial=0)))
        checked["between frames or blending"] = max(checked["between frames or blending"],
                                                    float(error[mixed].max(initial=0)))  # fmt: skip
        if mixed.any():
            lerped = matrix_lerp(textures, records[mixed])
            full = np.concatenate([lerped, np.broadcast_to([0.0, 0, 0, 1], lerped.shape[:2] + (1, 4))], axis=2)
            wrong = mesh.skinned(full @ np.linalg.inv(textures.inverse_bind))
            checked["matrix lerp"] = max(checked["matrix lerp"], float(np.abs(wrong - direct[mixed]).max() / size))
        rows.append((frame, int((records["weight"] > 0).sum()), int((mixed & (records["weight"] == 0)).sum()),
                     buffer_time, palette_time, skin_time, poses_time, lbs_time))  # fmt: skip
    print(f"  {agents} agents; per frame (best of 3), textures: instance_buffer + skin (of which the skinning "
          "matrices), baseline: Crowd.poses(world) + numpy LBS")  # fmt: skip
    for frame, blending, dilating, buffer_time, palette_time, skin_time, poses_time, lbs_time in rows:
        print(f"    frame {frame:3d}: {blending:3d} blending, {dilating:3d} between frames; textures "
              f"{(buffer_time + skin_time) * 1000:6.1f} ms ({palette_time * 1000:5.2f}), baseline "
              f"{(poses_time + lbs_time) * 1000:6.1f} ms ({poses_time * 1000:5.2f} poses)")  # fmt: skip
    textures_ms = np.mean([(r[3] + r[5]) * 1000 for r in rows])
    baseline_ms = np.mean([(r[6] + r[7]) * 1000 for r in rows])
    print(f"  mean: textures {textures_ms:.1f} ms, baseline {baseline_ms:.1f} ms per frame "
          f"({textures_ms / (agents * mesh.n_vertices / 1000):.3f} against "
          f"{baseline_ms / (agents * mesh.n_vertices / 1000):.3f} ms per 1 000 skinned vertices); skinning matrices "
          f"{np.mean([r[4] for r in rows]) * 1000:.2f} ms against Crowd.poses(world) "
          f"{np.mean([r[6] for r in rows]) * 1000:.2f} ms")  # fmt: skip
    print("  the same vertices, relative to the character's size: "
          + "; ".join(f"{k} {v:.1e}" for k, v in checked.items() if k != "matrix lerp")
          + f"; mixing skinning matrices instead would be off by {checked['matrix lerp']:.1e}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--agents", type=int, default=256)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fps", type=float, default=24.0)
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    args = parser.parse_args()
    for name in CHARACTERS:
        run(name, args.data, args.agents, args.seconds, args.fps)


if __name__ == "__main__":
    main()
