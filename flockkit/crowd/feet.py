"""Feet that stay put: how fast a locomotion clip pushes its feet back, how much a crowd's feet
slide, and foot-skate cleanup that plants a clip's feet (Kovar, Schreiner and Gleicher 2002,
"Footskate cleanup for motion capture editing", simplified to looping clips played in place).

An agent playing a walk in place while its root moves at speed v keeps a foot still when the clip
moves that foot back at v while it carries the body. Hand-keyed and captured clips rarely do: the
Fox's Walk moves its planted paws back at speeds that vary by half from frame to frame, and one
paw creeps forward, so no playback rate stops them sliding. ``plant_feet`` rewrites such a clip
so that each foot, while low, moves back in a straight line at one speed, by two-joint inverse
kinematics on its leg. The result is an ordinary clip, shared by every agent of a stream.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .. import validate
from ..errors import ValidationError
from ..skeleton import Pose, SkeletalClip
from .drive import CLIP_CONTROLLER, DEFAULT_FORWARD, _axis, character_axes

__all__ = ["ground_speed", "foot_sliding", "driven_sliding", "plant_feet"]


def ground_speed(clip: SkeletalClip, feet, *, up=None, forward=None, scale=None) -> float:
    """How fast `clip` (played in place at rate 1) pushes its lowest foot backwards, in world units
    per second (clip units times `scale`): the speed at which an agent playing it does not slide.
    `feet` are joint names; the median over the frames of the lowest foot's backward speed, each
    foot's height counted from its own lowest (a paw's joint sits higher above the ground than a
    toe's), height along the character's `up` axis. `up`, `forward` and `scale` default as a
    ``Driver`` places the character: the skeleton's up axis, its forward and its metres per unit."""
    up, forward, scale = character_axes(clip.skeleton, up=up, forward=forward, scale=scale, owner="ground_speed")
    positions = clip.skeleton.positions(Pose._adopt(clip.rotations, clip.translations))
    index = [clip.skeleton.index(f) for f in feet]
    u, f = _axis(up, "up"), _axis(forward, "forward")
    heights = positions[:, index, u]
    lowest = np.asarray(index)[np.argmin(heights - heights.min(axis=0), axis=1)]
    along = np.gradient(positions[:, :, f], 1.0 / clip.fps, axis=0)
    return float(-np.median(along[np.arange(len(lowest)), lowest]) * scale)


def foot_sliding(joints: np.ndarray, feet, *, dt: float) -> float:
    """The mean horizontal speed (world units per second, z up) of the lowest of `feet` (joint
    indices; each foot's height counted from its own lowest) over frames and agents, from world
    joint positions (F, N, J, 3): zero for feet that stay put while they carry the body."""
    feet = np.asarray(feet)
    heights = joints[:, :, feet, 2]
    lowest = np.argmin(heights - heights.min(axis=0, keepdims=True), axis=2)  # (F, N)
    chosen = np.take_along_axis(joints[:, :, feet, :2], lowest[..., None, None], axis=2)[:, :, 0]
    speed = np.linalg.norm(np.diff(chosen, axis=0), axis=-1) / dt
    same = lowest[1:] == lowest[:-1]  # a change of foot is not a slide
    return float(speed[same].mean()) if same.any() else 0.0


def driven_sliding(motion, walk: SkeletalClip, idle: SkeletalClip, feet, rates, *, scale=None, up=None, forward=None,
                   fps: float | None = None, idle_below: float = 0.2, controller=CLIP_CONTROLLER) -> float:  # fmt: skip
    """The foot sliding (``foot_sliding``, world units per second) of a crowd that follows
    `motion` (one agent each) idling below `idle_below` and walking above it on streams of
    `walk` at `rates`, each agent on the one whose ground speed is nearest its own (one rate:
    fixed-rate playback). A measure of how well a clip and its rates fit a group's speeds; at
    `fps` (default the motion's). `controller` plays a clip (a name or factory taking clip= and
    rate=). `scale`, `up` and `forward` as for ``Driver`` (by default the skeleton's)."""
    from ..registry import require, resolve
    from .drive import Driver, Gait, StateMachine
    from .pool import Stream, StreamPool
    from .runtime import Crowd

    fps = 1.0 / motion.dt if fps is None else fps
    up, forward, scale = character_axes(walk.skeleton, up=up, forward=forward, scale=scale, owner="driven_sliding")
    natural = ground_speed(walk, feet, up=up, forward=forward, scale=scale)
    require("controller", controller, "clip_player", "driven_sliding's streams")
    streams = [Stream(controller=resolve("controller", controller, clip=clip, rate=r), history=40)
               for clip, r in [(idle, 1.0), *((walk, r) for r in rates)]]  # fmt: skip
    crowd = Crowd(StreamPool(streams, fps=fps), n_agents=motion.n_agents, clusters={"body": 1}, seed=0)
    walking = Gait(name="walk", streams=list(range(1, len(rates) + 1)), speeds=[natural * r for r in rates],
                    low=idle_below)  # fmt: skip
    machine = StateMachine([Gait(name="idle", streams=0, high=idle_below), walking])
    driver = Driver(crowd, motion, machine, up=up, forward=forward, scale=scale)
    joints = []
    for _ in range(int(round(motion.duration * fps))):
        driver.step()
        joints.append(driver.world()[..., :3, 3])
    return foot_sliding(np.array(joints), [walk.skeleton.index(f) for f in feet], dt=1 / fps)


