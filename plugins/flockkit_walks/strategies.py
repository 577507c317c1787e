"""Walk strategies of paper 000 section 5: random walks (5.1) and walks kept inside a region (5.2).

Both respect blends: a transition is only taken once the previous one's blend has played out
(``MotionGraph.allowed_edges``), so synthesis never overlaps two blends. Turns (transitions from a
frame to itself, ``Transition.is_turn``) steer the group: a region walk takes them when it needs
to, a random walk only when asked.
"""

from __future__ import annotations

import math

import attrs
import numpy as np

import flockkit
from flockkit import rigid, validate
from flockkit.errors import ValidationError

# The room a region walk keeps on the group's way out (_Steer), as a fraction of the region's inner
# radius; edges that leave less are tried after those that leave more.
CUSHION = 0.1
# Frames apart of the points a way out is judged at (_Escape): a group moves a few hundredths of
# its region's width in them, and the walk's search checks every frame of what it takes anyway.
PATH_STRIDE = 4
# Starts a region walk tries (each a random node and heading) when every way from one leaves the
# region, unless it is given its start: a start inside a stretch of the graph that cannot turn
# (a solved bridge, a recording's straight run) may have none.
STARTS = 8
# The longest way out a region walk plays (_Escape), in seconds: a default boids flock with the
# default turns (15 degrees per 2 s blend) turns full circle in about 50 s.
ESCAPE_SECONDS = 60.0


def _check_graph(graph) -> None:
    if not isinstance(graph, flockkit.MotionGraph):
        raise ValidationError(f"a walk needs a flockkit.MotionGraph; got {type(graph).__name__}")


def _check_duration(duration, graph) -> int:
    """The frames a walk of `duration` seconds plays, refused before any work if its motion
    could not be held in memory."""
    duration = validate.number(duration, "walk duration (seconds)", minimum=0, strict=True)
    needed = math.ceil(duration / graph.motion.dt)
    # synthesizing it holds the positions, their gather indices and placed copies: about 4 times them
    what = f"a walk of {duration:g} s ({needed} frames)"
    validate.allocation(4 * needed * graph.motion.n_agents * graph.motion.dims, what)
    return needed


def _start_node(graph, start, rng) -> int:
    if start is None:
        return int(rng.integers(len(graph.nodes)))
    if start >= len(graph.nodes):
        raise ValidationError(f"walk start must be a node index in 0..{len(graph.nodes) - 1}; got {start!r}")
    return start


def _frames_of(graph, edge) -> int:
    return graph.clips[edge[1]].n_frames - 1 if edge[0] == "clip" else 0


def _source(graph, frames):
    """Source frames for frames counted on across the loop of a looping graph (MotionGraph.period)."""
    return frames if graph.period is None else frames % graph.period


def _is_turn(graph, edge) -> bool:
    return edge[0] == "transition" and graph.transitions[edge[1]].is_turn


@attrs.frozen(kw_only=True)
class RandomWalk:
    """Uniformly random edges from `start` (None: a random node) until `duration` seconds are
    played; turns only with `turns` (otherwise the group heads where its recording does)."""

    start: int | None = validate.parameter("walk", default=None, kind="integer", minimum=0, optional=True)
    turns: bool = validate.parameter("walk", default=False, kind="flag")

    def walk(self, graph: flockkit.MotionGraph, rng: np.random.Generator, duration: float) -> flockkit.Walk:
        _check_graph(graph)
        needed = _check_duration(duration, graph)
        node = _start_node(graph, self.start, rng)
        start, since, played, edges = node, math.inf, 0, []
        while played < needed:
            options = graph.allowed_edges(node, since)
            if not self.turns:
                options = [e for e in options if not _is_turn(graph, e)] or options
            edge = options[int(rng.integers(len(options)))]
            edges.append(edge)
            played += _frames_of(graph, edge)
            since = since + _frames_of(graph, edge) if edge[0] == "clip" else 0
            node = graph.edge_target(edge)
        return flockkit.Walk(start=start, edges=edges)


def _region(value):
    if not isinstance(value, flockkit.Region):
        raise ValidationError(
            f"walk parameter region must be a flockkit region (Ball, Box or Polygon); got {type(value).__name__}"
        )
    return value


