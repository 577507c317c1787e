"""Scene files (TOML): what ``flockkit scene`` reads.

::

    duration = 60            # seconds
    seed = 1
    region = [[0, 0], [40, 0], [40, 30], [0, 30]]   # a simple polygon on the ground
    scale = [0.8, 1.2]       # optional: uniform scales
    headings = "aligned"     # optional: "random" (default) or "aligned"
    max_turn = 90            # optional: degrees a second a moving object turns at most (default 90)

    [[templates]]            # one per template: layers or graph, a flockkit file, relative to this one
    layers = "plants.npz"
    count = 30
    features = [[0, [0.8, 0]], [2.5, [0.3, 0.1]]]   # optional, for layers that carry no feature
                             # arrows (build --layers makes none): keyframed [time, vector], time in
                             # seconds of the template's source, vectors in its coordinates
    speed = "stride"         # optional: the arrows are self-movement (a walk played in place): the
                             # object moves and turns after its targets; units a second an arrow of
                             # length 1 carries it, or "stride": measured from its feet

    [[arrows]]               # a flow field: physical-force arrows, keyframed [time, vector]
    position = [20, 15]
    keyframes = [[0, [0.8, 0]], [15, [0.8, 0]], [17, [0, 0.8]]]

    [[self_movement]]        # optional: an arrow riding on one object
    object = 0
    keyframes = [[0, [1, 0]]]

    [walk]                   # optional: annotated walk parameters (alpha, beta, segment, budget, ...)
    budget = 20
"""

from __future__ import annotations

import math
from pathlib import Path

import attrs
import numpy as np

from .. import _files, _tomlfile
from ..errors import FlockkitError, ValidationError
from ..graphs import MotionGraph
from ..regions import Polygon
from ..validate import number
from .features import Features, stride_speed
from .flow import Arrow, FlowField, SelfMovement
from .layers import GraphLayers
from .movement import MAX_TURN
from .scene import Scene

__all__ = ["read_scene", "FEATURE_SOURCES"]

_KEYS = {
    "duration",
    "seed",
    "region",
    "scale",
    "headings",
    "templates",
    "arrows",
    "self_movement",
    "walk",
    "n_jobs",
    "max_turn",
}

# Where the feature arrows of layers that carry none come from (read_scene's `features`): the
# paper's two kinds of annotation (section 4.2), keyframed by hand, or an object's own movement.
FEATURE_SOURCES = ("keyframes", "motion")


def read_scene(path, *, features: str | None = None, n_jobs: int | None = None, allow_outside: bool = False) -> Scene:
    """The Scene a TOML scene file describes; errors name the file and the entry. The template
    files it names must lie in its folder (below it), unless `allow_outside` is True.

    A scene's objects follow arrows matched against their templates' feature arrows, one per
    source frame (``flockkit.Features``). Layers built with ``features=`` carry theirs, and a
    plain graph's come from its motion; layers that carry none (what ``flockkit build --layers``
    writes) get them from their ``[[templates]]`` entry's ``features`` keyframes where it has
    them (``[[time, vector], ...]``: seconds of the source and vectors in its coordinates,
    interpolated as ``Features.from_keyframes``), else as `features` says: "motion", the
    source's own heading and speed (``Features.from_motion``: animals, characters, flocks that
    travel); "keyframes", the entry's keyframes, which every such template must then have; None
    (the default), none, and such a template is refused naming both ways."""
    path = Path(path)
    if features is not None and features not in FEATURE_SOURCES:
        raise ValidationError(
            f"read_scene: features must be one of {', '.join(map(repr, FEATURE_SOURCES))} or None; got {features!r}"
        )
    data = _tomlfile.read(path, "scene")
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise ValidationError(f"{path}: unknown entry {unknown[0]!r}; expected {', '.join(sorted(_KEYS))}")
    for key in ("duration", "region", "templates"):
        if key not in data:
            raise ValidationError(f"{path}: missing {key!r}")
    try:
        templates, counts = [], []
        for k, entry in enumerate(data["templates"]):
            kinds = [key for key in ("layers", "graph") if key in entry]
            allowed = {"layers", "graph", "count", "features", "speed"}
            if len(kinds) != 1 or "count" not in entry or set(entry) - allowed:
                raise ValidationError(
                    f"[[templates]] {k} needs one of layers or graph, and count (features and speed optional)"
                )
            file = _files.confined(path.parent, entry[kinds[0]], source=path, where=f"templates[{k}].{kinds[0]}",
                                   allow_outside=allow_outside, uri=False)  # fmt: skip
            template = (GraphLayers if kinds[0] == "layers" else MotionGraph).load(file)
            template = _with_features(template, entry.get("features"), features, k, entry[kinds[0]])
            templates.append(_with_speed(template, entry.get("speed"), k, entry[kinds[0]]))
            counts.append(entry["count"])
        for table, keys in (("arrows", {"position", "keyframes"}), ("self_movement", {"object", "keyframes"})):
            for k, entry in enumerate(data.get(table, [])):
                unknown = sorted(set(entry) - keys)
                if unknown:
                    raise ValidationError(
                        f"[[{table}]] {k}: unknown key {unknown[0]!r}; expected {', '.join(sorted(keys))}"
                    )
        constraints = []
        if data.get("arrows"):
            constraints.append(FlowField(arrows=[Arrow(**arrow) for arrow in data["arrows"]]))
        constraints += [SelfMovement(**entry) for entry in data.get("self_movement", [])]
        return Scene(
            templates=templates,
            region=Polygon(vertices=data["region"]),
            counts=counts,
            duration=data["duration"],
            constraints=constraints,
            seed=data.get("seed", 0),
            scale=data.get("scale", (1.0, 1.0)),
            headings=data.get("headings", "random"),
            max_turn=math.radians(
                number(data.get("max_turn", math.degrees(MAX_TURN)), "max_turn", minimum=0, strict=True)
            ),  # fmt: skip
            walk_params=data.get("walk", {}),
            n_jobs=n_jobs,
        )
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"{path}: {exc}") from None
    except FlockkitError as exc:
        raise type(exc)(str(exc) if str(exc).startswith(str(path)) else f"{path}: {exc}") from None
    except (TypeError, ValueError, OverflowError) as exc:  # a value of the wrong type or size
        raise ValidationError(f"{path}: {type(exc).__name__}: {exc}") from None


