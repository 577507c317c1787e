"""A scene template seen one way, whatever it is: the one place a scene asks whether a template
is a GraphLayers (an object's parts) or a MotionGraph (one part), and where it stands."""

from __future__ import annotations

import attrs
import numpy as np

from ..errors import ValidationError
from ..graphs import MotionGraph, played_positions, synthesize_graph
from ..motion import Motion
from .features import Features
from .layers import GraphLayers, LayeredWalk, affine, played_layers, synthesize_layers


@attrs.frozen(eq=False)
class TemplateView:
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
                f"Scene.templates[{k}] has no features: a scene's objects follow arrows (its constraints', or one "
                f"made from the first template's features when it has none), matched against their template's "
                f"feature arrows: build its layers with features= (flockkit.Features, e.g. Features.from_keyframes "
                f"or Features.from_motion)"
            )
        return self.template.features

    def walk_of(self, walks: list):
        """The template's walk from its parts' walks: a LayeredWalk, or the one Walk."""
        return LayeredWalk(walks=walks) if self.layered else walks[0]

    def part_walks(self, walk) -> tuple:
        return walk.walks if self.layered else (walk,)

    def played_arrows(self, walk) -> np.ndarray:
        """(S, D): the feature arrow `walk` plays at each of its frames, the mean over its parts'
        (each part plays its own source frame), over the frames every part plays."""
        from ..graphs import played_frames

        frames = [played_frames(g, w)[0] for g, w in zip(self.graphs, self.part_walks(walk))]
        n = min(len(f) for f in frames)
        vectors = np.asarray(self.features(0, needed=False).vectors)
        return np.mean([vectors[f[:n]] for f in frames], axis=0)

    def synthesize(self, walk) -> Motion:
        return synthesize_layers(self.template, walk) if self.layered else synthesize_graph(self.template, walk)

    def played(self, walk, n_frames: int | None = None, matrix=None, offset=None) -> np.ndarray:
        """(F, N, D): the first `n_frames` frames (default: all) that `walk` plays, frames past
        them never made, each point p mapped to ``matrix @ p + offset`` where they are given (an
        object placed in the world) as it is written."""
        if self.layered:
            return played_layers(self.template, walk, n_frames, matrix, offset)
        positions = np.ascontiguousarray(played_positions(self.template, walk, n_frames))
        if matrix is not None:
            d = positions.shape[2]
            matrix, offset = (np.ascontiguousarray(a, dtype=np.float64) for a in (matrix, offset))
            affine(positions.reshape(-1), 0, positions.size, d, matrix, offset)
        return positions


def template_view(template) -> TemplateView:
    if isinstance(template, GraphLayers):
        return TemplateView(template=template, graphs=template.graphs, source=template.source, layered=True)
    if isinstance(template, MotionGraph):
        return TemplateView(template=template, graphs=(template,), source=template.motion, layered=False)
    raise ValidationError(
        f"Scene.templates entries must be flockkit.GraphLayers or MotionGraph; got {type(template).__name__}"
    )


def footprint(template) -> tuple[np.ndarray, np.ndarray]:
    """(center (D,), half extents (2,)): the template's mean center of mass, and the half size in
    x and y of the box around every frame's shape about its own center of mass (what it covers
    where it stands, wherever its recording travels)."""
    source = template_view(template).source
    com = source.center_of_mass()
    relative = source.positions[..., :2] - com[:, None, :2]
    half = np.maximum(np.abs(relative.min(axis=(0, 1))), np.abs(relative.max(axis=(0, 1))))
    center = com.mean(axis=0)
    if source.dims == 3:
        center = np.array([center[0], center[1], 0.0])  # objects stand on the ground
    return center, half