@attrs.frozen(kw_only=True, slots=False)
class RegionWalk:
    """Keep the group's center of mass inside `region` (paper 000 section 5.2).

    At each node the allowed edges are tried in an order that steers: each is judged by its way
    out, the graph played on from the edge's end turning one way at every chance for as long as a
    full circle takes; edges whose best way out keeps clear of the boundary come first, turns
    after other edges, with random ties so that walks differ; then the others, the most room
    first (so the group turns before a wall, and away from a corner, not into it). An edge is
    taken if a depth-first search finds a path starting with it whose center of mass stays
    inside the region over the whole edge and `horizon` seconds from its start (across a
    transition both the old motion's continuation, which its blend mixes in, and the new one are
    checked); when no edge at a node has one, the walk steps back and tries the previous node's
    next edge. The walk starts with the group's center of mass at the region's center (for a
    polygon, an interior point).

    A graph with turns (``Transition.is_turn``; kovar adds them by default) can be kept in a
    region a few turning circles wide; when a region cannot hold the group, the error says why in
    numbers: how far the group travels between transitions, how tight it can turn, and the
    region's width.

    Parameters
    ----------
    region : flockkit.Ball, flockkit.Box or flockkit.Polygon
    horizon : float
        Look-ahead in seconds.
    start : int, optional
        Start node (None: random).
    budget : int
        Edges the search may expand per decision before it gives an edge up.
    """

    region: object = attrs.field(converter=_region)
    horizon: float = validate.parameter("walk", default=3.0, minimum=0, strict=True)
    start: int | None = validate.parameter("walk", default=None, kind="integer", minimum=0, optional=True)
    budget: int = validate.parameter("walk", default=2000, kind="integer", minimum=1)

    capabilities = flockkit.Capabilities()  # the class: any region; an instance: its region's dimension

    def __attrs_post_init__(self):
        object.__setattr__(self, "capabilities", flockkit.Capabilities(dims=(self.region.dims,)))

    def walk(self, graph: flockkit.MotionGraph, rng: np.random.Generator, duration: float) -> flockkit.Walk:
        _check_graph(graph)
        needed = _check_duration(duration, graph)
        if self.region.dims != graph.motion.dims:
            raise ValidationError(f"region is {self.region.dims}D but the graph's motion is {graph.motion.dims}D")
        com = graph.motion.center_of_mass()
        horizon = math.ceil(self.horizon / graph.motion.dt)
        search = _Search(graph, self.region, com, horizon, self.budget)
        steer = _Steer(graph, self.region, com)
        tries, reached, starts = 0, 0, 0
        while starts < (1 if self.start is not None else STARTS) and tries <= 20 * self.budget:
            starts += 1
            node = _start_node(graph, self.start, rng)
            frame = graph.nodes[node]
            rotation = _start_heading(self.region, com, frame, horizon, rng)
            translation = self.region.interior_point() - rotation @ com[frame]
            if not self.region.contains(rotation @ com[frame] + translation):
                raise ValidationError("the region cannot hold the group's center of mass even at the start")
            # Depth-first over decisions: each entry holds a state and the edges still to try there;
            # when none is left, step back and try the previous decision's next edge.
            order = steer.order(node, math.inf, rotation, translation, rng)
            stack, edges = [(node, math.inf, rotation, translation, 0, order)], []
            while stack and stack[-1][4] < needed and tries <= 20 * self.budget:
                node, since, rotation, translation, played, options = stack[-1]
                while options:
                    edge = options.pop()
                    tries += 1
                    if search.keeps_inside(edge, since, rotation, translation, rng):
                        break
                else:
                    stack.pop()
                    if edges:
                        edges.pop()
                    continue
                edges.append(edge)
                rotation, translation = _advance(graph, edge, rotation, translation)
                frames = _frames_of(graph, edge)
                since = since + frames if edge[0] == "clip" else 0
                target = graph.edge_target(edge)
                order = steer.order(target, since, rotation, translation, rng)
                stack.append((target, since, rotation, translation, played + frames, order))
                reached = max(reached, played + frames)
            if stack and stack[-1][4] >= needed:
                return flockkit.Walk(start=stack[0][0], edges=edges, rotation=stack[0][2], translation=stack[0][3])
        seconds = reached * graph.motion.dt
        raise ValidationError(_impossible(graph, self.region, com, duration, self.horizon, tries, seconds, starts))


