"""Scene files (TOML): what ``flockkit scene`` reads.

::

    duration = 60            # seconds
    seed = 1
    region = [[0, 0], [40, 0], [40, 30], [0, 30]]   # a simple polygon on the ground
    scale = [0.8, 1.2]       # optional: uniform scales
    headings = "aligned"     # optional: "random" (default) or "aligned"

    [[templates]]            # one per template: layers or graph, a flockkit file, relative to this one
    layers = "plants.npz"
    count = 30

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

from pathlib import Path

from .. import _files, _tomlfile
from ..errors import FlockkitError, ValidationError
from ..graphs import MotionGraph
from ..regions import Polygon
from .flow import Arrow, FlowField, SelfMovement
from .layers import GraphLayers
from .scene import Scene

__all__ = ["read_scene"]

_KEYS = {"duration", "seed", "region", "scale", "headings", "templates", "arrows", "self_movement", "walk", "n_jobs"}


def read_scene(path, *, n_jobs: int | None = None, allow_outside: bool = False) -> Scene:
    """The Scene a TOML scene file describes; errors name the file and the entry. The template
    files it names must lie in its folder (below it), unless `allow_outside` is True."""
    path = Path(path)
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
            if len(kinds) != 1 or "count" not in entry or set(entry) - {"layers", "graph", "count"}:
                raise ValidationError(f"[[templates]] {k} needs one of layers or graph, and count")
            file = _files.confined(path.parent, entry[kinds[0]], source=path, where=f"templates[{k}].{kinds[0]}",
                                   allow_outside=allow_outside, uri=False)  # fmt: skip
            templates.append((GraphLayers if kinds[0] == "layers" else MotionGraph).load(file))
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
            walk_params=data.get("walk", {}),
            n_jobs=n_jobs,
        )
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"{path}: {exc}") from None
    except FlockkitError as exc:
        raise type(exc)(str(exc) if str(exc).startswith(str(path)) else f"{path}: {exc}") from None
    except (TypeError, ValueError, OverflowError) as exc:  # a value of the wrong type or size
        raise ValidationError(f"{path}: {type(exc).__name__}: {exc}") from None
