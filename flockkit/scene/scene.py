"""Scenes of many duplicates (paper 002, sections 5.1 and 6).

Templates (graph layers or plain motion graphs, with feature arrows) are placed in a polygon,
uniformly, each with a random heading and scale, so that no two footprints (the axis-aligned
boxes of their placed outlines) overlap. Each object's parts then walk their graphs with a walk
strategy that follows the object's target arrows (by default ``annotated``: the paper's E = C_T
+ alpha C_C + beta N_T), and neighbouring duplicates that play the same source frames at the
same time are walked again, avoiding each other's frames, until they differ (section 6.2).

Objects stand on the ground plane: a template's center (its mean center of mass) is placed at
the object's position, turned by its heading about the up axis (+z) and scaled; a 2D template
lies in the plane. Arrows and targets are in the world's coordinates; each object follows its
target turned into its own (the template's) coordinates.
"""

from __future__ import annotations

import math

import attrs
import numpy as np

from .. import _npzfile, rigid
from .._arrays import readonly_float
from ..errors import FileFormatError, ValidationError
from ..graphs import MotionGraph, Walk, played_frames, synthesize, walk_parts
from ..io import USD_FPS
from ..motion import DEFAULT_UP, Motion
from ..regions import Polygon
from ..registry import require
from ..validate import integer, number
from .features import Features
from .flow import Arrow, FlowField, SelfMovement
from .layers import GraphLayers, LayeredWalk, synthesize_layers

__all__ = ["Placement", "Scene", "SceneAnimation"]

SCENE_FORMAT_VERSION = 1
# Neighbouring duplicates may play the same source frame at the same time on at most this share
# of frames (the bar); beyond it, section 6.2 walks one of them again.
MAX_IN_STEP = 0.05
# Same-template objects whose positions are closer than this many footprint diagonals are
# neighbours (they are seen together).
NEIGHBOUR_DIAGONALS = 3.0
# Batches a scene's walks are split into when walked in parallel (each carries the scene once),
# and the fewest objects a batch has.
WALK_BATCHES = 16
MIN_BATCH = 8
# Tries per object when placing before the region is declared too small.
PLACEMENT_TRIES = 200


@attrs.frozen(eq=False)
class _View:
    """A template seen one way, whatever it is: a GraphLayers (parts of an object) or a MotionGraph
    (one part: a flock's agents, a rigid object). The one place a scene asks which it is."""

    template: object
    graphs: tuple  # one graph per part
    source: Motion
    layered: bool

    @property
    def dt(self) -> float:
        return self.graphs[0].motion.dt

    @property
    def faces(self) -> np.ndarray | None:
        return self.template.faces if self.layered else None

    def features(self, k: int, needed: bool) -> Features | None:
        """The template's arrows: GraphLayers' features, a plain graph's from its motion."""
        if not self.layered:
            return Features.from_motion(self.source)
        if self.template.features is None and needed:
            raise ValidationError(
                f"Scene.templates[{k}] has no features but the scene has constraints: build its layers with "
                f"features= (flockkit.Features, e.g. Features.from_keyframes or Features.from_motion)"
            )
        return self.template.features

    def walk_of(self, walks: list):
        """The template's walk from its parts' walks: a LayeredWalk, or the one Walk."""
        return LayeredWalk(walks=walks) if self.layered else walks[0]

    def part_walks(self, walk) -> tuple:
        return walk.walks if self.layered else (walk,)

    def synthesize(self, walk) -> Motion:
        return synthesize_layers(self.template, walk) if self.layered else synthesize(self.template, walk)


def _view(template) -> _View:
    if isinstance(template, GraphLayers):
        return _View(template=template, graphs=template.graphs, source=template.source, layered=True)
    if isinstance(template, MotionGraph):
        return _View(template=template, graphs=(template,), source=template.motion, layered=False)
    raise ValidationError(
        f"Scene.templates entries must be flockkit.GraphLayers or MotionGraph; got {type(template).__name__}"
    )