def _start_heading(region, com, frame, horizon, rng) -> np.ndarray:
    """A rotation of the start (about the up axis in 3D) that heads the group where the region is
    deep: of 16 headings, a random one among those whose next `horizon` frames (straight on, as
    recorded) keep at least 90% of the best depth."""
    path = com[frame : frame + max(horizon, 1) + 1] - com[frame]
    axis = None if com.shape[1] == 2 else flockkit.DEFAULT_UP
    rotations = [rigid.rotation(angle, axis) for angle in np.linspace(0, 2 * np.pi, 16, endpoint=False)]
    depth = np.array([-region.signed_distance(path @ r.T + region.interior_point()).max() for r in rotations])
    good = np.flatnonzero(depth >= depth.max() - 0.1 * abs(depth.max()))
    return rotations[int(rng.choice(good))]


class _Steer:
    """Orders a node's edges so that the walk turns before the region's boundary, not at it.

    Each edge is judged by whether the group could still escape the boundary after it: from its
    end, the graph is played turning one way at every chance (left, right; in 3D also up, down),
    as long as it takes the group to turn full circle (:class:`_Escape`), and the edge's *room* is
    the depth inside the region of the deepest such way out at its shallowest point. Edges that
    keep at least CUSHION of the region's inner radius come first, in random order with a
    preference for the recording's own motion, then the others, the most room first. Judged
    only by where the group will be a little later, a walk is led along one wall into the next:
    a corner that no turn gets it out of (a 20-boid flock in a box three turning circles wide did
    so for 4 seeds in 21).
    """

    def __init__(self, graph, region, com):
        self.graph, self.region, self.com = graph, region, com
        self.velocity = np.gradient(com, graph.motion.dt, axis=0)
        self.depth = max(-float(region.signed_distance(region.interior_point())), 1e-12)  # the inner radius
        speed = max(float(np.median(np.linalg.norm(self.velocity, axis=1))), 1e-12)
        # a full circle at the turns' tightest, but no longer than crossing the region twice or ESCAPE_SECONDS
        seconds = min(2 * math.pi * _turning_radius(graph, com), 4 * self.depth) / speed
        seconds = min(seconds, ESCAPE_SECONDS)
        self.escape = _Escape(graph, com, self.velocity, seconds)

    def order(self, node, since, rotation, translation, rng) -> list:
        """The edges allowed at `node`, the one to try first last (it is popped)."""
        options = self.graph.allowed_edges(node, since)
        room = np.array([self._room(edge, since, rotation, translation) for edge in options]) / self.depth
        turn = np.array([_is_turn(self.graph, edge) for edge in options])
        score = (room < CUSHION) * (10 - room) + 0.3 * turn + 0.5 * rng.random(len(options))
        return [options[i] for i in np.argsort(-score, kind="stable")]

    def _room(self, edge, since, rotation, translation) -> float:
        """How deep inside the group stays after `edge`, on its best way out."""
        r, t = _advance(self.graph, edge, rotation, translation)
        since = since + _frames_of(self.graph, edge) if edge[0] == "clip" else 0
        node = self.graph.edge_target(edge)
        ways = [self.escape.path(node, since, way) for way in self.escape.ways]
        return max(-float(self.region.signed_distance(path @ r.T + t).max()) for path in ways)


