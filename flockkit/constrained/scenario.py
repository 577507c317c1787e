"""Scenario files: a constrained-animation Problem and solver settings in TOML.

::

    [problem]
    agents = 20          # required; dims = 2, dt = 0.1, flocks = 1, sigma_com, shape_weight, flock_weight,
    duration = 8.0       # visibility, clearance and follow are optional (defaults as in Problem)

    [behavior]           # optional: the behavior model's name (default "boids") and its parameters, which
    name = "boids"       # also define what is plausible (paper 004, Figure 8); dt and obstacles come from
    cohesion_weight = 6.0  # [problem] and [[obstacle]]

    [solve]              # optional: iterations, refine, starts, chains, seed, stable,
                         # proposals = {bump = 0.6, ...}, objectives = [...]
    iterations = 1000

    [[point]]            # agent, time, position, optional velocity
    agent = 0
    time = 1.0
    position = [-3.0, 0.0]

    [[com]]              # optional agents (default all), time, position, optional velocity
    [[shape]]            # optional agents, time, velocity, and one of
                         #   polygon = [[x, y], ...] / box = {lower = [...], upper = [...]} /
                         #   ball = {center = [...], radius = r}
    [[obstacle]]         # one of polygon / box / ball, as for shapes
"""

from __future__ import annotations

from pathlib import Path

from .. import _tomlfile, validate
from ..errors import FlockkitError, ValidationError
from ..regions import Ball, Box, Polygon
from .problem import ComConstraint, PointConstraint, Problem, ShapeConstraint
from .sampler import DEFAULT_BEHAVIOR

_PROBLEM_KEYS = {
    "agents": "n_agents",
    "dims": "dims",
    "dt": "dt",
    "duration": "duration",
    "flocks": "flocks",
    "sigma_com": "sigma_com",
    "shape_weight": "shape_weight",
    "flock_weight": "flock_weight",
    "visibility": "visibility",
    "clearance": "clearance",
    "follow": "follow",
    "keyframed_weight": "keyframed_weight",
}
# [behavior]: its name, and everything else is a parameter of the model
_BEHAVIOR_NAME = "name"
_SOLVE_KEYS = {
    "iterations",
    "refine",
    "starts",
    "chains",
    "seed",
    "proposals",
    "objectives",
    "stable",
}
_CONSTRAINT_KEYS = {
    "point": {"agent", "time", "position", "velocity"},
    "com": {"agents", "time", "position", "velocity"},
    "shape": {"agents", "time", "velocity", "polygon", "box", "ball"},
}


def load_scenario(path) -> tuple[Problem, dict]:
    """(Problem, solve settings) from a scenario file; errors name the file and the entry. The
    settings are ``flockkit.solve``'s keyword arguments: [solve]'s, and from a [behavior] table
    ``behavior`` (its name) and ``behavior_params`` (the rest)."""
    path = Path(path)
    data = _tomlfile.read(path, "scenario")
    unknown = set(data) - {"problem", "behavior", "solve", "point", "com", "shape", "obstacle"}
    if unknown:
        raise ValidationError(
            f"{path}: unknown table {sorted(unknown)[0]!r}; expected problem, behavior, solve, point, com, shape, "
            "obstacle"
        )
    try:
        problem_table = _table(data, "problem", path)
        _only(problem_table, set(_PROBLEM_KEYS), f"{path}: [problem]")
        settings = _table(data, "solve", path, required=False)
        _only(settings, _SOLVE_KEYS, f"{path}: [solve]")
        settings = dict(settings, **_behavior(_table(data, "behavior", path, required=False), path))
        if "seed" in settings:
            validate.seed(settings["seed"], f"{path}: [solve] seed")
        for key in ("iterations", "refine", "starts", "chains"):
            if key in settings:
                validate.integer(
                    settings[key], f"{path}: [solve] {key}", minimum=1 if key in ("starts", "chains") else 0
                )
        constraints = []
        for kind, build in (("point", _point), ("com", _com), ("shape", _shape)):
            for index, entry in enumerate(_array(data, kind, path)):
                where = f"{path}: [[{kind}]] number {index + 1}"
                _only(entry, _CONSTRAINT_KEYS[kind], where)
                constraints.append(_named(where, build, entry))
        obstacles = [
            _named(f"{path}: [[obstacle]] number {i + 1}", _region, entry)
            for i, entry in enumerate(_array(data, "obstacle", path))
        ]
        problem = _named(
            f"{path}: [problem]",
            lambda: Problem(
                **{_PROBLEM_KEYS[k]: v for k, v in problem_table.items()}, constraints=constraints, obstacles=obstacles
            ),
        )
    except TypeError as exc:
        raise ValidationError(f"{path}: {exc}") from None
    return problem, dict(settings)


def _behavior(table: dict, path) -> dict:
    """``behavior`` and ``behavior_params`` settings from a [behavior] table (none if it is empty);
    the model checks its parameters when ``solve`` makes it."""
    if not table:
        return {}
    name = table.get(_BEHAVIOR_NAME, DEFAULT_BEHAVIOR)
    if not isinstance(name, str):
        raise ValidationError(f"{path}: [behavior] name must be an installed behavior model's name; got {name!r}")
    params = {k: v for k, v in table.items() if k != _BEHAVIOR_NAME}
    clash = sorted({"dt", "obstacles"} & set(params))
    if clash:
        raise ValidationError(
            f"{path}: [behavior] {clash[0]} comes from the scenario ([problem] dt, [[obstacle]]); leave it out"
        )
    return {"behavior": name, "behavior_params": params}


def _named(where, build, *args):
    try:
        return build(*args)
    except FlockkitError as exc:
        raise ValidationError(f"{where}: {exc}") from None
    except TypeError as exc:
        raise ValidationError(f"{where}: {exc}") from None


def _table(data, name, path, required=True) -> dict:
    value = data.get(name, None if required else {})
    if not isinstance(value, dict):
        raise ValidationError(
            f"{path}: expected a [{name}] table" + ("" if value is None else f"; got {type(value).__name__}")
        )
    return value


def _array(data, name, path) -> list:
    value = data.get(name, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise ValidationError(f"{path}: {name} must be an array of tables, written [[{name}]]")
    return value


def _only(entry, allowed, where):
    unknown = set(entry) - allowed
    if unknown:
        raise ValidationError(
            f"{where}: unknown key {sorted(unknown)[0]!r}; expected some of {', '.join(sorted(allowed))}"
        )


def _point(entry):
    return PointConstraint(**entry)


def _com(entry):
    return ComConstraint(**entry)


def _shape(entry):
    entry = dict(entry)
    shape = _region({k: entry.pop(k) for k in ("polygon", "box", "ball") if k in entry})
    return ShapeConstraint(shape=shape, **entry)


def _region(entry):
    kinds = [k for k in ("polygon", "box", "ball") if k in entry]
    if len(kinds) != 1 or len(entry) != 1:
        raise ValidationError(f"expected exactly one of polygon, box or ball; got {', '.join(sorted(entry)) or 'none'}")
    value = entry[kinds[0]]
    if kinds[0] == "polygon":
        return Polygon(vertices=value)
    if not isinstance(value, dict):
        raise ValidationError(f"{kinds[0]} must be a table, e.g. {kinds[0]} = {{...}}")
    return Box(**value) if kinds[0] == "box" else Ball(**value)