def plant_feet(clip: SkeletalClip, legs, *, up=None, forward=None, speed: float | None = None, contact: float = 0.25,
               ease: int = 2) -> SkeletalClip:  # fmt: skip
    """A copy of the looping locomotion `clip` whose feet, while they carry the body, move back in
    a straight line at one `speed`: played in place on a root moving forward at that speed (times
    the playback rate), they stay put.

    Parameters
    ----------
    clip : SkeletalClip
        A loop played in place: its last frame is its first. The result is frames at `clip.fps`
        (a clip of channels is planted on its frames, so keys between them are not kept).
    legs : sequence of (upper, middle, foot)
        Joint names per leg: `upper` and `middle` are the joints inverse kinematics turns (a hip
        and a knee, a shoulder and an elbow); `foot` is the joint that must stay put, below
        `middle` (a paw, an ankle; joints between `middle` and `foot` keep their rotations).
    up, forward : str, optional
        The character's up and forward axes: heights are along `up`, feet move back along
        `forward`. Default the skeleton's up axis (glTF and BVH: "y") and its
        ``DEFAULT_FORWARD`` (glTF's "z" for y up).
    speed : float, optional
        Clip units per second. None: the clip's own, the distance its feet travel back while
        planted over the time they are planted (all feet together).
    contact : float
        A foot carries the body while its height is within this share of its height range above
        its lowest (0 < contact < 1).
    ease : int
        Frames over which the correction fades in before and out after each contact.

    Each contact's foot holds its mean sideways position and its lowest height, and moves back
    through its mean forward position at the contact's middle. Where a target is out of the leg's
    reach the leg stretches straight towards it.
    """
    if not isinstance(clip, SkeletalClip):
        raise ValidationError(f"plant_feet needs a flockkit.SkeletalClip; got {type(clip).__name__}")
    if clip.n_frames < 3:
        raise ValidationError(f"plant_feet needs a looping clip of 3 frames or more; {clip.name!r} has {clip.n_frames}")
    validate.number(contact, "plant_feet contact", minimum=0, strict=True)
    if contact >= 1:
        raise ValidationError(f"plant_feet contact must be a share below 1; got {contact}")
    ease = validate.integer(ease, "plant_feet ease", minimum=0)
    skeleton = clip.skeleton
    chains = _legs(skeleton, legs)
    up = skeleton.up_axis if up is None else up
    u = _axis(up, "up")
    forward = DEFAULT_FORWARD[up] if forward is None else forward
    f = _axis(forward, "forward")
    period = clip.n_frames - 1  # frames of one loop; frame `period` is frame 0 again
    world = skeleton.world(Pose._adopt(clip.rotations, clip.translations))
    positions = world[:period, :, :3, 3]
    contacts = [_contacts(positions[:, foot, u], contact) for _, _, foot in chains]
    if speed is None:
        back = sum(positions[run[0], foot, f] - positions[run[-1], foot, f]
                   for (_, _, foot), runs in zip(chains, contacts) for run in runs)  # fmt: skip
        planted = sum(len(run) - 1 for runs in contacts for run in runs) / clip.fps
        if planted <= 0 or back <= 0:
            raise ValidationError(
                f"plant_feet: clip {clip.name!r} does not move its feet back along {forward!r} while they are low "
                "(is it a walk played in place, and are up and forward its axes?)"
            )
        speed = back / planted
    speed = validate.number(speed, "plant_feet speed", minimum=0, strict=True)
    rotations = np.array(clip.rotations)
    for (upper, middle, foot), runs in zip(chains, contacts):
        hinge = _hinge(world, upper, middle, foot)
        target, weight = _targets(positions[:, foot], runs, u, f, speed / clip.fps, ease)
        frames = np.flatnonzero(weight > 0)
        if len(frames):
            raw = positions[frames, foot]
            goal = raw + weight[frames, None] * (target[frames] - raw)
            pose = Pose._adopt(rotations[frames], clip.translations[frames])
            rotations[frames] = _reach(skeleton, pose, upper, middle, foot, hinge, goal)
    rotations[period] = rotations[0]
    return SkeletalClip(skeleton=skeleton, fps=clip.fps, rotations=rotations, translations=clip.translations,
                        events=clip.events, name=clip.name)  # fmt: skip


def _legs(skeleton, legs) -> list:
    chains = []
    for k, leg in enumerate(legs):
        if isinstance(leg, str) or len(leg) != 3:
            raise ValidationError(f"plant_feet legs[{k}] must be (upper, middle, foot) joint names; got {leg!r}")
        upper, middle, foot = (skeleton.index(name) for name in leg)
        below_upper, below_middle = skeleton.descendants(leg[0]), skeleton.descendants(leg[1])
        if middle == upper or foot == middle or not below_upper[middle] or not below_middle[foot]:
            raise ValidationError(f"plant_feet legs[{k}]: {leg[2]!r} must be below {leg[1]!r}, below {leg[0]!r}")
        chains.append((upper, middle, foot))
    if not chains:
        raise ValidationError("plant_feet needs at least one leg")
    return chains


