"""Scenes of many duplicates (paper 002, sections 5.1 and 6).

Templates (graph layers or plain motion graphs, with feature arrows) are placed in a polygon,
uniformly, each with a random heading and scale, so that no two footprints (the axis-aligned
boxes of their placed outlines) overlap. Each object's parts then walk their graphs with a walk
strategy that follows the object's target arrows (by default ``annotated``: the paper's E = C_T
+ alpha C_C + beta N_T), in rounds of objects no two of which are neighbours, each avoiding the
frames of its neighbours walked in earlier rounds (section 6.2, from the first walk: each part of
each object starts at a phase of its own); neighbours still playing the same source frames at
the same time are walked again, avoiding each other's frames, until they differ. A part
that still plays in step with a neighbour's on more than MAX_IN_STEP of frames afterwards gets a
``flockkit.errors.FlockkitWarning`` naming the template and the part: its graph leaves too few
ways to differ (a short cycle without phase shifts, or more close neighbours than its cycle has
phases to give them).

Objects stand on the ground plane: a template's center (its mean center of mass) is placed at
the object's position, turned by its heading about the up axis (+z) and scaled; a 2D template
lies in the plane. Arrows and targets are in the world's coordinates; each object follows its
target turned into its own (the template's) coordinates. Objects whose templates' arrows are
self-movement (``Features.speed``: an animal's walk) move and turn after their targets
(``flockkit.scene.movement``); ``SceneAnimation.paths`` holds where each is at each frame.
"""

from __future__ import annotations

import contextlib
import gc
import math
import warnings

import attrs
import numpy as np

from ..errors import FlockkitWarning, ValidationError
from ..graphs import walk_parts
from ..regions import Polygon
from ..registry import require
from ..validate import integer, number
from .animation import SceneAnimation
from .desync import (
    IN_STEP_FRAMES,
    MAX_IN_STEP,
    in_step,
    largest_in_step,
    nearest_in_step,
    pairs_in_step,
    part_in_step,
)
from .features import Features
from .flow import Arrow, FlowField, SelfMovement, flow_constraints
from .movement import MAX_TURN, Course, Gaits, Paths, avoid_in_source_time, plan, settle
from .placement import PLACEMENT_TRIES, Placement, heading_turn, turned_half
from .templates import footprint, template_view

__all__ = ["Placement", "Scene", "SceneAnimation"]


# Batches a stage of a scene's walks is split into per worker when walked in parallel: each
# carries the scene (megabytes of templates, about 25 MB for bench/scene_assets.py's, a tenth of a
# second to send and read) once, and a scene is walked in several stages (rounds); two a worker
# even out batches that take longer than others. And the fewest objects a batch has.
BATCHES_PER_WORKER = 2


MIN_BATCH = 8


def _counts(value) -> tuple:
    counts = tuple(value) if not isinstance(value, int) else (value,)
    for k, count in enumerate(counts):
        integer(count, f"Scene.counts[{k}]", minimum=1)
    return tuple(int(c) for c in counts)