def _footprint(template) -> tuple[np.ndarray, np.ndarray]:
    """(center (D,), half extents (2,)): the template's mean center of mass, and the half size in
    x and y of the box around every frame's shape about its own center of mass (what it covers
    where it stands, wherever its recording travels)."""
    source = _view(template).source
    com = source.center_of_mass()
    relative = source.positions[..., :2] - com[:, None, :2]
    half = np.maximum(np.abs(relative.min(axis=(0, 1))), np.abs(relative.max(axis=(0, 1))))
    center = com.mean(axis=0)
    if source.dims == 3:
        center = np.array([center[0], center[1], 0.0])  # objects stand on the ground
    return center, half


def _constraints(value) -> tuple:
    items = tuple(value or ())
    for k, item in enumerate(items):
        if not isinstance(item, FlowField | SelfMovement):
            raise ValidationError(
                f"Scene.constraints[{k}] must be flockkit.scene.FlowField or SelfMovement; got {type(item).__name__}"
            )
    return items


def _counts(value) -> tuple:
    counts = tuple(value) if not isinstance(value, int) else (value,)
    for k, count in enumerate(counts):
        integer(count, f"Scene.counts[{k}]", minimum=1)
    return tuple(int(c) for c in counts)


def _scale(value) -> tuple:
    low, high = (value, value) if isinstance(value, int | float) else tuple(value)
    low, high = (
        number(low, "Scene.scale (low)", minimum=0, strict=True),
        number(high, "Scene.scale (high)", minimum=0, strict=True),
    )
    if high < low:
        raise ValidationError(f"Scene.scale must be (low, high) with low <= high; got {value!r}")
    return low, high


