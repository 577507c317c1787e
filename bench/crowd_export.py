"""Crowd exports for animation tools and engines: a driven crowd of Foxes written to USD, seconds,
bytes and peak memory, beside the per-agent writer flockkit had before, in the same run.

    python bench/crowd_export.py [--agents 10000] [--seconds 10] [--fps 24] [--peer-agents 1000]
                                 [--data ../shared/data]

The scene (as `flockkit demo`'s Foxes): N Foxes (24 joints, 1 728 skinned vertices) follow a 2D
boids flock of N agents through a `Driver` (idle = Survey, walk = Walk at three rates matched to
speed, the stream switched with a 0.3 s blend), and half of them run (a Stopped Run stream) for
3 s from 4 s on, a cue with 2 s of time dilation. Each writer runs the same crowd from the same
seeds in a child process of its own (so that peak memory is its own: ru_maxrss of the child) and
writes a .usdc of every frame of every agent:

- ``export_usd``: `flockkit.crowd.export_usd` with the Fox's skinned mesh (`read_skin`): the
  character once, a SkelAnimation per stream run that steady agents reference at their offsets,
  per-agent samples (stream frames stored once) for the rest; time includes running the crowd.
- ``recording``: `flockkit.crowd.record` then `CrowdRecording.export_usd` (every agent's poses
  kept in memory, then per-agent samples, repeated poses stored once), with the mesh.
- ``per-agent (before)``: `record` then the writer flockkit used before (a Skeleton and a
  SkelAnimation per agent, every pose a new array, written through the Usd API, no mesh), kept
  here as it was; it takes about 0.04 s per agent, so it runs at `--peer-agents` only.

Targets: 10 000 agents x 10 s in under 60 s and under 200 MB of file.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def crowd_scene(agents: int, seconds: float, fps: float, data: Path):
    import flockkit
    from flockkit.cli.demo import FOX_FEET, FOX_LEGS
    from flockkit.crowd import Crowd, Cue, Driver, Gait, StateMachine, Stream, StreamPool, ground_speed, plant_feet

    fox = data / "fox-gltf" / "Fox.glb"
    clips = flockkit.io.read_clips(fox)
    clips["Walk"] = plant_feet(clips["Walk"], FOX_LEGS)
    scale = 0.01  # centimetres
    natural = ground_speed(clips["Walk"], FOX_FEET, scale=scale)
    rates = (0.8, 1.0, 1.25)
    play = lambda clip, **k: flockkit.get("controller", "clip", clip=clips[clip], **k)  # noqa: E731
    streams = [Stream(controller=play("Survey"), history=60, name="idle")]
    streams += [Stream(controller=play("Walk", rate=r), history=40, name=f"walk x{r}") for r in rates]
    streams.append(Stream(controller=play("Run"), history=48, default="Stopped", name="run"))
    walking = Gait(name="walk", streams=[1, 2, 3], speeds=[natural * r for r in rates], low=0.2)
    machine = StateMachine([Gait(name="idle", streams=0, high=0.2), walking])
    cue = Cue(time=4.0, agents=np.arange(0, agents, 2), stream=4, duration=3.0, time_to_dilate=2.0, name="run")
    flock = flockkit.simulate(n_agents=agents, steps=int(seconds * fps), dt=1 / fps, seed=3)
    crowd = Crowd(StreamPool(streams, fps=fps), n_agents=agents, clusters={"body": 1}, seed=4)
    return Driver(crowd, flock, machine, scale=scale, cues=[cue]), fox


def previous_writer(recording, path) -> None:
    """The writer flockkit used before: per agent a Skeleton and a SkelAnimation, every frame a
    new array per attribute, through the Usd API (time codes as it wrote them)."""
    from pxr import Gf, UsdSkel, Vt

    from flockkit import rigid
    from flockkit.crowd.record import _joint_paths
    from flockkit.io.usd import _stage

    skeleton = recording.skeleton
    joints = _joint_paths(skeleton)
    bind = skeleton.world(skeleton.rest)
    rest = rigid.trs(skeleton.rest.translations, skeleton.rest.rotations, skeleton.scales)
    scales = Vt.Vec3hArray.FromNumpy(np.asarray(skeleton.scales).astype(np.float16))
    frames, agents = recording.roots.shape[:2]
    with _stage(path, "/Crowd", dt=1.0 / recording.fps, n_frames=frames, fps=recording.fps) as (stage, times):
        for agent in range(agents):
            root = UsdSkel.Root.Define(stage, f"/Crowd/Agent_{agent}")
            transform = root.AddTransformOp()
            bones = UsdSkel.Skeleton.Define(stage, f"/Crowd/Agent_{agent}/Skeleton")
            bones.CreateJointsAttr(joints)
            bones.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(m.T.tolist()) for m in bind]))
            bones.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(m.T.tolist()) for m in rest]))
            animation = UsdSkel.Animation.Define(stage, f"/Crowd/Agent_{agent}/Skeleton/Animation")
            animation.CreateJointsAttr(joints)
            animation.CreateScalesAttr(scales)
            turns, moves = animation.CreateRotationsAttr(), animation.CreateTranslationsAttr()
            UsdSkel.BindingAPI.Apply(bones.GetPrim()).CreateAnimationSourceRel().SetTargets([animation.GetPath()])
            for frame, when in enumerate(times):
                transform.Set(Gf.Matrix4d(recording.roots[frame, agent].T.tolist()), when)
                turns.Set(Vt.QuatfArray.FromNumpy(np.ascontiguousarray(recording.rotations[frame, agent])), when)
                moves.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(recording.translations[frame, agent])), when)


def child(which: str, agents: int, seconds: float, fps: float, data: Path, path: Path) -> dict:
    from flockkit.crowd import export_usd, read_skin, record

    driver, fox = crowd_scene(agents, seconds, fps, data)
    begin = time.perf_counter()
    found = {}
    if which == "export_usd":
        found = export_usd(driver, path, seconds, mesh=read_skin(fox))
    elif which == "recording":
        record(driver, seconds).export_usd(path, mesh=read_skin(fox))
    else:
        previous_writer(record(driver, seconds), path)
    found.update(seconds=time.perf_counter() - begin, bytes=path.stat().st_size,
                 peak=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)  # fmt: skip
    return found


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=10_000)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--fps", type=float, default=24.0)
    parser.add_argument("--peer-agents", type=int, default=1000, help="agents for the two writers that keep poses")
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[1].parent / "shared" / "data")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        which, agents = args.child.split(":")
        with tempfile.TemporaryDirectory() as folder:
            found = child(which, int(agents), args.seconds, args.fps, args.data, Path(folder) / "crowd.usdc")
        print("RESULT" + json.dumps(found))
        return
    print(f"{args.seconds:g} s at {args.fps:g} fps ({round(args.seconds * args.fps)} frames), Fox, driven; "
          "every agent of every frame written to .usdc")  # fmt: skip
    print(f"{'writer':>20} {'agents':>7} {'seconds':>8} {'MiB':>8} {'peak MiB':>9}  details")
    runs = [("export_usd", args.agents), ("export_usd", args.peer_agents), ("recording", args.peer_agents),
            ("per-agent (before)", args.peer_agents)]  # fmt: skip
    for which, agents in runs:
        done = subprocess.run([sys.executable, __file__, "--child", f"{which}:{agents}", "--seconds", str(args.seconds),
                               "--fps", str(args.fps), "--data", str(args.data)], capture_output=True, text=True,
                              env=dict(os.environ))  # fmt: skip
        if done.returncode:
            raise SystemExit(done.stderr[-2000:])
        found = json.loads(done.stdout.split("RESULT", 1)[1])
        details = ", ".join(f"{k} {found[k]}" for k in ("referencing", "sampled", "streams", "poses") if k in found)
        print(f"{which:>20} {agents:>7} {found['seconds']:8.1f} {found['bytes'] / 2**20:8.1f} "
              f"{found['peak'] / 2**20:9.0f}  {details}")  # fmt: skip


if __name__ == "__main__":
    main()
