"""Inputs the conformance kit makes itself, so that checking a component needs no built-in plugin.

``recording`` is a group motion written down in closed form; ``graph`` is a motion graph over it
whose transitions are known exactly. Both are deterministic, and cached per process.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .. import rigid
from ..graphs import MotionGraph
from ..mesh import AnimatedMesh, MeshSkin
from ..motion import Alignment, Configuration, Motion

__all__ = [
    "recording",
    "graph",
    "loop_graph",
    "parts",
    "chain_skin",
    "limbs",
    "plants",
    "walker",
    "bird",
    "random_clip",
    "degenerate_configurations",
    "WOBBLE_PERIOD",
]

# The group circles the origin once every LAP seconds while its members wobble about their places
# every WOBBLE_PERIOD seconds. The two periods are incommensurate, so a configuration recurs up
# to a rigid motion (a turn about the origin) every WOBBLE_PERIOD seconds, not in place.
LAP = 9.0
WOBBLE_PERIOD = 2.3
_RADIUS = 4.0  # of the circle the group's center follows, in length units


def recording(*, n_agents: int = 6, seconds: float = 12.0, dims: int = 2, dt: float = 0.1, seed: int = 0) -> Motion:
    """A group of `n_agents` circling the origin (in the xy plane, radius 4, about 2.8 length units
    per second), its members holding places about one unit apart in the group's heading frame, each
    wobbling on its own ellipse every ``WOBBLE_PERIOD`` seconds (and, in 3D, up and down).

    Frames WOBBLE_PERIOD seconds apart are the same configuration up to a turn about the origin,
    exactly, so the motion has transitions for a builder to find and for ``graph`` to take. Each
    call returns a new Motion (a check may hand it to a component that breaks it)."""
    return Motion(positions=_positions(n_agents, seconds, dims, dt, seed), dt=dt)


@functools.lru_cache(maxsize=16)
def _positions(n_agents, seconds, dims, dt, seed) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(round(seconds / dt) + 1) * dt
    places = rng.normal(0.0, 1.0, (n_agents, dims))
    axes = rng.normal(0.0, 0.25, (n_agents, dims))
    phases = rng.uniform(0.0, 2 * math.pi, n_agents)
    wobble = 2 * math.pi * t[:, None] / WOBBLE_PERIOD + phases  # (T, N)
    local = places + np.sin(wobble)[..., None] * axes + np.cos(wobble)[..., None] * axes[:, ::-1]
    angle = 2 * math.pi * t / LAP
    turn = np.zeros((len(t), dims, dims))
    turn[:, :2, :2] = [[[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]] for a in angle]
    if dims == 3:
        turn[:, 2, 2] = 1.0
    center = np.zeros((len(t), dims))
    center[:, 0], center[:, 1] = _RADIUS * np.cos(angle), _RADIUS * np.sin(angle)
    # the group's frame: x along the heading (tangent to the circle), so local x points ahead
    heading = rigid.rotate(turn, np.eye(dims)[1])
    frame = np.zeros_like(turn)
    frame[:, :, 0] = heading
    frame[:, :2, 1] = np.stack([-heading[:, 1], heading[:, 0]], axis=1)
    if dims == 3:
        frame[:, 2, 2] = 1.0
    positions = center[:, None, :] + rigid.rotate(frame[:, None], local)
    positions.setflags(write=False)
    return positions


@functools.lru_cache(maxsize=8)
def graph(*, dims: int = 2, blend: int = 5) -> MotionGraph:
    """A motion graph over ``recording(n_agents=6, seconds=12, dims=dims)`` with a transition each
    way between every other frame and the frame WOBBLE_PERIOD seconds later (the same
    configuration, turned): made without any metric or builder, each alignment exact. Each
    transition blends over `blend` frames; with 0 a walk may take one transition right after
    another (a transition plays no frames), so a walk that always prefers transitions never
    advances."""
    motion = recording(dims=dims)
    lag = round(WOBBLE_PERIOD / motion.dt)
    transitions = []
    for start in range(0, motion.n_frames - lag - blend - 1, 2):
        for a, b in ((start, start + lag), (start + lag, start)):
            transitions.append((a, b, _alignment(motion, a, b), blend))
    return MotionGraph.assemble(motion, transitions, params={"lag": lag}, provenance={"builder": "flockkit.testing"})


@functools.lru_cache(maxsize=4)
def loop_graph(*, dims: int = 2) -> MotionGraph:
    """The smallest motion graph there is: frames 40..63 of ``recording(dims=dims)`` (2.3 s) and
    one transition from the last back to the first (the same configuration, turned). A walk has no
    choice: it plays the loop over and over."""
    motion = recording(dims=dims)
    start, stop = 40, 40 + round(WOBBLE_PERIOD / motion.dt)
    return MotionGraph.assemble(motion, [(stop, start, _alignment(motion, stop, start), 5)], params={},
                                provenance={"builder": "flockkit.testing"})  # fmt: skip


def _alignment(motion: Motion, a: int, b: int) -> Alignment:
    """The alignment of configuration b onto a with agents kept: Kabsch on the centered positions."""
    x, y = motion.positions[a], motion.positions[b]
    rotation = rigid.kabsch(x - x.mean(axis=0), y - y.mean(axis=0))
    translation = x.mean(axis=0) - rigid.rotate(rotation, y.mean(axis=0))
    residual = float(np.mean(np.sum((x - rigid.apply(rotation, translation, y)) ** 2, axis=1)))
    return Alignment(
        distance=residual, assignment=np.arange(motion.n_agents), rotation=rotation, translation=translation
    )


def parts(*, dims: int = 3, seconds: float = 6.0, dt: float = 0.1) -> tuple[Motion, np.ndarray]:
    """A motion of three groups of points and the group of each (0, 1, 2): group 0 (12 points)
    never moves; group 1 (16 points, a flap) swings about an axis in the first half and rests in
    the second; group 2 (16 points, a tail) rests in the first half and swings in the second. Each
    moving group is rigid, and the two move at different times, so any segmenter that splits by
    motion finds them."""
    rng = np.random.default_rng(12)
    t = np.arange(round(seconds / dt) + 1) * dt
    half = seconds / 2
    base = [rng.uniform(-1, 1, (12, dims)), rng.uniform(-1, 1, (16, dims)) + 3, rng.uniform(-1, 1, (16, dims)) - 3]
    positions = np.empty((len(t), 44, dims))
    positions[:, :12] = base[0]
    for group, (points, active) in enumerate(((base[1], t < half), (base[2], t >= half)), 1):
        angle = np.where(active, 0.6 * np.sin(2 * np.pi * 1.3 * group * t), 0.0)
        c, s = np.cos(angle), np.sin(angle)
        center = points.mean(axis=0)
        offset = points - center
        turned = np.empty((len(t), len(points), dims))
        turned[..., 0] = c[:, None] * offset[:, 0] - s[:, None] * offset[:, 1]
        turned[..., 1] = s[:, None] * offset[:, 0] + c[:, None] * offset[:, 1]
        if dims == 3:
            turned[..., 2] = offset[:, 2]
        columns = slice(12, 28) if group == 1 else slice(28, 44)
        positions[:, columns] = turned + center
    truth = np.repeat([0, 1, 2], [12, 16, 16])
    return Motion(positions=positions, dt=dt), truth


def chain_skin(points, groups, *, pieces: int = 2) -> MeshSkin:
    """A skin for points `points` (N, D) (a motion's first frame) split into `groups` (N,) ints:
    an empty root joint, and under it one chain of `pieces` joints per group (fewer for a group
    of fewer points), its points cut into `pieces` slabs along the first axis (by rank, ties in
    order of the points); each point weighs 0.75 on its slab's joint and 0.25 on the next joint
    of its chain (the previous for the last), 1 on it where the chain has one joint. Points of a
    group are skinned only by that group's joints, so a skin-aware segmenter sees the groups in
    the hierarchy and must merge each chain's joints where the group moves as one."""
    points = np.asarray(points, dtype=np.float64)
    groups = np.asarray(groups)
    names, parents = ["root"], [-1]
    joints = np.zeros((len(points), 2), dtype=np.int64)
    weights = np.zeros((len(points), 2))
    for g in np.unique(groups):
        members = np.flatnonzero(groups == g)
        count = min(pieces, len(members))
        first = len(names)
        for k in range(count):
            names.append(f"group{g}.{k}")
            parents.append(0 if k == 0 else first + k - 1)
        rank = np.empty(len(members), dtype=np.int64)
        rank[np.argsort(points[members, 0], kind="stable")] = np.arange(len(members))
        slab = rank * count // len(members)
        joints[members, 0] = first + slab
        if count == 1:
            joints[members, 1], weights[members] = first, (1.0, 0.0)
        else:
            joints[members, 1] = first + np.where(slab < count - 1, slab + 1, slab - 1)
            weights[members] = (0.75, 0.25)
    return MeshSkin(joint_names=names, parents=parents, joints=joints, weights=weights)


def limbs(*, dims: int = 3, seconds: float = 6.0, dt: float = 0.1) -> tuple[AnimatedMesh, np.ndarray]:
    """A skinned mesh whose parts are known: a body (a box of 40 points on two joints) that turns
    and travels as one rigid body, and two limbs (24 points each, on an upper and a lower joint
    that never bend against each other) hung from it by joints that dominate no vertex, each
    swinging about its shoulder at its own rate. (AnimatedMesh with a ``MeshSkin``, the part of
    each vertex: 0 body, 1 left limb, 2 right limb.) The limbs touch the body; each vertex of a
    limb is shared by its two joints (0.7 and 0.3); every part moves rigidly and the three
    independently, so a skin-aware segmenter must find exactly these three."""
    rng = np.random.default_rng(21)
    t = np.arange(round(seconds / dt) + 1) * dt
    shoulders = np.array([[0.0, 0.5, 0.0], [0.0, -0.5, 0.0]])
    body = rng.uniform([-1.0, -0.5, -0.5], [1.0, 0.5, 0.5], (40, 3))
    body[:2, 1], body[2:4, 1] = 0.45, -0.45  # where the limbs meet it, a point each side of each shoulder
    body[:4, [0, 2]] = np.tile([[0.05, 0.0], [-0.05, 0.0]], (2, 1))
    limb = [np.column_stack([rng.uniform(-0.2, 0.2, 24), side * rng.uniform(0.05, 1.5, 24), rng.uniform(-0.2, 0.2, 24)])
            + [0.0, side * 0.5, 0.0] for side in (1.0, -1.0)]  # fmt: skip
    for side, points in zip((1.0, -1.0), limb):
        points[:2] = [[0.05, side * 0.55, 0.0], [-0.05, side * 0.55, 0.0]]  # touching the body at the shoulder
    rest = np.concatenate([body, *limb])[:, :dims]
    truth = np.repeat([0, 1, 2], [40, 24, 24])

    def turn(angle, axis):  # (T, D, D) turns by `angle` (T,) about `axis` (x: 0, z: 2; in 2D always in the plane)
        c, s = np.cos(angle), np.sin(angle)
        out = np.tile(np.eye(dims), (len(angle), 1, 1))
        i, j = (0, 1) if dims == 2 or axis == 2 else (1, 2)
        out[:, i, i], out[:, i, j], out[:, j, i], out[:, j, j] = c, -s, s, c
        return out

    heading, travel = turn(0.4 * np.sin(2 * np.pi * t / seconds), 2), np.zeros((len(t), dims))
    travel[:, 0] = 0.5 * t
    positions = np.empty((len(t), len(rest), dims))
    for part, swing in ((0, None), (1, 1.2 * np.sin(2 * np.pi * 0.9 * t)), (2, 1.0 * np.sin(2 * np.pi * 1.7 * t + 1))):
        local = np.broadcast_to(rest[truth == part], (len(t), int(np.sum(truth == part)), dims))
        if swing is not None:
            pivot = shoulders[part - 1, :dims]
            local = np.einsum("tij,tnj->tni", turn(swing, 0), local - pivot) + pivot
        positions[:, truth == part] = np.einsum("tij,tnj->tni", heading, local) + travel[:, None]
    names = ["root", "body", "chest", "shoulder.L", "arm.L", "forearm.L", "shoulder.R", "arm.R", "forearm.R"]
    parents = [-1, 0, 1, 2, 3, 4, 2, 6, 7]
    joints = np.zeros((len(rest), 2), dtype=np.int64)
    weights = np.tile([0.7, 0.3], (len(rest), 1))
    joints[:40] = np.where(body[:, :1] < 0, [1, 2], [2, 1])
    for part, (upper, lower) in ((1, (4, 5)), (2, (7, 8))):
        far = np.abs(rest[truth == part, 1]) > 1.0
        joints[truth == part] = np.where(far[:, None], [lower, upper], [upper, lower])
    skin = MeshSkin(joint_names=names, parents=parents, joints=joints, weights=weights)
    return AnimatedMesh(motion=Motion(positions=positions, dt=dt), faces=np.zeros((0, 3), dtype=np.int64),
                        skin=skin), truth  # fmt: skip


def plants(*, dt: float = 0.1, seconds: float = 24.0, points: int = 8, rates=(1.7, 2.9)):
    """Two stalks of `points` points each that lean with a wind turning a quarter turn every 6 s
    (+x, +y, -x, -y: held 4 s, turning 2 s), each fluttering at its own rate (`rates`, Hz): (Motion (T, 2 *
    points, 3), the stalk of each point (0 or 1), Features: the wind, length 0.8). A source whose
    arrows point every way, for scenes and annotated walks."""
    from ..scene.features import Features

    keyframes = []
    for quarter in range(4):
        direction = [math.cos(quarter * math.pi / 2), math.sin(quarter * math.pi / 2)]
        keyframes += [(6.0 * quarter, direction), (6.0 * quarter + 4.0, direction)]
    keyframes.append((seconds, [1.0, 0.0]))
    n_frames = round(seconds / dt) + 1
    wind = Features.from_keyframes([(t, 0.8 * np.array(v)) for t, v in keyframes], n_frames=n_frames, dt=dt)
    t = np.arange(n_frames) * dt
    height = np.linspace(0.0, 1.0, points)
    positions = np.empty((n_frames, 2 * points, 3))
    for stalk, (x, rate) in enumerate(zip((-0.3, 0.3), rates)):
        lean = wind.vectors[:, :, None] * (0.5 + 0.1 * np.sin(2 * np.pi * rate * t))[:, None, None]  # (T, 2, 1)
        bend = height**2  # the tip bends most
        rows = slice(stalk * points, (stalk + 1) * points)
        positions[:, rows, 0] = x + lean[:, 0] * bend
        positions[:, rows, 1] = lean[:, 1] * bend
        positions[:, rows, 2] = height
    labels = np.repeat([0, 1], points)
    return Motion(positions=positions, dt=dt), labels, wind


def walker(*, fps: float = 30.0, seconds: float = 2.0, swing: float = 30.0):
    """A skeletal clip in closed form: a stick figure of eleven joints (hips, spine, head, arms,
    hands, legs, feet; z up, facing y) whose legs swing `swing` degrees each way once per
    `seconds` and arms swing against them, its spine swaying and hips bobbing, first frame equal
    to the last (it loops), with a "step" event at each quarter and three quarters of the cycle."""
    from ..skeleton import Event, Pose, SkeletalClip, Skeleton

    names = ["hips", "spine", "head", "arm.L", "hand.L", "arm.R", "hand.R", "leg.L", "foot.L", "leg.R", "foot.R"]
    parents = [-1, 0, 1, 1, 3, 1, 5, 0, 7, 0, 9]
    offsets = [[0, 0, 1.0], [0, 0, 0.45], [0, 0, 0.3], [-0.2, 0, 0.35], [0, 0, -0.55], [0.2, 0, 0.35],
               [0, 0, -0.55], [-0.12, 0, 0], [0, 0, -0.95], [0.12, 0, 0], [0, 0, -0.95]]  # fmt: skip
    skeleton = Skeleton(
        names=names, parents=parents, rest=Pose(rotations=np.tile([0.0, 0, 0, 1], (11, 1)), translations=offsets)
    )
    phase = 2 * np.pi * np.arange(int(round(seconds * fps)) + 1) / (seconds * fps)
    angle = np.radians(swing) * np.sin(phase)
    rotations = np.tile([0.0, 0.0, 0.0, 1.0], (len(phase), 11, 1))
    for joint, share in ((7, 1.0), (9, -1.0), (3, -0.6), (5, 0.6)):  # legs and arms swing about x
        rotations[:, joint, 0] = np.sin(share * angle / 2)
        rotations[:, joint, 3] = np.cos(share * angle / 2)
    rotations[:, 1, 1] = np.sin(0.05 * np.sin(phase))  # the spine sways about y
    rotations[:, 1, 3] = np.cos(0.05 * np.sin(phase))
    hips = np.zeros((len(phase), 3))
    hips[:, 2] = 1.0 + 0.03 * np.cos(2 * phase)
    events = [Event(time=seconds / 4, name="step"), Event(time=3 * seconds / 4, name="step")]
    return SkeletalClip(
        skeleton=skeleton, fps=fps, rotations=rotations, translations=hips, events=events, name="walker"
    )


def strider(*, fps: float = 30.0, seconds: float = 2.0, speed: float = 1.0, turn: float = 0.3, up: str = "z"):
    """The ``walker`` carrying root motion in closed form: its hips travel forward at `speed`
    units per second while the whole figure turns `turn` radians per second about its up axis
    (an arc), starting at the origin facing its forward axis; so its motion joint ("hips") is at
    ground position (speed / turn) (cos(turn t) - 1, sin(turn t)) (z up, facing y; a straight
    line (0, speed t) without a turn) with heading turn t. `up` "y" gives the same figure in a
    y-up model space (x to -x, y to z, z to y: facing z, as a glTF character does)."""
    from ..skeleton import Pose, SkeletalClip, Skeleton

    base = walker(fps=fps, seconds=seconds)
    t = np.arange(base.n_frames) / fps
    heading = turn * t
    if turn == 0:
        ground = np.stack([np.zeros_like(t), speed * t], axis=1)
    else:
        ground = speed / turn * np.stack([np.cos(heading) - 1, np.sin(heading)], axis=1)
    rotations = base.rotations.copy()
    rotations[:, 0] = np.stack([0 * t, 0 * t, np.sin(heading / 2), np.cos(heading / 2)], axis=1)
    translations = base.translations.copy()
    translations[:, 0, :2] = ground
    rest = base.skeleton.rest
    axes = np.eye(3) if up == "z" else np.array([[-1.0, 0, 0], [0, 0, 1], [0, 1, 0]])
    if up not in ("z", "y"):
        raise ValueError(f"strider: up must be 'z' or 'y'; got {up!r}")

    def turned(q):
        return np.concatenate([q[..., :3] @ axes.T, q[..., 3:]], axis=-1)

    rest = Pose(rotations=turned(rest.rotations), translations=rest.translations @ axes.T)
    skeleton = Skeleton(names=base.skeleton.names, parents=base.skeleton.parents, up_axis=up, rest=rest)
    return SkeletalClip(skeleton=skeleton, fps=fps, rotations=turned(rotations), translations=translations @ axes.T,
                        events=base.events, name="strider")  # fmt: skip


def bird(*, flapping: bool = True, fps: float = 30.0, seconds: float = 0.5):
    """A bird's skeletal clip in closed form (z up, facing y): a body with a head, a tail and two
    two-joint wings that beat 50 degrees each way (`flapping`, 2 beats a second at the default
    length) or hold a shallow glide with a slow sway; first frame equal to the last (it loops)."""
    from ..skeleton import Pose, SkeletalClip, Skeleton

    names = ["body", "head", "tail", "wing.L", "tip.L", "wing.R", "tip.R"]
    parents = [-1, 0, 0, 0, 3, 0, 5]
    offsets = [[0, 0, 0], [0, 0.12, 0.02], [0, -0.15, 0], [-0.05, 0, 0], [-0.25, 0, 0], [0.05, 0, 0], [0.25, 0, 0]]
    skeleton = Skeleton(
        names=names, parents=parents, rest=Pose(rotations=np.tile([0.0, 0, 0, 1], (7, 1)), translations=offsets)
    )
    phase = 2 * np.pi * np.arange(int(round(seconds * fps)) + 1) / (seconds * fps)
    beat = np.radians(50.0) * np.sin(phase) if flapping else np.radians(8.0) + np.radians(3.0) * np.sin(phase)
    bend = 0.4 * beat if flapping else 0.0 * beat
    rotations = np.tile([0.0, 0.0, 0.0, 1.0], (len(phase), 7, 1))
    for joint, angle in ((3, -beat), (4, -bend), (5, beat), (6, bend)):  # wings turn about the body's y axis
        rotations[:, joint, 1] = np.sin(angle / 2)
        rotations[:, joint, 3] = np.cos(angle / 2)
    return SkeletalClip(skeleton=skeleton, fps=fps, rotations=rotations, translations=np.zeros((len(phase), 3)),
                        name="flap" if flapping else "glide")  # fmt: skip


def random_clip(joints: int, *, frames: int = 60, fps: float = 30.0, seed: int = 0):
    """A skeletal clip of `joints` joints (a random tree) whose rotations wander smoothly (a few
    random sines per joint): any size of skeleton, for crowds and benchmarks."""
    from ..skeleton import Pose, SkeletalClip, Skeleton

    rng = np.random.default_rng(seed)
    parents = np.concatenate([[-1], [int(rng.integers(0, j)) for j in range(1, joints)]])
    rest = Pose(rotations=np.tile([0.0, 0.0, 0.0, 1.0], (joints, 1)), translations=rng.normal(0, 0.3, (joints, 3)))
    skeleton = Skeleton(names=[f"joint{j}" for j in range(joints)], parents=parents, rest=rest)
    t = np.arange(frames)[:, None, None] / fps
    rates, phases = rng.uniform(0.3, 2.0, (1, joints, 4)), rng.uniform(0, 2 * np.pi, (1, joints, 4))
    rotations = 0.3 * np.sin(2 * np.pi * rates * t + phases)
    rotations[..., 3] = 1.0
    rotations /= np.linalg.norm(rotations, axis=-1, keepdims=True)
    root = np.stack([np.sin(t[:, 0, 0]), np.cos(t[:, 0, 0]), 0.1 * t[:, 0, 0]], axis=1)
    return SkeletalClip(skeleton=skeleton, fps=fps, rotations=rotations, translations=root, name=f"random{joints}")


def degenerate_configurations(dims: int = 2) -> list[tuple[str, Configuration]]:
    """Configurations with ties and symmetries, as scikit-learn's checks feed estimators
    degenerate data: (label, configuration) for a square, a regular hexagon, a grid (3 x 3, or
    3 x 3 x 3 in 3D), five agents on one spot, three pairs of coincident agents, one agent, and
    seven agents evenly spaced on a line; each at rest, all heading one way, and (where there is
    a centre to turn about) turning about the centre. Distances to the centre, pairwise distances
    and principal spreads tie exactly, so a component that breaks ties by index or trusts
    principal axes meets inputs where that fails."""
    rng = np.random.default_rng(7)

    def flat(points):
        points = np.asarray(points, dtype=float)
        return np.column_stack([points, np.zeros((len(points), dims - 2))]) if dims == 3 else points

    def polygon(n):
        angle = np.arange(n) * 2 * math.pi / n
        return flat(np.column_stack([np.cos(angle), np.sin(angle)]))

    side = np.arange(3.0) - 1.0
    shapes = {
        "a square": polygon(4),
        "a regular hexagon": polygon(6),
        "a grid": np.stack(np.meshgrid(*[side] * dims, indexing="ij"), axis=-1).reshape(-1, dims),
        "five agents on one spot": np.tile(rng.normal(0, 1, dims), (5, 1)),
        "three pairs of coincident agents": np.repeat(rng.normal(0, 1, (3, dims)), 2, axis=0),
        "one agent": rng.normal(0, 1, (1, dims)),
        "seven agents on a line": np.outer(np.arange(7.0) - 3.0, np.eye(dims)[0]),
    }
    found = []
    for label, positions in shapes.items():
        centered = positions - positions.mean(axis=0)
        turning = np.zeros_like(positions)
        turning[:, 0], turning[:, 1] = -centered[:, 1], centered[:, 0]
        heading = np.tile(np.eye(dims)[0], (len(positions), 1))
        motions = {"at rest": np.zeros_like(positions), "heading one way": heading}
        if np.any(turning):
            motions["turning"] = turning
        for moving, velocities in motions.items():
            found.append((f"{label}, {moving}", Configuration(positions=positions, velocities=velocities)))
    return found
