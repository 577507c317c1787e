"""Walk strategies of paper 000 section 5: random walks (5.1) and walks kept inside a region (5.2).

Both respect blends: a transition is only taken once the previous one's blend has played out
(``MotionGraph.allowed_edges``), so synthesis never overlaps two blends.
"""

from __future__ import annotations

import math

import attrs
import numpy as np

import flockkit
from flockkit import rigid, validate
from flockkit.errors import ValidationError


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


@attrs.frozen(kw_only=True)
class RandomWalk:
    """Uniformly random edges from `start` (None: a random node) until `duration` seconds are played."""

    start: int | None = validate.parameter("walk", default=None, kind="integer", minimum=0, optional=True)

    def walk(self, graph: flockkit.MotionGraph, rng: np.random.Generator, duration: float) -> flockkit.Walk:
        _check_graph(graph)
        needed = _check_duration(duration, graph)
        node = _start_node(graph, self.start, rng)
        start, since, played, edges = node, math.inf, 0, []
        while played < needed:
            options = graph.allowed_edges(node, since)
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


@attrs.frozen(kw_only=True)
class RegionWalk:
    """Keep the group's center of mass inside `region` (paper 000 section 5.2).

    At each node the outgoing edges are tried in random order; an edge is taken if a depth-first
    search finds a path starting with it whose center of mass stays inside the region over the
    whole edge and `horizon` seconds from its start (across a transition both the old motion's
    continuation, which its blend mixes in, and the new one are checked). The walk starts with the
    group's center of mass at the region's center (for a polygon, an interior point).

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

    def walk(self, graph: flockkit.MotionGraph, rng: np.random.Generator, duration: float) -> flockkit.Walk:
        _check_graph(graph)
        needed = _check_duration(duration, graph)
        if self.region.dims != graph.motion.dims:
            raise ValidationError(f"region is {self.region.dims}D but the graph's motion is {graph.motion.dims}D")
        com = graph.motion.center_of_mass()
        node = _start_node(graph, self.start, rng)
        rotation = np.eye(graph.motion.dims)
        translation = self.region.interior_point() - com[graph.nodes[node]]
        if not self.region.contains(com[graph.nodes[node]] + translation):
            raise ValidationError("the region cannot hold the group's center of mass even at the start")
        search = _Search(graph, self.region, com, math.ceil(self.horizon / graph.motion.dt), self.budget)
        # Depth-first over decisions: each entry holds a state and the edges still to try there;
        # when none is left, step back and try the previous decision's next edge.
        stack = [(node, math.inf, rotation, translation, 0, self._order(graph, node, math.inf, rng))]
        edges, tries = [], 0
        while stack[-1][4] < needed:
            node, since, rotation, translation, played, options = stack[-1]
            while options:
                edge = options.pop()
                tries += 1
                if search.keeps_inside(edge, since, rotation, translation, rng):
                    break
            else:
                stack.pop()
                if not stack or tries > 20 * self.budget:
                    raise ValidationError(
                        f"cannot keep the group inside the region for {duration} s: every path leaves it within "
                        f"{self.horizon} s look-ahead (searched {tries} edges); use a larger region or horizon, or a "
                        "graph with more transitions"
                    )
                edges.pop()
                continue
            edges.append(edge)
            rotation, translation = _advance(graph, edge, rotation, translation)
            frames = _frames_of(graph, edge)
            since = since + frames if edge[0] == "clip" else 0
            target = graph.edge_target(edge)
            stack.append(
                (target, since, rotation, translation, played + frames, self._order(graph, target, since, rng))
            )
        return flockkit.Walk(
            start=stack[0][0], edges=edges, rotation=np.eye(graph.motion.dims), translation=stack[0][3]
        )

    @staticmethod
    def _order(graph, node, since, rng) -> list:
        """The edges allowed at `node`, in the random order they will be tried (last first)."""
        options = graph.allowed_edges(node, since)
        return [options[i] for i in rng.permutation(len(options))]


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
            frames = np.arange(clip.start + 1, end + 1)
            if not np.all(self.region.contains(self.com[frames] @ rotation.T + translation)):
                return False
            ahead += len(frames)
            since += len(frames)
        else:
            # A blend mixes the old motion's continuation in: check it too (inside a convex
            # region, a blend of two inside points stays inside).
            transition = graph.transitions[edge[1]]
            frames = np.arange(transition.start, transition.start + transition.blend)
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