@attrs.frozen(kw_only=True, eq=False)
class Scene:
    """A background scene: `counts[k]` duplicates of `templates[k]` placed in `region` (a
    flockkit.Polygon on the ground), animated for `duration` seconds at the templates' frame
    time (`dt`, if given, must be it), each following the target arrows of `constraints`
    (FlowField, SelfMovement; none: one arrow at the region's center, the first template's
    first feature arrow, held). `scale` is a (low, high) range of uniform scales. `walk` names the
    walk strategy (a registered name or an instance factory's name) and `walk_params` its
    parameters beyond target, features and avoid (it must declare ``Capabilities(targets=True)``:
    it takes those three). `n_jobs` walks objects in parallel through
    joblib; the result is the same whatever it is.

    `headings` "random" turns each object uniformly about +z; "aligned" turns it so that its
    first target, in its own coordinates, points like an arrow its source holds, of about the
    same length (chosen at random among them): for templates whose arrows point only a few ways
    (a flag recorded in wind from one side), which a random heading would ask to lean where
    their source never does."""

    templates: tuple = attrs.field(converter=tuple)
    region: Polygon = attrs.field()
    counts: tuple = attrs.field(converter=_counts)
    duration: float = attrs.field(converter=lambda v: number(v, "Scene.duration", minimum=0, strict=True))
    dt: float | None = attrs.field(default=None)
    constraints: tuple = attrs.field(default=(), converter=_constraints)
    seed: int = attrs.field(default=0, converter=lambda v: integer(v, "Scene.seed", minimum=0))
    scale: tuple = attrs.field(default=(1.0, 1.0), converter=_scale)
    walk: str = attrs.field(default="annotated")
    walk_params: dict = attrs.field(factory=dict, converter=dict)
    n_jobs: int | None = attrs.field(default=None)
    headings: str = attrs.field(default="random")

    def __attrs_post_init__(self):
        if self.headings not in ("random", "aligned"):
            raise ValidationError(f"Scene.headings must be 'random' or 'aligned'; got {self.headings!r}")
        require("walk", self.walk, "targets", "a Scene's walks")
        if not isinstance(self.region, Polygon):
            raise ValidationError(f"Scene.region must be a flockkit.Polygon; got {type(self.region).__name__}")
        if not self.templates:
            raise ValidationError("Scene.templates needs at least one template")
        if len(self.counts) != len(self.templates):
            raise ValidationError(f"Scene.counts has {len(self.counts)} entries for {len(self.templates)} templates")
        dts = {_view(t).dt for t in self.templates}
        if len(dts) != 1 or (self.dt is not None and abs(self.dt - next(iter(dts))) > 1e-12):
            raise ValidationError(
                f"Scene: every template must share one frame time (and dt, if given, must be it); got "
                f"{sorted(dts)}{'' if self.dt is None else f' and dt={self.dt}'}"
            )
        for k, template in enumerate(self.templates):
            _view(template).features(k, needed=True)
        for k, constraint in enumerate(self.constraints):
            keyed = (
                [a.keyframes for a in constraint.arrows]
                if isinstance(constraint, FlowField)
                else [constraint.keyframes]
            )
            last = max(float(times[-1]) for times, _ in keyed)
            if min(float(times[0]) for times, _ in keyed) < 0 or last > self.duration + 1e-9:
                raise ValidationError(
                    f"Scene.constraints[{k}]: keyframe times must lie in 0..{self.duration:g} s (the duration); "
                    f"one is at {last:g} s"
                )
        moving = {c.object for c in self.constraints if isinstance(c, SelfMovement)}
        if moving and max(moving) >= self.n_objects:
            raise ValidationError(
                f"SelfMovement.object {max(moving)} is not an object of this scene (0..{self.n_objects - 1})"
            )

    @property
    def n_objects(self) -> int:
        return sum(self.counts)

    @property
    def frame_time(self) -> float:
        return _view(self.templates[0]).dt

    @property
    def n_frames(self) -> int:
        return math.ceil(self.duration / self.frame_time)

    def place(self) -> Placement:
        """Positions uniform in the region, random headings and scales, no two footprints
        overlapping (deterministic under the seed). ValidationError when the region cannot hold
        them, with the areas in numbers."""
        rng = np.random.default_rng(np.random.SeedSequence(self.seed).spawn(2)[0])
        feet = [_footprint(t)[1] for t in self.templates]
        aligned = [self._held_arrows(k) if self.headings == "aligned" else None for k in range(len(self.templates))]
        kinds = np.repeat(np.arange(len(self.templates)), self.counts)
        rng.shuffle(kinds)
        low, high = self.region.bounds()
        area = self.region.area()
        needed = sum(count * 4 * foot[0] * foot[1] * self.scale[0] ** 2 for count, foot in zip(self.counts, feet))
        if needed > area:
            raise ValidationError(
                f"Scene: {self.n_objects} objects cover at least {needed:.4g} square units but the region has "
                f"{area:.4g}: use a larger region, fewer objects or a smaller scale"
            )
        n = len(kinds)
        positions, headings, scales = np.empty((n, 2)), np.empty(n), np.empty(n)
        boxes = np.empty((n, 2, 2))
        for i, kind in enumerate(kinds):
            for _ in range(PLACEMENT_TRIES):
                scale = rng.uniform(*self.scale)
                diagonal = np.linalg.norm(feet[kind]) * scale  # the box's half size under any heading
                if np.any(high - low <= 2 * diagonal):
                    point = None
                    break
                point = rng.uniform(low + diagonal, high - diagonal)
                heading = self._heading(aligned[kind], i, point, rng)
                half = _turned_half(feet[kind] * scale, heading)
                corners = point + half * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
                if not np.all(self.region.contains(corners)):
                    continue
                box = np.array([point - half, point + half])
                if i and np.any(np.all((boxes[:i, 0] < box[1]) & (box[0] < boxes[:i, 1]), axis=1)):
                    continue
                positions[i], headings[i], scales[i], boxes[i] = point, heading, scale, box
                break
            else:
                point = None
            if point is None:
                raise ValidationError(
                    f"Scene: the region cannot hold {self.n_objects} objects without overlap: placed {i}, then "
                    f"{PLACEMENT_TRIES} tries found no free spot (region {area:.4g} square units, objects cover "
                    f"{needed:.4g}); use a larger region, fewer objects or a smaller scale"
                )
        return Placement(positions=positions, headings=headings, scales=scales, templates=kinds)

    def _held_arrows(self, kind: int) -> tuple[np.ndarray, np.ndarray]:
        """Template `kind`'s arrows and, for each, how many of them lie within 0.1 of it (how
        long the source holds it): what aligned headings choose among."""
        arrows = _view(self.templates[kind]).features(kind, needed=False).vectors
        return arrows, (np.linalg.norm(arrows[:, None] - arrows[None], axis=2) < 0.1).sum(axis=1)

    def _heading(self, held_arrows, i: int, point, rng) -> float:
        heading = rng.uniform(0, 2 * np.pi)
        if self.headings == "random":
            return heading
        first = self._world(point[None], np.zeros(1), [i])[0, 0]
        arrows, held = held_arrows
        flat = np.linalg.norm(arrows[:, :2], axis=1)
        near = np.flatnonzero(
            np.abs(flat - np.linalg.norm(first[:2])) <= 0.05 + np.abs(flat - np.linalg.norm(first[:2])).min()
        )
        # prefer arrows the source holds for a while over ones it passes through
        near = near[held[near] >= 0.5 * held[near].max()]
        pick = arrows[near[int(rng.integers(len(near)))]]
        if np.linalg.norm(first[:2]) < 1e-12 or np.linalg.norm(pick[:2]) < 1e-12:
            return heading
        return float(np.arctan2(first[1], first[0]) - np.arctan2(pick[1], pick[0])) % (2 * np.pi)

    def targets(self, placement: Placement) -> np.ndarray:
        """(objects, frames, 3): each object's target arrow per output frame, in the world."""
        times = np.arange(self.n_frames) * self.frame_time
        return self._world(placement.positions, times, range(placement.n_objects))

    def _world(self, positions, times, objects) -> np.ndarray:
        """(len(objects), len(times), 3): the target arrows of `objects` standing at `positions`."""
        objects = list(objects)
        flows = [c for c in self.constraints if isinstance(c, FlowField)]
        if not self.constraints:
            # the made arrow: the first template's first arrow (its longest, if that one is zero)
            arrows = _view(self.templates[0]).features(0, needed=False).vectors
            first = arrows[0] if np.linalg.norm(arrows[0]) > 1e-9 else arrows[np.argmax(np.linalg.norm(arrows, axis=1))]
            if np.linalg.norm(first) <= 1e-9:
                return np.zeros((len(positions), len(times), 3))  # a template that never moves: nothing to follow
            flows = [FlowField(arrows=[Arrow(position=self.region.interior_point(), keyframes=[(0.0, first[:2])])])]
        world = np.zeros((len(positions), len(times), 3))
        for flow in flows:
            ground = np.asarray(positions)
            if flow.dims == 3:  # objects stand on the ground: z = 0
                ground = np.column_stack([ground, np.zeros(len(ground))])
            arrows = flow.targets(ground, times)  # (F, M, D)
            world[..., : arrows.shape[2]] += arrows.transpose(1, 0, 2)
        for constraint in self.constraints:
            if isinstance(constraint, SelfMovement) and constraint.object in objects:
                row = objects.index(constraint.object)
                own = constraint.targets(times)
                world[row] = 0.0
                world[row, :, : own.shape[1]] = own
        lengths = np.linalg.norm(world, axis=2, keepdims=True)
        return np.where(lengths > 1, world / np.maximum(lengths, 1e-300), world)  # several flows: at most 1

    def synthesize(self, progress: bool = False) -> SceneAnimation:
        """Place, walk every object's parts after its targets, then de-synchronise neighbours."""
        from .._progress import progress_bar

        placement = self.place()
        targets = self.targets(placement)
        seeds = np.random.SeedSequence(self.seed).spawn(2)[1].spawn(placement.n_objects)
        with progress_bar(progress, unit="object") as report:
            items = [(i, targets[i], int(seeds[i].generate_state(1)[0]), None) for i in range(placement.n_objects)]
            walks, played = self._walk_many(placement, items, report, "walks")
            animation = SceneAnimation(
                templates=self.templates, placement=placement, walks=walks, dt=self.frame_time,
                n_frames=self.n_frames, constraints=self.constraints, region=self.region,
            )  # fmt: skip
            frames, neighbours = _stacked(played, self.n_frames), animation.neighbours()
            before = _largest_in_step(frames, neighbours)
            walks = self._desynchronise(animation, targets, seeds, frames, neighbours, report)
        report = {"in_step_before": before, "in_step_after": _largest_in_step(frames, neighbours)}
        return attrs.evolve(animation, walks=walks, report=report)

    def _walk_many(self, placement, items, report, stage: str) -> tuple[list, list]:
        """The walks of `items` ((object, target, seed, avoid) each) and the source frames they
        play ((parts, frames) each), in order: in up to
        WALK_BATCHES batches of at least MIN_BATCH objects through joblib (the scene and its
        templates travel once a batch, not once an object), or here when there are too few."""
        from ..parallel import imap, jobs

        # a batch carries the templates (megabytes): too few objects in it and the trip costs more
        # than the walks; then they are walked here
        count = 1 if jobs(self.n_jobs) == 1 else max(1, min(WALK_BATCHES, len(items) // MIN_BATCH))
        batches = [items[k::count] for k in range(count)]  # interleaved: neighbours' costs spread evenly
        walks, played = [None] * len(items), [None] * len(items)
        calls = [(self, placement, b) for b in batches]
        for k, results in enumerate(imap(_walk_batch, calls, n_jobs=self.n_jobs if count > 1 else 1)):
            walks[k::count], played[k::count] = zip(*results)
            if report:
                report(sum(len(b) for b in batches[: k + 1]), len(items), stage)
        return walks, played

    def _desynchronise(self, animation, targets, seeds, frames, near, report) -> list:
        """Section 6.2: each object in step with a neighbour on more than MAX_IN_STEP of its frames
        is walked again avoiding its neighbours' frames. They go in rounds of objects no two of
        which are neighbours (a greedy colouring, in object order), each round in parallel and
        seeing the walks of the rounds before; `frames` (animation.source_frames()) is kept up
        to date."""
        walks = list(animation.walks)
        need = [i for i, nb in enumerate(near) if len(nb) and _in_step(frames[i], frames[nb]).max() > MAX_IN_STEP]
        colour = {}
        for i in need:
            taken = {colour[j] for j in near[i] if j in colour}
            colour[i] = next(c for c in range(len(need) + 1) if c not in taken)
        for c in range(max(colour.values(), default=-1) + 1):
            members = [i for i in need if colour[i] == c]
            items = [(i, targets[i], int(seeds[i].generate_state(2)[1]), frames[near[i]]) for i in members]
            again, played = self._walk_many(animation.placement, items, report, f"out of step ({c + 1})")
            for i, walk, own in zip(members, again, played):
                walks[i] = walk
                frames[i, : len(own)] = own
        return walks


def _walk_batch(scene: Scene, placement: Placement, items) -> list:
    """(walk, the source frames it plays) of _walk_object for each (object, target, seed, avoid)
    of `items` (the frames made here, on the worker, where the walk is)."""
    results = []
    for i, target, seed, avoid in items:
        walk = _walk_object(scene, i, placement, target, seed, avoid)
        template = scene.templates[placement.templates[i]]
        results.append((walk, SceneAnimation._frames_of(template, walk, scene.n_frames)))
    return results


def _stacked(played, n_frames: int) -> np.ndarray:
    """(objects, parts, frames) of each object's (parts, frames) source frames, -1 where an
    object has fewer parts than the most."""
    frames = np.full((len(played), max(len(own) for own in played), n_frames), -1, dtype=np.int64)
    for i, own in enumerate(played):
        frames[i, : len(own)] = own
    return frames


def _walk_object(scene: Scene, i: int, placement: Placement, target: np.ndarray, seed: int, avoid):
    """Object i's walk (a Walk, or a LayeredWalk of one walk per part), each part with its own
    random stream from `seed`; `avoid` (neighbours, parts, frames) of source frames to fall out
    of step with."""
    kind = int(placement.templates[i])
    view = _view(scene.templates[kind])
    local = target @ _turn(placement.headings[i], 3)  # the world's arrows in the template's coordinates (R^T w)
    track = Features(vectors=local[:, : view.source.dims], dt=scene.frame_time)
    part_params = None if avoid is None else [{"avoid": avoid[:, k]} for k in range(len(view.graphs))]
    params = {**scene.walk_params, "target": track, "features": view.features(kind, needed=False)}
    walks = walk_parts(view.graphs, strategy=scene.walk, duration=scene.duration, seed=seed, part_params=part_params,
                       **params)  # fmt: skip
    return view.walk_of(walks)


def _turn(heading: float, dims: int) -> np.ndarray:
    """The rotation by `heading` about the up axis (in 2D, in the plane)."""
    return rigid.rotation(heading) if dims == 2 else rigid.rotation(heading, DEFAULT_UP)


def _turned_half(half: np.ndarray, heading: float) -> np.ndarray:
    """Half extents of the axis-aligned box around a box of half extents `half` turned by `heading`."""
    c, s = abs(math.cos(heading)), abs(math.sin(heading))
    return np.array([c * half[0] + s * half[1], s * half[0] + c * half[1]])


def _largest_in_step(frames: np.ndarray, neighbours) -> float:
    """The largest in-step share (see _in_step) between an object and one of its neighbours."""
    shares = [_in_step(frames[i], frames[near]).max() for i, near in enumerate(neighbours) if len(near)]
    return float(max(shares, default=0.0))


def _in_step(frames: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Share of frames on which `frames` (parts, F) and each of `others` (K, parts, F) play the
    same source frame in some part: (K,)."""
    same = (frames[None] == others) & (frames[None] >= 0)
    return same.any(axis=1).mean(axis=1)


@attrs.frozen(kw_only=True, eq=False)
class Placement:
    """Where each object of a scene stands: `positions` (M, 2) on the ground, `headings` (M,)
    radians about +z, `scales` (M,), `templates` (M,) the template each duplicates."""

    positions: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Placement.positions"))
    headings: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Placement.headings"))
    scales: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="Placement.scales"))
    templates: np.ndarray = attrs.field(converter=lambda v: np.asarray(v, dtype=np.int64))

    @property
    def n_objects(self) -> int:
        return len(self.positions)

    def __eq__(self, other):
        if not isinstance(other, Placement):
            return NotImplemented
        return all(
            np.array_equal(getattr(self, f), getattr(other, f))
            for f in ("positions", "headings", "scales", "templates")
        )

    __hash__ = None


class _Motions:
    """The objects' world-space motions, synthesized when asked for (a scene of a thousand
    meshes does not fit in memory at once)."""

    def __init__(self, animation):
        self.animation = animation

    def __len__(self):
        return self.animation.placement.n_objects

    def __getitem__(self, i):
        if not -len(self) <= i < len(self):
            raise IndexError(f"object {i} of {len(self)}")
        return self.animation.motion(i % len(self))

    def __iter__(self):
        return (self.animation.motion(i) for i in range(len(self)))


@attrs.frozen(kw_only=True, eq=False)
class SceneAnimation:
    """A synthesized scene: the templates, where each object stands (`placement`), each object's
    walk (a Walk, or a LayeredWalk for layered templates), `n_frames` output frames `dt` apart,
    and the constraints it followed. `report` holds the neighbours' in-step share before and
    after de-synchronisation when it comes from Scene.synthesize."""

    templates: tuple = attrs.field(converter=tuple)
    placement: Placement
    walks: tuple = attrs.field(converter=tuple)
    dt: float
    n_frames: int
    constraints: tuple = attrs.field(default=(), converter=_constraints)
    region: Polygon | None = attrs.field(default=None)
    report: dict = attrs.field(factory=dict)
    _footprints: list = attrs.field(init=False, repr=False, eq=False)  # (center, half extents) per template

    def __attrs_post_init__(self):
        object.__setattr__(self, "_footprints", [_footprint(t) for t in self.templates])

    @property
    def motions(self) -> _Motions:
        """One world-space Motion per object, each synthesized when indexed."""
        return _Motions(self)

    def motion(self, i: int) -> Motion:
        """Object i's motion in the world: its walk played, cut to n_frames, scaled, turned by its
        heading about +z and moved to its position."""
        played = _view(self.templates[self.placement.templates[i]]).synthesize(self.walks[i])
        center, _ = self._footprints[self.placement.templates[i]]
        dims = played.dims
        scale, turn = self.placement.scales[i], _turn(self.placement.headings[i], dims)
        where = np.zeros(dims)
        where[:2] = self.placement.positions[i]
        positions = (played.positions[: self.n_frames] - center) @ (scale * turn).T + where
        return Motion._adopt(positions, self.dt)

    @staticmethod
    def _frames_of(template, walk, n_frames: int) -> np.ndarray:
        view = _view(template)
        return np.stack([played_frames(g, w)[0][:n_frames] for g, w in zip(view.graphs, view.part_walks(walk))])

    def source_frames(self) -> np.ndarray:
        """(objects, parts, frames): the source frame each object's part plays at each output
        frame (-1 for parts an object's template does not have)."""
        return _stacked(
            [
                self._frames_of(self.templates[kind], walk, self.n_frames)
                for kind, walk in zip(self.placement.templates, self.walks)
            ],
            self.n_frames,
        )

    def bounding_boxes(self) -> np.ndarray:
        """(objects, 2, 2): the (low, high) corners in x, y of each object's placed footprint."""
        boxes = np.empty((self.placement.n_objects, 2, 2))
        for i in range(self.placement.n_objects):
            half = self._footprints[self.placement.templates[i]][1] * self.placement.scales[i]
            half = _turned_half(half, self.placement.headings[i])
            boxes[i] = [self.placement.positions[i] - half, self.placement.positions[i] + half]
        return boxes

    def neighbours(self) -> list[np.ndarray]:
        """For each object, the other objects of its template within NEIGHBOUR_DIAGONALS
        footprint diagonals."""
        from scipy.spatial import cKDTree

        result = [np.zeros(0, dtype=np.int64)] * self.placement.n_objects
        for kind, (_, half) in enumerate(self._footprints):
            members = np.flatnonzero(self.placement.templates == kind)
            if len(members) < 2:
                continue
            reach = NEIGHBOUR_DIAGONALS * 2 * np.linalg.norm(half) * self.placement.scales[members].max()
            tree = cKDTree(self.placement.positions[members])
            for row, near in zip(members, tree.query_ball_point(self.placement.positions[members], reach)):
                result[row] = members[[j for j in near if members[j] != row]]
        return result

    def save(self, path) -> None:
        """Write the templates, placement, walks and constraints to one .npz with JSON metadata
        (atomic; the motions are synthesized again on load, not stored)."""
        _save(self, path)

    @classmethod
    def load(cls, path) -> SceneAnimation:
        """Read a file written by :meth:`save`; FileFormatError naming the file if it is not one."""
        return _load(path)

    def export(self, path, *, fps: float | None = USD_FPS, meters_per_unit: float = 1.0) -> None:
        """A USD stage (.usda/.usdc): each object under /Scene an animated UsdGeom.Mesh (a template
        with faces) or UsdGeom.Points, its points time-sampled every frame on a time line at `fps`
        (None: 1 / dt), up axis z, metersPerUnit `meters_per_unit`, as flockkit.io.write_usd
        writes motions. Needs usd-core."""
        from pathlib import Path

        if Path(path).suffix.lower() not in (".usda", ".usdc", ".usd"):
            raise ValidationError(f"SceneAnimation.export writes .usda, .usdc or .usd; got {path}")
        _export_usd(self, path, fps=fps, meters_per_unit=meters_per_unit)

    def __eq__(self, other):
        if not isinstance(other, SceneAnimation):
            return NotImplemented
        return (self.templates == other.templates and self.placement == other.placement and self.walks == other.walks
                and self.dt == other.dt and self.n_frames == other.n_frames)  # fmt: skip

    __hash__ = None

    def in_step_share(self) -> float:
        """The largest share of frames on which two neighbours play the same source frame at the
        same time (in some part)."""
        return _largest_in_step(self.source_frames(), self.neighbours())


def _constraint_json(constraint) -> dict:
    def keyframes(pair):
        times, vectors = pair
        return [[float(t), [float(x) for x in v]] for t, v in zip(times, vectors)]

    if isinstance(constraint, FlowField):
        return {
            "flow": [{"position": a.position.tolist(), "keyframes": keyframes(a.keyframes)} for a in constraint.arrows]
        }
    return {"object": constraint.object, "keyframes": keyframes(constraint.keyframes)}


def _constraint_from_json(value):
    if "flow" in value:
        return FlowField(arrows=value["flow"])
    return SelfMovement(object=value["object"], keyframes=value["keyframes"])


def _save(animation: SceneAnimation, path) -> None:
    arrays = {
        "positions": animation.placement.positions,
        "headings": animation.placement.headings,
        "scales": animation.placement.scales,
        "templates": animation.placement.templates,
    }
    views = [_view(t) for t in animation.templates]
    walks = [w for kind, walk in zip(animation.placement.templates, animation.walks)
             for w in views[kind].part_walks(walk)]  # fmt: skip
    arrays["walk_start"] = np.array([w.start for w in walks], dtype=np.int64)
    arrays["walk_edges"] = np.array([len(w.edges) for w in walks], dtype=np.int64)
    edges = [e for w in walks for e in w.edges]
    arrays["edge_transition"] = np.array([kind == "transition" for kind, _ in edges], dtype=bool)
    arrays["edge_index"] = np.array([index for _, index in edges], dtype=np.int64)
    kinds, headers = [], []
    for k, template in enumerate(animation.templates):
        own, header = template._payload()
        arrays.update({f"template{k}.{name}": array for name, array in own.items()})
        kinds.append("layers" if views[k].layered else "graph")
        headers.append(header)
    metadata = {
        "dt": animation.dt,
        "n_frames": animation.n_frames,
        "template_kinds": kinds,
        "template_headers": headers,
        "constraints": [_constraint_json(c) for c in animation.constraints],
        "report": animation.report,
        "region": None if animation.region is None else animation.region.vertices.tolist(),
    }
    _npzfile.write(path, kind="scene", version=SCENE_FORMAT_VERSION, arrays=arrays, metadata=metadata)


def _load(path) -> SceneAnimation:
    arrays, header = _npzfile.read(path, kind="scene", versions=(SCENE_FORMAT_VERSION,))
    try:
        templates = []
        for k, (kind, own) in enumerate(zip(header["template_kinds"], header["template_headers"])):
            prefix = f"template{k}."
            payload = {name[len(prefix) :]: a for name, a in arrays.items() if name.startswith(prefix)}
            templates.append((GraphLayers if kind == "layers" else MotionGraph)._from_payload(payload, own, path))
        placement = Placement(positions=arrays["positions"], headings=arrays["headings"], scales=arrays["scales"],
                              templates=arrays["templates"])  # fmt: skip
        ends = np.cumsum(arrays["walk_edges"])
        kinds = np.where(arrays["edge_transition"], "transition", "clip")
        flat = [
            Walk(
                start=int(start),
                edges=list(zip(kinds[end - n : end].tolist(), arrays["edge_index"][end - n : end].tolist())),
            )
            for start, n, end in zip(arrays["walk_start"], arrays["walk_edges"], ends)
        ]
        walks, at = [], 0
        views = [_view(t) for t in templates]
        for kind in placement.templates:
            parts = len(views[kind].graphs)
            walks.append(views[kind].walk_of(flat[at : at + parts]))
            at += parts
        if at != len(flat):
            raise ValidationError(f"{len(flat)} walks for {at} object parts")
        return SceneAnimation(templates=templates, placement=placement, walks=walks, dt=header["dt"],
                              n_frames=header["n_frames"], report=header.get("report", {}),
                              region=None if header.get("region") is None else Polygon(vertices=header["region"]),
                              constraints=[_constraint_from_json(c) for c in header["constraints"]])  # fmt: skip
    except (KeyError, IndexError, TypeError, ValueError, ValidationError) as exc:
        raise FileFormatError(f"{path}: invalid scene animation: {type(exc).__name__}: {exc}") from None


def _export_usd(animation: SceneAnimation, path, *, fps, meters_per_unit) -> None:
    """Each object an animated UsdGeom.Mesh (a template with faces) or UsdGeom.Points under
    /Scene, on the stage flockkit.io writes motions on."""
    from ..io.usd import write_meshes

    width = len(str(animation.placement.n_objects))
    objects = []
    for i, motion in enumerate(animation.motions):
        template = animation.templates[animation.placement.templates[i]]
        faces = _view(template).faces
        objects.append((f"/Scene/Object{i:0{width}d}", motion.positions, faces,
                        {"flockkit:template": int(animation.placement.templates[i])}))  # fmt: skip
    write_meshes(path, objects, dt=animation.dt, n_frames=animation.n_frames, fps=fps,
                 meters_per_unit=meters_per_unit)  # fmt: skip
