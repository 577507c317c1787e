"""Per-frame cost of part hooks, a look-at override and root motion for a crowd, beside a vectorized
numpy peer doing the same work.

    python bench/crowd_parts.py [--agents 10000] [--frames 60]
    python bench/crowd_parts.py --quick     # 1 000 agents, 20 frames

The character is the Fox of the glTF samples (25 joints; the kit's 11-joint walker where the
shared data is absent), its Walk and Run clips in two streams, every agent carrying a 3-joint
flag hung on its head (a ``Hook`` with a fixed offset) and a ``LookAt`` on the head. Per frame,
the median over the frames of:

- hook: ``Crowd.poses(cluster="flag", space="world")`` (the body's and the flag's local poses
  read, both forward kinematics, the flag placed at the head) against the peer: the same local
  poses read by ``Crowd.poses`` and both skeletons' forward kinematics written here in numpy
  (level by level), the flag's matrices left-multiplied by head @ offset;
- look-at: ``Crowd.poses(cluster="body")`` with the override against the peer: ``poses()``
  without it plus a numpy look-at written here (the head's parent by forward kinematics along its
  chain, the shortest turn of the head's forward onto the target, clamped to the cone, weighted);
  and ``poses()`` alone, the cost the override adds to;
- root motion: ``Crowd.update()`` with ``root_motion=`` against without (each agent's step read
  from its stream's root track and composed), and the peer: numpy composing one ground step per
  agent from the same reads.

Each pair is checked equal on the last frame.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import flockkit
from flockkit.crowd import Crowd, Hook, LookAt, Pose, SkeletalClip, Skeleton, Stream, StreamPool
from flockkit.rigid import quaternion_matrix, quaternion_product
from flockkit.testing import inputs

FOX = Path(__file__).resolve().parents[2] / "shared" / "data" / "fox-gltf" / "Fox.glb"


def character():
    if FOX.is_file():
        clips = flockkit.io.read_clips(FOX)
        return "Fox (25 joints)", [clips["Walk"], clips["Run"]], "b_Head_05", np.array([0.0, 0.0, 1.0])
    walker = inputs.walker()
    return "walker (11 joints; no shared data)", [walker, walker], "head", np.array([0.0, 1.0, 0.0])


def flag(fps=30.0):
    skeleton = Skeleton(names=["pole", "cloth", "tip"], parents=[-1, 0, 1],
                        rest=Pose(rotations=np.tile([0.0, 0, 0, 1], (3, 1)),
                                  translations=[[0, 0, 0], [0, 0, 4.0], [3.0, 0, 0]]))  # fmt: skip
    phase = 2 * np.pi * np.arange(31) / 30
    rotations = np.tile([0.0, 0, 0, 1], (31, 3, 1))
    rotations[:, 1, 2], rotations[:, 1, 3] = np.sin(0.4 * np.sin(phase)), np.cos(0.4 * np.sin(phase))
    return SkeletalClip(skeleton=skeleton, fps=fps, rotations=rotations, translations=np.zeros((31, 3)))


def forward_kinematics(skeleton, pose):
    """World matrices (n, J, 4, 4), written out: T R S per joint, then parents first, level by level."""
    q = pose.rotations.astype(np.float64)
    m = np.zeros(q.shape[:-1] + (4, 4))
    m[..., :3, :3] = quaternion_matrix(q) * skeleton.scales[None, :, None, :]
    m[..., :3, 3] = pose.translations
    m[..., 3, 3] = 1
    for level in range(1, int(skeleton.depth.max()) + 1):
        joints = np.flatnonzero(skeleton.depth == level)
        m[:, joints] = m[:, skeleton.parents[joints]] @ m[:, joints]
    return m


def look_peer(skeleton, pose, head, forward, targets, origins, limit, weights):
    """Local rotations (n, J, 4) with the head turned onto `targets` (world) within `limit`."""
    chain, k = [], skeleton.parents[head]
    while k >= 0:
        chain.append(k)
        k = skeleton.parents[k]
    n = len(targets)
    above = np.tile(np.eye(4), (n, 1, 1))
    for k in reversed(chain):
        m = np.zeros((n, 4, 4))
        m[:, :3, :3] = quaternion_matrix(pose.rotations[:, k].astype(np.float64)) * skeleton.scales[k]
        m[:, :3, 3], m[:, 3, 3] = pose.translations[:, k], 1
        above = above @ m
    r = above[:, :3, :3] / np.linalg.norm(above[:, :3, :3], axis=1, keepdims=True)
    position = np.einsum("nij,nj->ni", above[:, :3, :3], pose.translations[:, head]) + above[:, :3, 3]
    facing = np.einsum("nij,j->ni", r @ quaternion_matrix(pose.rotations[:, head].astype(np.float64)), forward)
    local_target = np.linalg.solve(origins, np.concatenate([targets, np.ones((n, 1))], 1)[..., None])[:, :3, 0]
    wanted = local_target - position
    wanted /= np.linalg.norm(wanted, axis=1, keepdims=True)
    axis = np.cross(facing, wanted)
    angle = np.arctan2(np.linalg.norm(axis, axis=1), np.sum(facing * wanted, axis=1))
    axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    turn = np.minimum(angle, limit) * weights / 2
    change = np.concatenate([np.sin(turn)[:, None] * np.einsum("nji,nj->ni", r, axis), np.cos(turn)[:, None]], 1)
    out = pose.rotations.astype(np.float64).copy()
    out[:, head] = quaternion_product(change, out[:, head])
    return out


def median_ms(samples):
    return 1000 * float(np.median(samples))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=10_000)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--quick", action="store_true", help="1 000 agents, 20 frames")
    args = parser.parse_args()
    n, frames = (1_000, 20) if args.quick else (args.agents, args.frames)
    name, clips, head_name, forward = character()
    body = clips[0].skeleton
    head = body.index(head_name)
    play = lambda clip, **k: flockkit.get("controller", "clip", clip=clip, **k)  # noqa: E731
    streams = [Stream(controller=play(clips[0]), history=48), Stream(controller=play(clips[1]), history=48),
               Stream(controller=play(flag()), history=30)]  # fmt: skip
    limit = np.radians(60)
    look = LookAt(head_name, n_agents=n, forward=forward, max_angle=limit, blend_time=0.3)
    offset = np.eye(4)
    offset[:3, 3] = [0.0, 5.0, 2.0]
    clusters = {"body": np.arange(n) % 2, "flag": 2}
    # one crowd with the hook, one with the look-at: each measured alone
    crowd = Crowd(StreamPool(streams, fps=30), n_agents=n, clusters=clusters, seed=0,
                  hooks=[Hook(part="flag", parent="body", joint=head_name, offset=offset)])  # fmt: skip
    looking = Crowd(StreamPool(streams, fps=30), n_agents=n, clusters={"body": np.arange(n) % 2}, seed=0,
                    overrides={"body": [look]})  # fmt: skip
    rng = np.random.default_rng(1)
    looking.placement[:, :2, 3] = rng.uniform(-500, 500, (n, 2))
    targets = rng.uniform(-500, 500, (n, 3))
    look.look(np.arange(n), targets, time=0.0)
    plain = Crowd(StreamPool(streams, fps=30), n_agents=n, clusters={"body": np.arange(n) % 2}, seed=0)
    print(f"{n} agents of the {name} with a 3-joint flag hung on {head_name!r} and a look-at on it; {frames} frames")

    timings = {key: [] for key in ("hook", "hook peer", "look", "look peer", "plain poses")}
    for _ in range(frames):
        crowd.update()
        looking.update()
        t0 = time.perf_counter()
        flags = crowd.poses(cluster="flag", space="world")
        t1 = time.perf_counter()
        body_local, flag_local = crowd.poses(cluster="body"), crowd.poses(cluster="flag")
        anchor = forward_kinematics(body, body_local)[:, head] @ offset
        peer_flags = anchor[:, None] @ forward_kinematics(crowd.skeletons[1], flag_local)
        t2 = time.perf_counter()
        looked = looking.poses(cluster="body")
        t3 = time.perf_counter()
        base = looking._entries(np.arange(n), 0)  # the blended pose before the override
        base_pose = Pose._adopt(base[..., 0:4], base[..., 4:7])
        weights = look.weights(looking.time)
        peer_look = look_peer(body, base_pose, head, forward, targets, looking.placement, limit, weights)
        t4 = time.perf_counter()
        plain.update()
        t5 = time.perf_counter()
        plain.poses(cluster="body")
        t6 = time.perf_counter()
        for key, dt in zip(timings, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t6 - t5)):
            timings[key].append(dt)
    hook_error = np.abs(flags - peer_flags).max() / np.ptp(peer_flags[..., :3, 3])
    look_error = np.abs(np.abs(np.sum(looked.rotations * peer_look, axis=-1)) - 1).max()
    print("per frame, median (ms):")
    print(
        f"  hook:    flockkit poses(flag, world) {median_ms(timings['hook']):.2f}; numpy peer (same reads, FK of "
        f"both, anchor) {median_ms(timings['hook peer']):.2f}; equal within {hook_error:.1e} of the spread"
    )
    print(f"  look-at: flockkit poses(body) with LookAt {median_ms(timings['look']):.2f}; numpy peer (the blended "
          f"pose, then look-at) {median_ms(timings['look peer']):.2f}; poses(body) without an override "
          f"{median_ms(timings['plain poses']):.2f}; rotations equal within 1 - |q.q'| = {look_error:.1e}")  # fmt: skip

    # root motion: update with and without it, and a numpy peer of the step from the same reads
    strider = flockkit.crowd.extract_root_motion(inputs.strider())
    rooted = [Stream(controller=play(strider, rate=r), history=48) for r in (0.8, 1.0, 1.3)]
    moving = Crowd(StreamPool(rooted, fps=30), n_agents=n, clusters={"body": np.arange(n) % 3}, seed=0,
                   root_motion="body")  # fmt: skip
    still = Crowd(StreamPool(rooted, fps=30), n_agents=n, clusters={"body": np.arange(n) % 3}, seed=0)
    with_roots, without, peer = [], [], []
    ground = np.zeros((n, 3))  # x, y, heading (z up)
    record = moving.instance_buffer()
    last = moving.pool.root_at(record["stream"][:, 0], record["offset"][:, 0])
    for _ in range(frames):
        t0 = time.perf_counter()
        moving.update()
        t1 = time.perf_counter()
        still.update()
        t2 = time.perf_counter()
        now = moving.pool.root_at(record["stream"][:, 0], record["offset"][:, 0])
        c, s = np.cos(last[:, 3]), np.sin(last[:, 3])
        dx, dy = now[:, 0] - last[:, 0], now[:, 1] - last[:, 1]
        lx, ly = c * dx + s * dy, -s * dx + c * dy  # the step in the agent's own frame
        c, s = np.cos(ground[:, 2]), np.sin(ground[:, 2])
        ground = ground + np.stack([c * lx - s * ly, s * lx + c * ly, now[:, 3] - last[:, 3]], axis=1)
        last = now
        t3 = time.perf_counter()
        with_roots.append(t1 - t0)
        without.append(t2 - t1)
        peer.append(t3 - t2)
    root_error = np.abs(moving.roots()[:, :2, 3] - ground[:, :2]).max()
    print(
        f"  root motion: update() with root_motion {median_ms(with_roots):.2f}, without "
        f"{median_ms(without):.2f} (the step costs {median_ms(with_roots) - median_ms(without):.2f}); numpy peer "
        f"of the step from the same reads {median_ms(peer):.2f}; roots equal within {root_error:.1e} units"
    )


if __name__ == "__main__":
    main()