def _scale(value) -> tuple:
    try:
        low, high = (value, value) if isinstance(value, int | float) else tuple(value)
    except (TypeError, ValueError):
        raise ValidationError(f"Scene.scale must be a number or (low, high); got {value!r}") from None
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
    their source never does.

    Objects whose template's arrows are self-movement (``Features.speed`` set) move: their heading
    follows their target, turning at most `max_turn` radians a second, and they travel as their
    clips carry them (``flockkit.scene.movement``)."""

    templates: tuple = attrs.field(converter=tuple)
    region: Polygon = attrs.field()
    counts: tuple = attrs.field(converter=_counts)
    duration: float = attrs.field(converter=lambda v: number(v, "Scene.duration", minimum=0, strict=True))
    dt: float | None = attrs.field(default=None)
    constraints: tuple = attrs.field(default=(), converter=flow_constraints)
    seed: int = attrs.field(default=0, converter=lambda v: integer(v, "Scene.seed", minimum=0))
    scale: tuple = attrs.field(default=(1.0, 1.0), converter=_scale)
    walk: str = attrs.field(default="annotated")
    walk_params: dict = attrs.field(factory=dict, converter=dict)
    n_jobs: int | None = attrs.field(default=None)
    headings: str = attrs.field(default="random")
    max_turn: float = attrs.field(default=MAX_TURN, converter=lambda v: number(v, "Scene.max_turn", minimum=0,
                                                                              strict=True))  # fmt: skip

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
        dts = {template_view(t).dt for t in self.templates}
        if len(dts) != 1 or (self.dt is not None and abs(self.dt - next(iter(dts))) > 1e-12):
            raise ValidationError(
                f"Scene: every template must share one frame time (and dt, if given, must be it); got "
                f"{sorted(dts)}{'' if self.dt is None else f' and dt={self.dt}'}"
            )
        for k, template in enumerate(self.templates):
            template_view(template).features(k, needed=True)
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
        return template_view(self.templates[0]).dt

    @property
    def n_frames(self) -> int:
        return math.ceil(self.duration / self.frame_time)

    def place(self) -> Placement:
        """Positions uniform in the region, random headings and scales, no two footprints
        overlapping (deterministic under the seed). ValidationError when the region cannot hold
        them, with the areas in numbers."""
        rng = np.random.default_rng(np.random.SeedSequence(self.seed).spawn(2)[0])
        feet = [footprint(t)[1] for t in self.templates]
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
                half = turned_half(feet[kind] * scale, heading)
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
        arrows = template_view(self.templates[kind]).features(kind, needed=False).vectors
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
            arrows = template_view(self.templates[0]).features(0, needed=False).vectors
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
        """Place, walk every object's parts after its targets (in rounds, each object avoiding
        the frames of its neighbours walked before it), then walk again the neighbours still in
        step."""
        from .._progress import progress_bar

        placement = self.place()
        targets, rates = self._courses(placement)
        seeds = np.random.SeedSequence(self.seed).spawn(2)[1].spawn(placement.n_objects)
        with progress_bar(progress, unit="object") as report:
            animation = SceneAnimation(
                templates=self.templates, placement=placement, walks=[None] * placement.n_objects,
                dt=self.frame_time, n_frames=self.n_frames, constraints=self.constraints, region=self.region,
            )  # fmt: skip
            neighbours = animation.neighbours()
            walks, frames, rounds = self._first_walks(placement, targets, seeds, neighbours, report)
            animation = attrs.evolve(animation, walks=walks)
            before, pairs_before = largest_in_step(frames, neighbours), pairs_in_step(frames, neighbours)
            walks, again = self._desynchronise(animation, targets, seeds, frames, neighbours, report)
        self._warn_in_step(placement, frames, neighbours)
        report = {"in_step_before": before, "in_step_after": largest_in_step(frames, neighbours),
                  "pairs_in_step_before": pairs_before, "pairs_in_step_after": pairs_in_step(frames, neighbours),
                  "in_step_frames": IN_STEP_FRAMES, "first_rounds": rounds, "walked_again": again}  # fmt: skip
        animation = attrs.evolve(animation, walks=walks, report=report, paths=self._paths(placement, walks, rates))
        report.update(nearest_in_step(animation))
        return animation

    def _gaits(self, placement: Placement) -> list:
        """Each object's Gaits (None for an object whose template does not move)."""
        own = [Gaits.of(template_view(t).features(k, needed=False)) for k, t in enumerate(self.templates)]
        return [own[kind] for kind in placement.templates]

    def _arrows_at(self, movers):
        """arrows_at(positions, t) for `movers`: their target arrows standing at positions at frame t."""
        return lambda positions, t: self._world(positions, [t * self.frame_time], movers)[:, 0]

    def _courses(self, placement: Placement) -> tuple[list, np.ndarray | None]:
        """Each object's target: its world arrows per frame (F, 3), or for a moving object its
        Course (movement.plan); and the moving objects' rates (movers, F), None without any."""
        targets = list(self.targets(placement))
        gaits = self._gaits(placement)
        movers = [i for i, g in enumerate(gaits) if g is not None]
        if not movers:
            return targets, None
        dims = [template_view(self.templates[placement.templates[i]]).source.dims for i in movers]
        courses, rates = plan([gaits[i] for i in movers], placement.positions[movers], placement.headings[movers],
                              n_frames=self.n_frames, dt=self.frame_time, max_turn=self.max_turn,
                              arrows_at=self._arrows_at(movers), dims=dims)  # fmt: skip
        for i, course in zip(movers, courses):
            targets[i] = course
        return targets, rates

    def _paths(self, placement: Placement, walks, rates) -> Paths | None:
        """Where each object is at each frame (movement.settle for the moving ones), None when
        none moves."""
        if rates is None:
            return None
        gaits = self._gaits(placement)
        movers = [i for i, g in enumerate(gaits) if g is not None]
        played = [template_view(self.templates[placement.templates[i]]).played_arrows(walks[i]) for i in movers]
        moved, turned = settle([gaits[i] for i in movers], played, rates, placement.positions[movers],
                               placement.headings[movers], dt=self.frame_time, max_turn=self.max_turn,
                               arrows_at=self._arrows_at(movers))  # fmt: skip
        n = placement.n_objects
        positions = np.repeat(placement.positions[:, None], self.n_frames, axis=1)
        headings = np.repeat(placement.headings[:, None], self.n_frames, axis=1)
        clocks = np.tile(np.arange(self.n_frames, dtype=float), (n, 1))
        positions[movers], headings[movers] = moved, turned
        clocks[movers] = np.concatenate([np.zeros((len(movers), 1)), np.cumsum(rates[:, :-1], axis=1)], axis=1)
        moving = np.zeros(n, dtype=bool)
        moving[movers] = True
        return Paths(positions=positions, headings=headings, clocks=clocks, moving=moving)

    def _walk_many(self, placement, items, report, stage: str) -> tuple[list, list]:
        """The walks of `items` ((object, target, seed, avoid) each) and the source frames they
        play ((parts, frames) each), in order: in up to BATCHES_PER_WORKER batches a worker, of
        at least MIN_BATCH objects, through joblib (the scene and its templates travel once a
        batch, not once an object), or here when there are too few."""
        from joblib import effective_n_jobs

        from ..parallel import imap, jobs

        # a batch carries the templates (megabytes): too few objects in it and the trip costs more
        # than the walks; then they are walked here
        workers = jobs(self.n_jobs)
        most = 1 if workers == 1 else BATCHES_PER_WORKER * effective_n_jobs(workers)
        count = max(1, min(most, len(items) // MIN_BATCH))
        batches = [items[k::count] for k in range(count)]  # interleaved: neighbours' costs spread evenly
        walks, played = [None] * len(items), [None] * len(items)
        calls = [(self, placement, b) for b in batches]
        with _collection_paused():  # the walks arrive as millions of small tuples
            for k, results in enumerate(imap(_walk_batch, calls, n_jobs=self.n_jobs if count > 1 else 1)):
                walks[k::count], played[k::count] = zip(*results)
                if report:
                    report(sum(len(b) for b in batches[: k + 1]), len(items), stage)
        return walks, played

    def _first_walks(self, placement, targets, seeds, near, report) -> tuple[list, np.ndarray, int]:
        """Every object's walk, made in rounds of objects no two of which are neighbours (see
        _rounds), each round seeing the walks of the rounds before: an object avoids the frames
        of its neighbours walked in earlier rounds and counts those of later rounds as walks yet
        to be made (rows of -1), which avoid it in turn. So each part of each object starts at a
        phase of its own and keeps out of step with its neighbours from the first walk, and
        de-synchronisation is left only the pairs still in step. Returns the walks, the source
        frames they play (objects, parts, frames) and the number of rounds."""
        parts = max(len(template_view(t).graphs) for t in self.templates)
        # int32: the frames travel to workers as the walks to avoid, and back (a thousand objects'
        # 9 parts over 3 600 frames are 130 MB so)
        frames = np.full((placement.n_objects, parts, self.n_frames), -1, dtype=np.int32)
        walks = [None] * placement.n_objects
        colour = self._rounds(range(placement.n_objects), near)
        rounds = max(colour.values(), default=-1) + 1
        for c in range(rounds):
            members = [i for i in range(placement.n_objects) if colour[i] == c]
            items = [(i, targets[i], int(seeds[i].generate_state(1)[0]), self._avoided(frames, near[i], colour, c))
                     for i in members]  # fmt: skip
            made, played = self._walk_many(placement, items, report, f"walks ({c + 1} of {rounds})")
            for i, walk, own in zip(members, made, played):
                walks[i] = walk
                frames[i, : len(own)] = own
        return walks, frames, rounds

    @staticmethod
    def _rounds(objects, near) -> dict:
        """{object: round} for `objects`: a greedy colouring, so that no two neighbours among
        them share a round, the objects with the most neighbours first (ties in object order):
        they are walked while most of their neighbours are yet to be made, and those with few
        neighbours, walked last, have few walks to thread between (and there are fewer rounds)."""
        colour = {}
        for i in sorted(objects, key=lambda i: (-len(near[i]), i)):
            taken = {colour[j] for j in near[i] if j in colour}
            colour[i] = next(c for c in range(len(taken) + 1) if c not in taken)
        return colour

    def _desynchronise(self, animation, targets, seeds, frames, near, report) -> tuple[list, int]:
        """Section 6.2: each object still in step with a neighbour on more than MAX_IN_STEP of its
        frames is walked again avoiding its neighbours' frames. They go in rounds of objects no
        two of which are neighbours (see _rounds), each round in parallel and seeing the walks of
        the rounds before; an object avoids the neighbours that keep their walks and those walked
        again in earlier rounds, not those of this round or later ones, which avoid it in turn
        (so it keeps room to vary): they are passed as walks yet to be made (rows of -1), which
        count for the room a loop leaves it. `frames` (animation.source_frames()) is kept up to
        date. Returns the walks and how many objects were walked again."""
        walks = list(animation.walks)
        periods = self._periods(animation.placement)
        need = [i for i, nb in enumerate(near)
                if len(nb) and in_step(frames[i], frames[nb], periods[i]).max() > MAX_IN_STEP]  # fmt: skip
        colour = self._rounds(need, near)
        for c in range(max(colour.values(), default=-1) + 1):
            members = [i for i in need if colour[i] == c]
            items = [(i, targets[i], int(seeds[i].generate_state(2)[1]), self._avoided(frames, near[i], colour, c))
                     for i in members]  # fmt: skip
            again, played = self._walk_many(animation.placement, items, report, f"out of step ({c + 1})")
            for i, walk, own in zip(members, again, played):
                walks[i] = walk
                frames[i, : len(own)] = own
        return walks, len(need)

    @staticmethod
    def _avoided(frames, near, colour, c):
        """What an object of round c avoids: its neighbours' frames, -1 (nothing) for those walked
        again in round c or later, which avoid it in turn; None without neighbours."""
        if not len(near):
            return None
        avoided = frames[near].copy()
        avoided[[colour.get(int(j), -1) >= c for j in near]] = -1
        return avoided

    def _periods(self, placement: Placement) -> list:
        """Each object's parts' periods (MotionGraph.period: None for a part that does not loop)."""
        own = [[g.period for g in template_view(t).graphs] for t in self.templates]
        return [own[kind] for kind in placement.templates]

    def _warn_in_step(self, placement: Placement, frames, near) -> None:
        """A FlockkitWarning for each template part that a pair of neighbours still plays in step
        on more than MAX_IN_STEP of frames (around the loop, for a looping part), naming it, the
        pairs and what its graph offers."""
        periods = self._periods(placement)
        stuck = {}  # (template, part) -> pairs in step
        for i, nb in enumerate(near):
            later = nb[nb > i]
            if not len(later):
                continue
            shares = part_in_step(frames[i], frames[later], periods[i])  # (neighbours, parts)
            kind = int(placement.templates[i])
            for part in np.flatnonzero((shares > MAX_IN_STEP).any(axis=0)):
                stuck[kind, int(part)] = stuck.get((kind, int(part)), 0) + int(np.sum(shares[:, part] > MAX_IN_STEP))
        pairs = sum(len(nb) for nb in near) // 2
        for (kind, part), count in sorted(stuck.items()):
            graph = template_view(self.templates[kind]).graphs[part]
            shifts = int(np.count_nonzero(graph.shifts))
            ordinary = len(graph.transitions) - shifts
            if graph.period is not None and shifts:
                members = np.flatnonzero(placement.templates == kind)
                crowd = max((len(near[i]) for i in members), default=0)
                why = (f"its graph loops over {graph.period} frames with {shifts} phase shifts, too few phases to "
                       f"keep up to {crowd} close neighbours out of step: place the objects farther apart or use "
                       f"fewer")  # fmt: skip
            else:
                why = (f"its graph has {ordinary} transition{'s' * (ordinary != 1)} and {shifts} phase shifts over "
                       f"{graph.kept_frames()} frames: build the layers from a longer source, or with phase shifts "
                       f"(the windowed builder adds them to sparse graphs unless shift_blend=0)")  # fmt: skip
            warnings.warn(
                f"Scene: template {kind} part {part} still plays in step with a neighbour (source frames at most "
                f"{IN_STEP_FRAMES} apart) on more than {MAX_IN_STEP:.0%} of frames for {count} of {pairs} neighbour "
                f"pairs after de-synchronisation: {why}",
                FlockkitWarning,
                stacklevel=3,
            )


@contextlib.contextmanager
def _collection_paused():
    """Python's cyclic garbage collection paused (as it was, after): walks make and gather
    millions of small tuples (their edges) and no reference cycles, and each collection would
    scan the templates' and the walks' objects again (a sixth of the walks' time on
    bench/scene_assets.py's scene)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def _walk_batch(scene: Scene, placement: Placement, items) -> list:
    """(walk, the source frames it plays) of _walk_object for each (object, target, seed, avoid)
    of `items` (the frames made here, on the worker, where the walk is)."""
    results = []
    with _collection_paused():
        for i, target, seed, avoid in items:
            walk = _walk_object(scene, i, placement, target, seed, avoid)
            template = scene.templates[placement.templates[i]]
            clock = target.clock if isinstance(target, Course) else None
            frames = SceneAnimation._frames_of(template, walk, scene.n_frames, clock).astype(np.int32)
            results.append((walk, frames))
    return results


def _walk_object(scene: Scene, i: int, placement: Placement, target, seed: int, avoid):
    """Object i's walk (a Walk, or a LayeredWalk of one walk per part), each part with its own
    random stream from `seed`, after `target` (its world arrows per frame, or a moving object's
    Course, walked in its source time); `avoid` (neighbours, parts, frames) of source frames to
    fall out of step with."""
    kind = int(placement.templates[i])
    view = template_view(scene.templates[kind])
    duration = scene.duration
    if isinstance(target, Course):
        local, duration = target.track, target.n_source * scene.frame_time
        avoid = avoid_in_source_time(avoid, target.clock, target.n_source)
    else:  # the world's arrows in the template's coordinates (R^T w)
        local = target @ heading_turn(placement.headings[i], 3)
    track = Features(vectors=local[:, : view.source.dims], dt=scene.frame_time)
    part_params = None if avoid is None else [{"avoid": avoid[:, k]} for k in range(len(view.graphs))]
    params = {**scene.walk_params, "target": track, "features": view.features(kind, needed=False)}
    walks = walk_parts(view.graphs, strategy=scene.walk, duration=duration, seed=seed, part_params=part_params,
                       **params)  # fmt: skip
    return view.walk_of(walks)