class _Escape:
    """Ways out: the center of mass of the group played on from a node, taking at every chance the
    transition that turns it most one way (a turn the graph made, or any transition that turns it
    so), else the clip; for `seconds`. Cached per node, whether a transition may be taken yet, and
    way; in the coordinates the walk reaches the node in, so one path serves every placement."""

    def __init__(self, graph, com, velocity, seconds):
        self.graph, self.com, self.velocity = graph, com, velocity
        self.blend = int(graph.tables.transition_blend.max())
        self.frames = max(math.ceil(seconds / graph.motion.dt), 1)
        self.ways = [1.0, -1.0] if com.shape[1] == 2 else ["left", "right", "down", "up"]
        self.cache = {}
        # per transition, the heading before it and the sine of its turn times the turn's axis (2D: signed)
        transitions = graph.transitions
        starts = np.array([t.start for t in transitions], dtype=int)
        ends = np.array([t.end for t in transitions], dtype=int)
        rotations = np.array([t.alignment.rotation for t in transitions]).reshape(-1, com.shape[1], com.shape[1])
        before = velocity[starts]
        after = np.einsum("kij,kj->ki", rotations, velocity[ends])
        scale = np.maximum(np.linalg.norm(before, axis=1) * np.linalg.norm(after, axis=1), 1e-300)
        if com.shape[1] == 2:
            self.turning = (before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]) / scale
        else:
            self.turning = np.cross(before, after) / scale[:, None]
        self.before = before

    def path(self, node, since, way) -> np.ndarray:
        key = (node, since >= self.blend, way)
        if key not in self.cache:
            path = self._play(node, since, way)
            self.cache[key] = np.concatenate([path[::PATH_STRIDE], path[-1:]])
        return self.cache[key]

    def _play(self, node, since, way) -> np.ndarray:
        graph, d = self.graph, self.com.shape[1]
        rotation, translation = np.eye(d), np.zeros(d)
        points, played = [self.com[graph.nodes[node]][None]], 0
        while played < self.frames:
            options = graph.allowed_edges(node, since)
            if not options:
                break
            edge = self._pick(options, rotation, way)
            if edge[0] == "clip":
                clip = graph.clips[edge[1]]
                frames = _source(graph, np.arange(clip.start + 1, clip.stop + 1))
                points.append(self.com[frames] @ rotation.T + translation)
                played += len(frames)
                since += len(frames)
            else:
                rotation, translation = _advance(graph, edge, rotation, translation)
                since = 0
            node = graph.edge_target(edge)
        return np.concatenate(points)

    def _pick(self, options, rotation, way):
        """The transition that turns the heading most `way`, if any turns it that way (by over a
        degree), else the clip, else the transition that turns it least the other way."""
        chosen = [k for k, edge in enumerate(options) if edge[0] == "transition"]
        if not chosen:
            return options[0]
        index = [options[k][1] for k in chosen]
        if self.com.shape[1] == 2:
            sense = way * self.turning[index]
        else:  # turning and headings as the walk has rotated them
            turning, before = self.turning[index] @ rotation.T, self.before[index] @ rotation.T
            up = np.asarray(flockkit.DEFAULT_UP)
            if way in ("left", "right"):
                axis = np.broadcast_to(up, before.shape)
            else:
                axis = np.cross(up, before)
                axis = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-300)
            sense = (1.0 if way in ("left", "down") else -1.0) * np.sum(turning * axis, axis=1)
        best = int(np.argmax(sense))
        if sense[best] > math.sin(math.radians(1)) or options[0][0] != "clip":
            return options[chosen[best]]
        return options[0]


def _turning_radius(graph, com) -> float:
    """The radius of the tightest circle the turns alone keep the group on: the distance it
    travels in a blend (the median) over the largest turn of a transition; infinite without turns."""
    blend = max(int(graph.tables.transition_blend.max()), 1)
    angles = [_turn_degrees(t.alignment.rotation) for t in graph.transitions if t.is_turn]
    if not angles or len(com) <= blend:
        return math.inf
    travel = float(np.median(np.linalg.norm(com[blend:] - com[:-blend], axis=1)))
    return travel / math.radians(max(angles))


def _turn_degrees(rotation) -> float:
    cosine = rotation[0, 0] if len(rotation) == 2 else (np.trace(rotation) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(cosine, -1, 1))))


