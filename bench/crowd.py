"""The crowd runtime at the paper's evaluation scale (paper 003, section 5).

    python bench/crowd.py [--agents 65000] [--streams 1024] [--frames 120] [--data ../shared/data]

65 000 agents x 4 part clusters (body: 82 joints; flag: 25; scarf and hat: 24), 1 024 streams
(half human, a quarter each flag and scarf; half of each Stopped by default) with histories of 20
to 120 frames, random clips of those skeleton sizes. After the crowd starts, 4 096 body parts
transition at once into Stopped streams (a goal is scored: celebrations), blending over 0.5 s
with time dilation. It prints milliseconds per `update` (mean and worst over the frames) and per
`instance_buffer`, milliseconds to sample the blended poses of the 4 096 transitioning parts
(local, and world by forward kinematics), the pool's memory against Equations 4-6, and, in the
same run, a naive per-agent evaluation (each agent part evaluating its own controller, timed on a
sample of parts and scaled to the crowd). Targets (2 cores): update + instance_buffer <= 5 ms
per frame; blended poses of 4 096 parts <= 3 ms; >= 100x faster than the naive evaluation;
memory equal to Equation 5. First it times read_clips on the shared data's clips (the
2 752-frame BVH should take well under a second).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from timing import timed  # bench/timing.py: the scripts run from bench/

import flockkit
from flockkit.crowd import Crowd, Stream, StreamPool, equation_4, equation_5
from flockkit.testing import inputs

SKELETONS = {"body": 82, "flag": 25, "scarf": 24, "hat": 24}


def build(n_agents: int, n_streams: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    clips = {j: inputs.random_clip(j, frames=90, seed=j) for j in sorted(set(SKELETONS.values()))}
    bones = np.concatenate(
        [np.full(n_streams // 2, 82), np.full(n_streams // 4, 25), np.full(n_streams - 3 * n_streams // 4, 24)]
    )
    histories = rng.integers(20, 121, size=n_streams)
    stopped = rng.random(n_streams) < 0.5
    streams = [
        Stream(
            controller=flockkit.get("controller", "clip", clip=clips[int(b)], rate=float(rng.uniform(0.8, 1.2))),
            history=int(h),
            default="Stopped" if s else "Running",
        )
        for b, h, s in zip(bones, histories, stopped)
    ]
    pool = StreamPool(streams, fps=30.0)
    clusters = {}
    shares = {"body": 1.0, "flag": 0.3, "scarf": 0.5, "hat": 0.4}
    for name, joints in SKELETONS.items():
        candidates = np.flatnonzero((bones == joints) & ~stopped)
        chosen = rng.choice(candidates, size=n_agents)
        clusters[name] = np.where(rng.random(n_agents) < shares[name], chosen, -1)
    return pool, clusters, bones, histories, stopped


def ms(function, repeat=5) -> float:
    """The best of `repeat` calls, in milliseconds."""
    return timed(function, repeat=repeat)[1] * 1000


def gpu(args, movers, celebrations):
    """The same crowd with its store in CuPy, sampled and blended there through the same code
    (the array API), where CuPy and a GPU are present."""
    try:
        import cupy
    except ImportError:
        print("GPU: CuPy is not installed; the sampling and blending ran on the CPU only")
        return
    try:
        pool, clusters, *_ = build(args.agents, args.streams)
        pool = StreamPool(pool.streams, fps=pool.fps, xp=cupy)
        crowd = Crowd(pool, n_agents=args.agents, clusters=clusters, seed=1)
        for k, group in enumerate(np.array_split(movers, 16)):
            crowd.transition_to_streamed(group, "body", int(celebrations[k]), blend_time=0.5, time_to_dilate=2.0)
        for _ in range(5):
            crowd.update()

        def sample():
            crowd.poses(movers, "body")
            cupy.cuda.Device().synchronize()

        print(f"GPU ({cupy.cuda.runtime.getDeviceProperties(0)['name'].decode()}): blended poses of "
              f"{len(movers)} parts {ms(sample):.2f} ms")  # fmt: skip
    except Exception as exc:  # noqa: BLE001 - report what a device run met, and go on
        print(f"GPU: the CuPy run failed: {type(exc).__name__}: {exc}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=65_000)
    parser.add_argument("--streams", type=int, default=1024)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--transitions", type=int, default=4096)
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    args = parser.parse_args()
    for name in ("cmu-mocap-bvh/01_01.bvh", "fox-gltf/Fox.glb", "robot-expressive-gltf/RobotExpressive.glb"):
        path = Path(args.data) / name
        if path.is_file():
            begin = time.perf_counter()
            clips = flockkit.io.read_clips(path)
            frames = sum(c.n_frames for c in clips.values())
            print(f"read_clips({name}): {len(clips)} clips, {frames} frames in {time.perf_counter() - begin:.3f} s")
    start = time.perf_counter()
    pool, clusters, bones, histories, stopped = build(args.agents, args.streams)
    crowd = Crowd(pool, n_agents=args.agents, clusters=clusters, seed=1)
    setup = time.perf_counter() - start
    parts = sum(int(np.sum(c >= 0)) for c in clusters.values())
    print(f"{args.agents} agents, {parts} agent parts in {len(SKELETONS)} clusters, {args.streams} streams "
          f"({int(stopped.sum())} Stopped by default), histories 20..120; set up in {setup:.1f} s")  # fmt: skip
    for _ in range(40):  # past the streams' first refills
        crowd.update()
    rng = np.random.default_rng(2)
    movers = rng.choice(args.agents, size=args.transitions, replace=False)
    celebrations = np.flatnonzero((bones == 82) & stopped)
    begin = time.perf_counter()
    for k, group in enumerate(np.array_split(movers, 16)):  # 16 celebration streams start at once
        crowd.transition_to_streamed(group, "body", int(celebrations[k]), blend_time=0.5, time_to_dilate=2.0)
    transition = (time.perf_counter() - begin) * 1000
    updates = []
    for _ in range(args.frames):
        begin = time.perf_counter()
        crowd.update()
        updates.append((time.perf_counter() - begin) * 1000)
        if len(updates) == 5:  # mid-blend: sample the 4 096 blending parts
            blended = ms(lambda: crowd.poses(movers, "body"))
            blended_world = ms(lambda: crowd.poses(movers, "body", space="world"), repeat=3)
            assert np.all(crowd.alphas("body")[movers] > 0)
    buffer = ms(lambda: crowd.instance_buffer())
    copied = ms(lambda: crowd.instance_buffer().copy())
    updates = np.array(updates)
    print(f"{args.transitions} body parts transition at once: {transition:.1f} ms for the 16 calls")
    print(f"update: mean {updates.mean():.2f} ms, median {np.median(updates):.2f} ms, worst {updates.max():.2f} ms "
          f"over {args.frames} frames (target: update + instance_buffer <= 5 ms)")  # fmt: skip
    print(f"instance_buffer: {buffer:.3f} ms (a read-only view; copying it: {copied:.2f} ms, "
          f"{crowd.instance_buffer().nbytes / 2**20:.1f} MB)")  # fmt: skip
    print(f"blended poses of {args.transitions} parts: local {blended:.2f} ms (target <= 3 ms), "
          f"world (forward kinematics) {blended_world:.2f} ms")  # fmt: skip
    total_new = equation_5(bones, histories)
    total_prev = equation_4(bones, histories, transitions=args.transitions)
    print(f"memory: pool {pool.memory() / 2**20:.1f} MB; Equation 5 {total_new / 2**20:.1f} MB "
          f"({'equal' if pool.memory() == total_new else 'NOT EQUAL'}); Equation 4 (every stream padded to 82 "
          f"joints and 120 frames, {args.transitions} transition slots) {total_prev / 2**20:.1f} MB; "
          f"difference (Equation 6) {(total_prev - total_new) / 2**20:.1f} MB")  # fmt: skip
    gpu(args, movers, celebrations)
    # naive: each agent part evaluates its own controller every frame
    sample = [pool.streams[int(s)].controller for s in clusters["body"][:1500]]
    begin = time.perf_counter()
    for k, controller in enumerate(sample):
        controller.pose([k / 30.0])
    per_part = (time.perf_counter() - begin) / len(sample) * 1000
    naive = per_part * parts
    ours = updates.mean() + buffer
    print(f"naive per-agent evaluation: {per_part * 1000:.1f} us per part (measured on {len(sample)} parts) x "
          f"{parts} parts = {naive:.0f} ms per frame; flockkit {ours:.2f} ms: {naive / ours:.0f}x faster")  # fmt: skip


if __name__ == "__main__":
    main()