def _with_features(template, keyframes, source: str | None, k: int, name: str):
    """`template` with feature arrows: its own, its entry's `keyframes`, or as `source` says
    (see read_scene); a ValidationError naming the entry where it gets none, or keyframes it
    cannot take."""
    where = f"[[templates]] {k} ({name})"
    if not isinstance(template, GraphLayers) or template.features is not None:
        if keyframes is not None:
            own = "a graph's arrows come from its motion" if not isinstance(template, GraphLayers) else (
                "its layers carry their own feature arrows")  # fmt: skip
            raise ValidationError(f"{where} features: {own}; leave out features here")
        return template
    motion = template.source
    if keyframes is not None:
        try:
            arrows = Features.from_keyframes(keyframes, n_frames=motion.n_frames, dt=motion.dt)
        except ValidationError as exc:
            raise ValidationError(f"{where} features: {exc}") from None
    elif source == "motion":
        arrows = Features.from_motion(motion)
    elif source == "keyframes":
        raise ValidationError(
            f"{where}: features='keyframes' (flockkit scene --features keyframes) but the entry has no features "
            f"keyframes: add features = [[time, [x, y]], ...] (seconds of its {motion.duration:g} s source)"
        )
    else:
        raise ValidationError(
            f"{where}: its layers carry no feature arrows (flockkit build --layers makes none), which a scene's "
            f"objects need to follow arrows: give the entry features = [[time, [x, y]], ...] keyframes, or take them "
            f"from its own motion with features='motion' (flockkit scene --features motion)"
        )
    return attrs.evolve(template, features=arrows)


def _with_speed(template, speed, k: int, name: str):
    """`template` whose arrows are self-movement at `speed` (units a second of an arrow of length
    1; "stride": the source's stride_speed along its mean arrow over that arrow's length), or
    unchanged where `speed` is None."""
    if speed is None:
        return template
    where = f"[[templates]] {k} ({name}) speed"
    if not isinstance(template, GraphLayers):
        raise ValidationError(f"{where}: only layers walk in place; a graph's motion travels by itself")
    arrows = template.features.vectors
    mean = arrows.mean(axis=0)
    if speed == "stride":
        length = float(np.linalg.norm(mean))
        if length < 1e-9 or template.source.dims != 3:
            raise ValidationError(f"{where}: 'stride' needs 3D layers whose arrows point somewhere (their mean is 0)")
        speed = stride_speed(template.source, forward=mean) / length
        if speed <= 0:
            raise ValidationError(
                f"{where}: the source's feet do not push back along its arrows {np.round(mean, 3).tolist()} (ground "
                f"speed {speed * length:.3g}): its features must point the way it faces"
            )
    elif isinstance(speed, str):
        raise ValidationError(f"{where}: a number (units a second of an arrow of length 1) or 'stride'; got {speed!r}")
    return attrs.evolve(template, features=attrs.evolve(template.features, speed=speed))