def _contacts(height: np.ndarray, share: float) -> list:
    """Runs of consecutive frames (wrapping around the loop) where `height` is within `share` of
    its range above its lowest: each a list of frame indices in time order."""
    low = height - height.min() <= share * (height.max() - height.min())
    n = len(low)
    if low.all():
        return [list(range(n))]
    start = int(np.flatnonzero(~low)[0])  # begin scanning at a lifted frame, so no run is cut by the wrap
    runs, run = [], []
    for k in range(start, start + n):
        if low[k % n]:
            run.append(k % n)
        elif run:
            runs.append(run)
            run = []
    if run:
        runs.append(run)
    return runs


def _targets(foot: np.ndarray, runs, u: int, f: int, step: float, ease: int):
    """Where the foot should be (period, 3) and how much of the correction applies (period,)."""
    n = len(foot)
    target, weight = foot.copy(), np.zeros(n)
    ground = foot[:, u].min()
    for run in runs:
        mean = foot[run].mean(axis=0)
        middle = (len(run) - 1) / 2
        for offset in range(-ease, len(run) + ease):
            k = (run[0] + offset) % n
            outside = -offset if offset < 0 else max(offset - len(run) + 1, 0)  # frames from the contact
            fade = 1 - outside / (ease + 1)
            if fade <= weight[k]:
                continue
            target[k] = mean
            target[k, u] = ground
            target[k, f] = mean[f] - step * (offset - middle)
            weight[k] = fade
    return target, weight


def _hinge(world: np.ndarray, upper: int, middle: int, foot: int) -> np.ndarray:
    """The axis (3,) in `upper`'s frame about which the leg's middle joint bends over the frames
    of world joint matrices (T, J, 4, 4): the mean normal of the planes (upper, middle, foot), so
    that inverse kinematics bends every frame's knee the way the clip bends it most."""
    a, b, c = (world[:, j, :3, 3] for j in (upper, middle, foot))
    normals = _rotation(world[:, upper]).inv().apply(np.cross(c - b, a - b))
    return _unit(normals.sum(axis=0))


def _reach(skeleton, pose: Pose, upper: int, middle: int, foot: int, hinge: np.ndarray, goal: np.ndarray):
    """Rotations (F, J, 4) of `pose` with `upper` and `middle` turned so that `foot` reaches
    `goal` (F, 3): the middle joint bends about `hinge` (in `upper`'s frame; see ``_hinge``) to
    the distance, never through straight, then the upper joint aims (two-joint inverse
    kinematics)."""
    world = skeleton.world(pose)
    a, b, c = (world[:, j, :3, 3] for j in (upper, middle, foot))
    along, back = c - b, a - b
    l1, l2 = np.linalg.norm(back, axis=1), np.linalg.norm(along, axis=1)
    reach = np.clip(np.linalg.norm(goal - a, axis=1), np.abs(l1 - l2) + 1e-9, (l1 + l2) * (1 - 1e-9))
    wanted = np.arccos(np.clip((l1**2 + l2**2 - reach**2) / (2 * l1 * l2), -1, 1))  # the angle at the knee
    normal = np.cross(along, back)  # turning `along` about it closes the knee
    reference = _rotation(world[:, upper]).apply(hinge)
    side = np.where(np.sum(normal * reference, axis=1) < 0, -1.0, 1.0)
    axis = np.where(
        (np.linalg.norm(normal, axis=1) < 1e-6 * l1 * l2)[:, None], reference, side[:, None] * _unit(normal)
    )
    bent_now = side * (np.pi - _angle(along, back))  # how far the knee is from straight, signed by the hinge
    bend = Rotation.from_rotvec(axis * ((np.pi - wanted) - bent_now)[:, None])
    bent = b + bend.apply(along) - a
    aim = Rotation.from_rotvec(_unit(np.cross(bent, goal - a)) * _angle(bent, goal - a)[:, None])
    rotations = np.array(pose.rotations)
    for joint, turn in ((middle, bend), (upper, aim)):
        parent = skeleton.parents[joint]
        above = Rotation.identity(len(goal)) if parent < 0 else _rotation(world[:, parent])
        # a world-space turn of the joint, written in its parent's frame
        local = above.inv() * turn * above * Rotation.from_quat(rotations[:, joint])
        rotations[:, joint] = local.as_quat()
    return rotations


def _rotation(matrices: np.ndarray) -> Rotation:
    """The rotations of world matrices (F, 4, 4) whose joints scale uniformly."""
    linear = matrices[:, :3, :3]
    return Rotation.from_matrix(linear / np.linalg.norm(linear, axis=1, keepdims=True))


def _angle(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.arctan2(np.linalg.norm(np.cross(x, y), axis=-1), np.sum(x * y, axis=-1))


def _unit(v: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0)
