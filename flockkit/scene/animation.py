"""A synthesized scene: the objects' motions in the world (synthesized when asked for), their
source frames and neighbours, saved to one .npz and exported to USD."""

from __future__ import annotations

import attrs
import numba
import numpy as np

from .. import _npzfile, validate
from ..errors import FileFormatError, ValidationError
from ..graphs import MotionGraph, Walk, played_frames
from ..io import USD_FPS
from ..motion import Motion
from ..regions import Polygon
from .desync import NEAREST, NEIGHBOUR_DIAGONALS, largest_in_step, stacked
from .flow import FlowField, SelfMovement, flow_constraints
from .layers import GraphLayers
from .movement import Paths, source_frames_at
from .placement import Placement, heading_turn, turned_half
from .templates import footprint, template_view

SCENE_FORMAT_VERSION = 1


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
    and the constraints it followed. `report`, when it comes from Scene.synthesize, holds after
    the first walks (made in rounds, each object avoiding the frames of its neighbours walked
    before it: ``first_rounds``) and at the end (after the pairs still in step were walked again:
    ``walked_again`` objects) the largest share of frames two neighbours play in step
    (``in_step_before``, ``in_step_after``: source frames at most ``in_step_frames`` apart in some
    part) and the share of neighbour pairs in step on more than 5% of frames
    (``pairs_in_step_before``, ``pairs_in_step_after``); see :meth:`neighbours`; and over the
    true nearest neighbours, the share of pairs in step within ``in_step_tolerance_frames``
    frames (``nearest_pairs_in_step``) and, for looping parts, within ``in_step_tolerance_phase``
    of their cycle (``nearest_pairs_in_phase``; ``flockkit.scene.desync.nearest_in_step``). `paths`, where
    some objects move (``flockkit.scene.movement``), holds where each object is, its heading and
    the source time it plays at each frame; None: every object stands where it is placed."""

    templates: tuple = attrs.field(converter=tuple)
    placement: Placement
    walks: tuple = attrs.field(converter=tuple)
    dt: float
    n_frames: int
    constraints: tuple = attrs.field(default=(), converter=flow_constraints)
    region: Polygon | None = attrs.field(default=None)
    report: dict = attrs.field(factory=dict)
    paths: Paths | None = attrs.field(default=None)
    _footprints: list = attrs.field(init=False, repr=False, eq=False)  # (center, half extents) per template

    def __attrs_post_init__(self):
        object.__setattr__(self, "_footprints", [footprint(t) for t in self.templates])

    @property
    def motions(self) -> _Motions:
        """One world-space Motion per object, each synthesized when indexed."""
        return _Motions(self)

    def motion(self, i: int) -> Motion:
        """Object i's motion in the world: its walk played, cut to n_frames, scaled, turned by its
        heading about +z and moved to its position (at each frame, where it moves: ``paths``)."""
        if self._moves(i):
            paths = self.paths
            return self._at_clock(i, paths.clocks[i], paths.headings[i], paths.positions[i])
        kind = self.placement.templates[i]
        view = template_view(self.templates[kind])
        dims = view.source.dims
        matrix = self.placement.scales[i] * heading_turn(self.placement.headings[i], dims)
        where = np.zeros(dims)
        where[:2] = self.placement.positions[i]
        return self._played(i, matrix, where - matrix @ self._footprints[kind][0])

    def local_motion(self, i: int) -> Motion:
        """Object i's points in its own frame at each output frame: its walk played at its clock,
        about the template's center, scaled; `transforms` places them (a moving object's export)."""
        if self._moves(i):
            return self._at_clock(i, self.paths.clocks[i], np.zeros(self.n_frames), np.zeros((self.n_frames, 2)))
        kind = self.placement.templates[i]
        dims = template_view(self.templates[kind]).source.dims
        scale = self.placement.scales[i]
        return self._played(i, scale * np.eye(dims), -scale * self._footprints[kind][0])

    def _moves(self, i: int) -> bool:
        return self.paths is not None and bool(self.paths.moving[i])

    def _played(self, i: int, matrix: np.ndarray, offset: np.ndarray) -> Motion:
        """Object i's first n_frames frames played, each point p written as matrix @ p + offset
        by the pass that plays it."""
        view = template_view(self.templates[self.placement.templates[i]])
        return Motion._adopt(view.played(self.walks[i], self.n_frames, matrix, offset), self.dt)

    def _at_clock(self, i: int, clock, headings, positions) -> Motion:
        """Object i played at `clock` (F,; source frames, linear between them), about its
        template's center, scaled, turned by `headings` (F,) about +z and moved to `positions`
        (F, 2): only the source frames the clock reaches are played."""
        kind = self.placement.templates[i]
        clock = np.asarray(clock, dtype=np.float64)
        reached = int(np.floor(max(float(clock.max()), 0.0))) + 2  # at_clock reads frames below and above
        local = template_view(self.templates[kind]).played(self.walks[i], reached)
        out = np.empty((len(clock), *local.shape[1:]))
        _placed_at_clock(local, np.asarray(self._footprints[kind][0], dtype=np.float64),
                         float(self.placement.scales[i]), clock, np.asarray(headings, dtype=np.float64),
                         np.asarray(positions, dtype=np.float64), out)  # fmt: skip
        return Motion._adopt(out, self.dt)

    def transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """(positions (objects, frames, 2) on the ground, headings (objects, frames) radians about
        +z): where each object's center is and how it is turned at each output frame."""
        if self.paths is not None:
            return np.asarray(self.paths.positions), np.asarray(self.paths.headings)
        n = self.n_frames
        return np.repeat(self.placement.positions[:, None], n, axis=1), np.repeat(self.placement.headings[:, None], n,
                                                                                  axis=1)  # fmt: skip

    @staticmethod
    def _frames_of(template, walk, n_frames: int, clock=None) -> np.ndarray:
        """(parts, n_frames): the source frame each part of `walk` plays at each output frame (at
        `clock`, a moving object's source time per output frame, if given)."""
        view = template_view(template)
        played = [played_frames(g, w)[0] for g, w in zip(view.graphs, view.part_walks(walk))]
        if clock is None:
            return np.stack([f[:n_frames] for f in played])
        return source_frames_at(np.stack([f[: min(map(len, played))] for f in played]), clock)

    def source_frames(self) -> np.ndarray:
        """(objects, parts, frames): the source frame each object's part plays at each output
        frame (-1 for parts an object's template does not have)."""
        return stacked(
            [
                self._frames_of(self.templates[kind], walk, self.n_frames, self._clock(i))
                for i, (kind, walk) in enumerate(zip(self.placement.templates, self.walks))
            ],
            self.n_frames,
        )

    def _clock(self, i: int):
        """Object i's clock where it moves, else None (it plays output frame t at t)."""
        return self.paths.clocks[i] if self.paths is not None and self.paths.moving[i] else None

    def bounding_boxes(self) -> np.ndarray:
        """(objects, 2, 2): the (low, high) corners in x, y of each object's placed footprint."""
        boxes = np.empty((self.placement.n_objects, 2, 2))
        for i in range(self.placement.n_objects):
            half = self._footprints[self.placement.templates[i]][1] * self.placement.scales[i]
            half = turned_half(half, self.placement.headings[i])
            boxes[i] = [self.placement.positions[i] - half, self.placement.positions[i] + half]
        return boxes

    def neighbours(self) -> list[np.ndarray]:
        """For each object, the other objects of its template within NEIGHBOUR_DIAGONALS
        footprint diagonals, and its NEAREST closest ones of its template however far (each way:
        if b is among a's nearest, a is b's neighbour too), sorted."""
        from scipy.spatial import cKDTree

        linked = [set() for _ in range(self.placement.n_objects)]
        for kind, (_, half) in enumerate(self._footprints):
            members = np.flatnonzero(self.placement.templates == kind)
            if len(members) < 2:
                continue
            reach = NEIGHBOUR_DIAGONALS * 2 * np.linalg.norm(half) * self.placement.scales[members].max()
            places = self.placement.positions[members]
            tree = cKDTree(places)
            _, nearest = tree.query(places, k=min(NEAREST + 1, len(members)))
            for row, near, closest in zip(
                members, tree.query_ball_point(places, reach), nearest.reshape(len(members), -1)
            ):
                for other in members[np.union1d(near, closest)]:
                    if other != row:
                        linked[row].add(int(other))
                        linked[int(other)].add(int(row))
        return [np.array(sorted(own), dtype=np.int64) for own in linked]

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
        writes motions. Needs usd-core.

        Objects are written where the scene placed them, in flockkit's axes: z up, standing on
        z = 0, turned about +z. An object that moves (``paths``) holds its points in its own
        frame and is placed by time-sampled translate and rotateZ ops: its transform over time.
        Templates built from a mesh read in another convention (a glTF file is y up) stand upright
        only if the mesh was converted before it was analysed (``AnimatedMesh.to_flockkit_axes``).
        The stage's ``customLayerData["flockkit"]`` records the axes and each template's height
        and size in metres; a FlockkitWarning with a hint (``flockkit.mesh.unit_hint``) comes
        where a template is a size no object plausibly has (a mesh modelled in centimetres and
        never said to be)."""
        from pathlib import Path

        if Path(path).suffix.lower() not in (".usda", ".usdc", ".usd"):
            raise ValidationError(f"SceneAnimation.export writes .usda, .usdc or .usd; got {path}")
        _export_usd(self, path, fps=fps, meters_per_unit=meters_per_unit)

    def __eq__(self, other):
        if not isinstance(other, SceneAnimation):
            return NotImplemented
        return (self.templates == other.templates and self.placement == other.placement and self.walks == other.walks
                and self.dt == other.dt and self.n_frames == other.n_frames and self.paths == other.paths)  # fmt: skip

    __hash__ = None

    def in_step_share(self) -> float:
        """The largest share of frames on which two neighbours play source frames at most
        IN_STEP_FRAMES apart at the same time (in some part)."""
        return largest_in_step(self.source_frames(), self.neighbours())


@numba.njit(cache=True, nogil=True)
def _placed_at_clock(local, center, scale, clock, headings, positions, out):
    """A moving object's points in one pass: `out` (F, N, D) is `local` (S, N, D) read at
    `clock` (``movement.at_clock``: linear between the frames around each, the ends held), about
    `center`, scaled, turned by each frame's heading about +z and moved to each frame's position
    (F, 2)."""
    last, dims = local.shape[0] - 1, local.shape[2]
    for t in range(out.shape[0]):
        c = min(max(clock[t], 0.0), float(last))
        below = min(int(np.floor(c)), max(last - 1, 0))
        above = min(below + 1, last)
        u = c - below
        cos, sin = np.cos(headings[t]), np.sin(headings[t])
        px, py = positions[t, 0], positions[t, 1]
        for p in range(out.shape[1]):
            x = ((1 - u) * local[below, p, 0] + u * local[above, p, 0] - center[0]) * scale
            y = ((1 - u) * local[below, p, 1] + u * local[above, p, 1] - center[1]) * scale
            out[t, p, 0] = cos * x - sin * y + px
            out[t, p, 1] = sin * x + cos * y + py
            if dims == 3:
                out[t, p, 2] = ((1 - u) * local[below, p, 2] + u * local[above, p, 2] - center[2]) * scale


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
    views = [template_view(t) for t in animation.templates]
    walks = [w for kind, walk in zip(animation.placement.templates, animation.walks)
             for w in views[kind].part_walks(walk)]  # fmt: skip
    arrays["walk_start"] = np.array([w.start for w in walks], dtype=np.int64)
    arrays["walk_edges"] = np.array([len(w.edges) for w in walks], dtype=np.int64)
    edges = [e for w in walks for e in w.edges]
    arrays["edge_transition"] = np.array([kind == "transition" for kind, _ in edges], dtype=bool)
    arrays["edge_index"] = np.array([index for _, index in edges], dtype=np.int64)
    if animation.paths is not None:
        for name in ("positions", "headings", "clocks", "moving"):
            arrays[f"paths.{name}"] = getattr(animation.paths, name)
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
        views = [template_view(t) for t in templates]
        for kind in placement.templates:
            parts = len(views[kind].graphs)
            walks.append(views[kind].walk_of(flat[at : at + parts]))
            at += parts
        if at != len(flat):
            raise ValidationError(f"{len(flat)} walks for {at} object parts")
        paths = None
        if "paths.positions" in arrays:
            paths = Paths(**{name: arrays[f"paths.{name}"] for name in ("positions", "headings", "clocks", "moving")})
        return SceneAnimation(templates=templates, placement=placement, walks=walks, dt=header["dt"], paths=paths,
                              n_frames=header["n_frames"], report=header.get("report", {}),
                              region=None if header.get("region") is None else Polygon(vertices=header["region"]),
                              constraints=[_constraint_from_json(c) for c in header["constraints"]])  # fmt: skip
    except (KeyError, IndexError, TypeError, ValueError, ValidationError) as exc:
        raise FileFormatError(f"{path}: invalid scene animation: {type(exc).__name__}: {exc}") from None


def _export_usd(animation: SceneAnimation, path, *, fps, meters_per_unit) -> None:
    """Each object an animated UsdGeom.Mesh (a template with faces) or UsdGeom.Points under
    /Scene, on the stage flockkit.io writes motions on."""
    import warnings

    from ..errors import FlockkitWarning
    from ..io.usd import write_meshes
    from ..mesh import object_size, unit_hint

    unit = validate.number(meters_per_unit, "SceneAnimation.export: meters_per_unit", minimum=0, strict=True)
    heights, sizes = [], []
    for k, template in enumerate(animation.templates):
        source = template_view(template).source
        heights.append(float(np.ptp(source.positions[..., 2])) * unit if source.dims == 3 else 0.0)
        sizes.append(object_size(source) * unit)
        hint = unit_hint(sizes[-1] / unit, unit, f"template {k}")
        if hint is not None:
            warnings.warn(f"SceneAnimation.export: {hint}", FlockkitWarning, stacklevel=3)
    metadata = {"up_axis": "z", "meters_per_unit": unit, "placement": "on the ground z = 0, turned about +z",
                "template_heights_m": heights, "template_sizes_m": sizes}  # fmt: skip
    width = len(str(animation.placement.n_objects))
    objects = []
    places, turns = animation.transforms()
    for i in range(animation.placement.n_objects):
        template = animation.templates[animation.placement.templates[i]]
        faces = template_view(template).faces
        name, custom = f"/Scene/Object{i:0{width}d}", {"flockkit:template": int(animation.placement.templates[i])}
        if animation.paths is not None and animation.paths.moving[i]:  # its own frame, placed by its transform
            ground = np.column_stack([places[i], np.zeros(animation.n_frames)])
            objects.append((name, animation.local_motion(i).positions, faces, custom, (ground, turns[i])))
        else:
            objects.append((name, animation.motion(i).positions, faces, custom))
    write_meshes(path, objects, dt=animation.dt, n_frames=animation.n_frames, fps=fps,
                 meters_per_unit=meters_per_unit, metadata=metadata)  # fmt: skip