def _impossible(graph, region, com, duration, horizon, tries, reached, starts=1) -> str:
    """Why a region walk failed, in numbers, and what to change: a region narrower than the
    group's tightest circle cannot hold it; in a wider one the search ran out (its look-ahead
    finds no way to turn in time on this graph), which the graph's edges or a longer look-ahead
    can change, not a wider region."""
    blend = max(int(graph.tables.transition_blend.max()), 1)
    dt = graph.motion.dt
    travel = float(np.linalg.norm(com[blend:] - com[:-blend], axis=1).min()) if len(com) > blend else 0.0
    width = 2 * max(-float(region.signed_distance(region.interior_point())), 0.0)
    angles = [_turn_degrees(t.alignment.rotation) for t in graph.transitions if t.is_turn]
    if angles:
        turning = f"it turns at most {max(angles):.3g} degrees per transition"
        circle = travel * 360 / max(angles) / np.pi
        change = "a graph with larger turn_angle or shorter blend_time"
    else:
        velocity = np.diff(com, axis=0)
        cosine = np.sum(velocity[blend:] * velocity[:-blend], axis=1) / np.maximum(
            np.linalg.norm(velocity[blend:], axis=1) * np.linalg.norm(velocity[:-blend], axis=1), 1e-300
        )
        degrees = max(float(np.degrees(np.arccos(np.clip(cosine, -1, 1))).max()), 1e-9) if len(cosine) else 1e-9
        turning = f"the graph has no turns and its recording turns at most {degrees:.3g} degrees per blend"
        circle = travel * 360 / degrees / np.pi
        change = "a graph with turns (kovar turn_angle > 0, its default)"
    numbers = (
        f"after each transition the group travels at least {travel:.3g} units before it may take another "
        f"({blend * dt:g} s blend); {turning}, so its tightest circle is about {circle:.3g} units across"
    )
    if circle < width:
        return (
            f"cannot keep the group inside the region for {duration:g} s: the search gave up after {tries} edges "
            f"from {starts} start{'s' if starts > 1 else ''}, "
            f"{reached:g} s in at best. The region, {width:.3g} units across at its narrowest, is wide enough for "
            f"the group's turns ({numbers}), but looking {horizon:g} s ahead the walk finds no way through this "
            f"graph's {len(graph.nodes)} nodes and {len(graph.transitions)} transitions that turns in time. Use a "
            f"longer horizon or a larger budget, or a graph with more ways to turn: solver-made bridges "
            f"(flockkit.graphs.bridge, kovar bridges=True), a longer recording, or {change}"
        )
    return (
        f"cannot keep the group inside the region for {duration:g} s (searched {tries} edges): {numbers}, "
        f"against a region {width:.3g} units across at its narrowest. Use a region wider than that circle, a "
        f"horizon longer than {horizon:g} s, or {change}"
    )


def _advance(graph, edge, rotation, translation):
    if edge[0] == "clip":
        return rotation, translation
    a = graph.transitions[edge[1]].alignment
    return rigid.compose((rotation, translation), (a.rotation, a.translation))


class _Search:
    """Depth-first look-ahead on the center of mass, which is all a region needs (it does not
    depend on which agent is which)."""

    def __init__(self, graph, region, com, horizon, budget):
        self.graph, self.region, self.com, self.horizon, self.budget = graph, region, com, horizon, budget

    def keeps_inside(self, edge, since, rotation, translation, rng) -> bool:
        self.left = self.budget
        return self._path(edge, since, rotation, translation, 0, rng)

    def _path(self, edge, since, rotation, translation, ahead, rng) -> bool:
        self.left -= 1
        if self.left < 0:
            return False
        graph = self.graph
        if edge[0] == "clip":
            clip = graph.clips[edge[1]]
            # the edge decided on is played whole, so it is checked whole, however long
            end = clip.stop if ahead == 0 else min(clip.stop, clip.start + self.horizon - ahead)
            frames = _source(graph, np.arange(clip.start + 1, end + 1))
            if not np.all(self.region.contains(self.com[frames] @ rotation.T + translation)):
                return False
            ahead += len(frames)
            since += len(frames)
        else:
            # A blend mixes the old motion's continuation in: check it too (inside a convex
            # region, a blend of two inside points stays inside).
            transition = graph.transitions[edge[1]]
            frames = _source(graph, np.arange(transition.start, transition.start + transition.blend))
            if not np.all(self.region.contains(self.com[frames] @ rotation.T + translation)):
                return False
            rotation, translation = _advance(graph, edge, rotation, translation)
            since = 0
        if ahead >= self.horizon:
            return True
        options = graph.allowed_edges(graph.edge_target(edge), since)
        return any(
            self._path(options[i], since, rotation, translation, ahead, rng) for i in rng.permutation(len(options))
        )
