"""A ready distribution for a new plugin of any extension kind: what ``flockkit new-plugin`` writes.

:func:`write_plugin` writes a folder that installs and tests as it is::

    flockkit-<name>/
      pyproject.toml               the entry point in the flockkit group, dependencies = ["flockkit"]
      README.md                    how to install, test, and what to change
      flockkit_<name>/__init__.py  the ``@flockkit.hookimpl`` registration
      flockkit_<name>/<kind>.py    a small but real component of the kind (its docstring says what
                                   it does) that passes every check of the conformance kit
      tests/test_conformance.py    the kit, one test per check (``parametrize_with_checks``)
      tests/test_properties.py     hypothesis property tests drawn from ``flockkit.testing.strategies``

The components use only flockkit's public API (``import flockkit``, ``flockkit.validate``,
``flockkit.errors``), never a built-in plugin's package: they are what a plugin author starts from.
The sources are the string templates below; what every kind shares (pyproject, README, the
registration, the conformance test) is written once, and only the component and its property
tests differ per kind.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import re
import shutil
import string
import tempfile
from pathlib import Path

import attrs

from .._atomic import _cleanup_on_sigterm
from ..errors import FlockkitError, ValidationError
from ..kinds import KINDS

__all__ = ["write_plugin", "PLUGIN_NAME"]

# A plugin's name: what the registry accepts for a component (flockkit.registry), so that the
# entry point, the component and the package flockkit_<name> can all carry it.
PLUGIN_NAME = re.compile(r"[a-z][a-z0-9]*(?:[-_][a-z0-9]+)*")


def write_plugin(kind: str, name: str, directory=None) -> Path:
    """Write a distribution ``flockkit-<name>`` for a plugin registering a `kind` component
    `name` into `directory` (default ``./flockkit-<name>``), and return its path.

    The folder is built in a private temporary folder beside `directory` and renamed into place
    when complete, so an interrupted or failed write leaves nothing half-written.

    Raises ValidationError for an unknown `kind`, a `name` the registry would refuse, or one an
    installed plugin, component of that kind or module ``flockkit_<name>`` already uses;
    FileExistsError when `directory` exists and is not an empty folder.
    """
    if not isinstance(kind, str) or kind not in KINDS:
        raise ValidationError(f"kind must be one of {', '.join(KINDS)}; got {kind!r}")
    if not isinstance(name, str) or not PLUGIN_NAME.fullmatch(name):
        raise ValidationError(
            "name must be lower-case letters and digits, words joined by '-' or '_', starting with a letter "
            f"(like 'spread' or 'my-walk'); got {name!r}"
        )
    names = _names(kind, name)
    target = Path(f"flockkit-{name}" if directory is None else directory)
    _check_target(target)
    _check_free(kind, name, names["package"])
    files = _files(kind, names)
    target.parent.mkdir(parents=True, exist_ok=True)
    with _cleanup_on_sigterm():
        private = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
        try:
            tree = private / target.name
            for relative, text in files.items():
                path = tree / relative
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(text, encoding="utf-8")
            if target.is_dir():
                target.rmdir()  # empty, as checked; a folder filled meanwhile stops the write here
            os.replace(tree, target)
        except OSError as exc:
            if exc.errno is None:
                raise
            raise type(exc)(exc.errno, f"{target}: {exc.strerror}") from None
        finally:
            shutil.rmtree(private, ignore_errors=True)
    return target


def _names(kind: str, name: str) -> dict[str, str]:
    return {
        "name": name,
        "kind": kind,
        "hook": KINDS[kind].hook,
        "package": "flockkit_" + name.replace("-", "_"),
        "distribution": f"flockkit-{name}",
        "Class": "".join(word.capitalize() for word in re.split(r"[-_]", name)),
        "summary": _KIND_TEMPLATES[kind].summary,
    }


def _check_free(kind: str, name: str, package: str) -> None:
    """Refuse a name that would clash once installed: an entry point (plugin) of that name, a
    component of that kind, or an importable module flockkit_<name>."""
    plugins = {entry_point.name for entry_point in importlib.metadata.entry_points(group="flockkit")}
    if name in plugins:
        raise ValidationError(f"name {name!r} is taken: an installed flockkit plugin has that name; choose another")
    try:
        from ..registry import available

        taken = name in available(kind)
    except FlockkitError:  # a broken installed plugin is reported where it is used, not here
        taken = False
    if taken:
        raise ValidationError(f"name {name!r} is taken: an installed plugin registers the {kind} {name!r}")
    if importlib.util.find_spec(package) is not None:
        raise ValidationError(f"name {name!r} is taken: a module {package} is already importable")


def _check_target(target: Path) -> None:
    if target.is_dir():
        if any(target.iterdir()):
            raise FileExistsError(f"{target}: the folder exists and is not empty; choose another or empty it")
    elif target.exists() or target.is_symlink():
        raise FileExistsError(f"{target}: exists and is not a folder; choose another name")


def _files(kind: str, names: dict[str, str]) -> dict[str, str]:
    own = _KIND_TEMPLATES[kind]
    sources = {
        "pyproject.toml": _PYPROJECT,
        "README.md": _README.replace("$change", own.change.strip()),
        "$package/__init__.py": _INIT,
        "$package/$kind.py": own.component,
        "tests/test_conformance.py": _CONFORMANCE,
        "tests/test_properties.py": own.properties,
    }
    return {
        string.Template(path).substitute(names): string.Template(text.lstrip("\n")).substitute(names)
        for path, text in sources.items()
    }


@attrs.frozen
class _KindTemplate:
    """What differs per kind: a one-line summary, the component's module, its property tests, and
    the README's paragraph on what to change."""

    summary: str
    component: str
    properties: str
    change: str


# -- shared by every kind -----------------------------------------------------------------------

_PYPROJECT = """
[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "$distribution"
version = "0.1.0"
description = "$Class: a flockkit $kind that $summary"
readme = "README.md"
requires-python = ">=3.11"
dependencies = ["flockkit"]

[project.optional-dependencies]
test = ["pytest", "hypothesis"]

# The whole of the registration: flockkit finds the module through this entry point.
[project.entry-points.flockkit]
$name = "$package"

[tool.setuptools]
packages = ["$package"]

[tool.pytest.ini_options]
testpaths = ["tests"]

[tool.ruff]
line-length = 100
"""

_README = """
# $distribution

A flockkit plugin: the $kind `$name`, which $summary.

`$package/$kind.py` holds the class `$Class` (its docstring says exactly what it does), and
`$package/__init__.py` registers it with `@flockkit.hookimpl`; the entry point in
`pyproject.toml` is how flockkit finds it.

## Install and test

```bash
pip install -e ".[test]"
pytest
```

The first line installs the plugin with what its tests need (pytest, hypothesis). Then
`flockkit plugins --kind $kind` lists `$name`, `flockkit.get("$kind", "$name")` makes one,
and every flockkit function that takes a $kind takes the name `"$name"`.

`tests/test_conformance.py` runs flockkit's conformance kit: one test per check of the $kind
kind, the checks of optional operations it does not declare reported as skipped with the reason.
`flockkit check $kind $name` runs the same checks from the command line. `tests/test_properties.py`
holds property tests whose inputs hypothesis draws (`flockkit.testing.strategies`).

## What to change

$change

The contract of a $kind, and the optional operations it can declare in its `capabilities`
(`flockkit.Capabilities`), are on the $kind page of flockkit's documentation (`kinds/$kind/`). Keep the
conformance test as it is: when a check fails, its message ends with a "to fix" line. To rename
the plugin, change `NAME` in `$package/$kind.py`, the entry point and the package in
`pyproject.toml`, the package's folder and the tests' imports together.
"""

_INIT = '''
"""A flockkit plugin: the $kind `$name`.

flockkit finds this module through the entry point in pyproject.toml and calls its hook.
"""

import flockkit

from .$kind import NAME, $Class

__all__ = ["$Class"]


@flockkit.hookimpl
def $hook(registry):
    registry.add(
        NAME,
        $Class,
        description="$summary",
    )
'''

_CONFORMANCE = '''
"""flockkit's conformance kit on $Class: one test per check of the $kind kind."""

import flockkit
from flockkit.testing import parametrize_with_checks

from $package import $Class


@parametrize_with_checks([("$kind", $Class())])
def test_conformance(component, check):
    check(component)


def test_found_through_its_entry_point():
    assert isinstance(flockkit.get("$kind", "$name"), $Class)
'''

# -- per kind -----------------------------------------------------------------------------------

_BEHAVIOR = _KindTemplate(
    summary="keeps a flock together by cohesion, with drag and random accelerations",
    component='''
"""A behavior model: agents pulled towards the group's center, slowed by drag, pushed by noise.

At frame t >= 1 an agent arriving with velocity v_t = (x_t - x_{t-1}) / dt accelerates by

    a_t = cohesion (c_t - x_t) - drag v_t + sigma xi_t,    xi_t ~ N(0, I),

c_t the group's center, and moves to x_{t+1} = x_t + dt (v_t + dt a_t); frame 0 drifts with the
initial velocity. Given positions, xi_t follows from frames t - 1 .. t + 1, so log_plausibility
is the standard normal log density of the inferred xi (summed over agents), and a change at frame
f reaches frames f - 1 .. f + 1 only: the model declares ``plausibility_reach=1``. Nothing is
divided by a distance or a speed, so agents on one spot and a lone agent need no special case.
"""

import math

import attrs
import flockkit
import numpy as np
from flockkit import validate

NAME = "$name"  # the name it is registered under


def _positive(default):
    return validate.parameter(NAME, default=default, minimum=0, strict=True)


@attrs.frozen(kw_only=True)
class $Class:
    """Parameters: dt (seconds per frame), cohesion (pull towards the center, 1/s^2), drag
    (1/s), sigma (standard deviation of the random acceleration, length/s^2)."""

    dt: float = _positive(0.1)
    cohesion: float = _positive(1.0)
    drag: float = _positive(0.5)
    sigma: float = _positive(0.5)

    # frame t of log_plausibility reads frames t - 1 .. t + 1 only
    capabilities = flockkit.Capabilities(plausibility_reach=1)

    def forward(self, initial, steps, rng):
        positions = self._run(initial.positions, initial.velocities, steps, rng)
        return flockkit.Motion(positions=positions, dt=self.dt)

    def backward(self, final, steps, rng):
        # forward from the final state with its velocities reversed, then played backwards
        positions = self._run(final.positions, -final.velocities, steps, rng)
        return flockkit.Motion(positions=positions[::-1], dt=self.dt)

    def log_plausibility(self, motion, start=0, stop=None):
        start, stop = validate.window(motion, start, stop, owner=NAME)
        values = np.zeros(stop - start)
        first, last = max(start, 1), min(stop, motion.n_frames - 1)
        if first < last:  # frame 0 and the last frame have no inferable choice: they score 0
            x = motion.positions[first - 1 : last + 1]
            xi = self._noise(x[:-2], x[1:-1], x[2:], motion.dt)
            constant = 0.5 * xi[0].size * math.log(2 * math.pi)
            values[first - start : last - start] = -0.5 * np.sum(xi**2, axis=(1, 2)) - constant
        return values

    def _noise(self, before, now, after, dt):
        """xi at each frame of `now` (F, N, D), from the frames before and after it."""
        velocity = (now - before) / dt
        acceleration = (after - 2 * now + before) / dt**2
        pull = self.cohesion * (now.mean(axis=1, keepdims=True) - now)
        return (acceleration - pull + self.drag * velocity) / self.sigma

    def _run(self, x0, v0, steps, rng):
        steps = validate.integer(steps, f"{NAME}: steps", minimum=0)
        positions = np.empty((steps + 1, *x0.shape))
        positions[0] = x0
        velocity = np.array(v0, dtype=np.float64)
        for t in range(steps):
            if t > 0:
                pull = self.cohesion * (positions[t].mean(axis=0) - positions[t])
                noise = self.sigma * rng.standard_normal(x0.shape)
                velocity = velocity + self.dt * (pull - self.drag * velocity + noise)
            positions[t + 1] = positions[t] + self.dt * velocity
            velocity = (positions[t + 1] - positions[t]) / self.dt  # as log_plausibility infers it
        return positions
''',
    properties='''
"""Properties of $Class for any flock: hypothesis draws the states."""

import numpy as np
from flockkit.testing import strategies as fst
from hypothesis import given, settings
from hypothesis import strategies as st

from $package import $Class


@settings(max_examples=30, deadline=None)
@given(state=fst.states(max_agents=8), steps=st.integers(0, 10), seed=st.integers(0, 2**32 - 1))
def test_forward_starts_at_the_state_and_scores_finite(state, steps, seed):
    model = $Class()
    motion = model.forward(state, steps, np.random.default_rng(seed))
    assert motion.positions.shape == (steps + 1, state.n_agents, state.dims)
    assert np.array_equal(motion.positions[0], state.positions)
    assert np.all(np.isfinite(model.log_plausibility(motion)))
''',
    change="""
The model's step is `_run` and its inverse is `_noise`: change both together, so that
`log_plausibility` scores exactly the random choices `forward` makes (the kit checks that forward
motions score better than noisy ones, and that a window equals a slice). If frame t of
`log_plausibility` reads frames farther than t - 1 .. t + 1, change `plausibility_reach` in
`capabilities` (or remove it). A model that handles 2D only declares `dims=(2,)` there.
""",
)

_METRIC = _KindTemplate(
    summary="compares configurations after the best rigid motion and matching",
    component='''
"""A metric: the mean squared distance between two group configurations after the best rigid
motion and matching of agents that its search finds.

Positions are centered on their centroids (every agent is matched, so the best translation maps
centroid onto centroid). The search starts from the identity and from every rotation that lays
an anchor of `a` on an agent of `b`: the agent farthest from the centroid (in 3D with the agent
farthest from that axis, laid on each ordered pair of agents). Each start is scored by one
optimal matching (the Hungarian algorithm); the best `refine` starts then alternate matching and
the best rotation (Kabsch) while the distance falls. A rotated, translated and reordered copy is
found exactly whatever its symmetries (a square, a grid, agents on one spot or on a line), since
one start lays the anchor on its own copy. The search runs both ways (b onto a, and a onto b
inverted) and keeps the better, so the distance does not depend on the order of the arguments.
Velocities are not compared.

There are N starts in 2D and N (N - 1) in 3D, each a matching: meant for groups of tens of agents.
"""

import attrs
import flockkit
import numpy as np
from flockkit import validate
from flockkit.errors import ValidationError
from scipy.optimize import linear_sum_assignment

NAME = "$name"  # the name it is registered under


def _count(default):
    return validate.parameter(NAME, default=default, kind="integer", minimum=1)


@attrs.frozen(kw_only=True)
class $Class:
    """Parameters: refine (the best starts refined to convergence), max_iterations (per start)."""

    refine: int = _count(4)
    max_iterations: int = _count(30)

    def compare(self, a, b):
        if not isinstance(a, flockkit.Configuration) or not isinstance(b, flockkit.Configuration):
            raise ValidationError(f"{NAME}: compare needs two flockkit.Configuration")
        if a.positions.shape != b.positions.shape:
            raise ValidationError(
                f"{NAME}: a has {a.n_agents} agents in {a.dims}D and b {b.n_agents} in {b.dims}D; "
                "compare needs the same"
            )
        forth = self._search(a.positions, b.positions)
        back = self._search(b.positions, a.positions).inverse()
        return forth if forth.distance <= back.distance else back

    def _search(self, a, b):
        """The best Alignment of b onto a (positions (N, D)) from every start."""
        center_a, center_b = a.mean(axis=0), b.mean(axis=0)
        pa, pb = a - center_a, b - center_b
        tiny = 1e-9 * (1.0 + max(np.abs(a).max(), np.abs(b).max()))  # below it a length is 0
        starts = self._starts(pa, pb, tiny)
        scores = [self._match(pa, pb, rotation)[1] for rotation in starts]
        best = None
        for index in np.argsort(scores, kind="stable")[: self.refine]:
            found = self._descend(pa, pb, starts[index])
            if best is None or found[0] < best[0]:
                best = found
        distance, assignment, rotation = best
        translation = center_a - rotation @ center_b
        return flockkit.Alignment(
            distance=distance, assignment=assignment, rotation=rotation, translation=translation
        )

    def _starts(self, pa, pb, tiny):
        """Rotations laying the anchors of pa on agents of pb, and the identity."""
        dims = pa.shape[1]
        lengths = np.linalg.norm(pa, axis=1)
        k = int(np.argmax(lengths))
        if lengths[k] <= tiny:  # every agent on one spot: any rotation will do
            return [np.eye(dims)]
        anchors = pa[[k]]
        if dims == 3:
            axis = pa[k] / lengths[k]
            across = pa - np.outer(pa @ axis, axis)
            far = int(np.argmax(np.linalg.norm(across, axis=1)))
            if np.linalg.norm(across[far]) > tiny:  # not all on one line: a second anchor
                anchors = pa[[k, far]]
        n = len(pb)
        if len(anchors) == 1:
            sources = pb[:, None, :]
        else:
            first, second = np.nonzero(~np.eye(n, dtype=bool))
            sources = np.stack([pb[first], pb[second]], axis=1)
        targets = np.broadcast_to(anchors, sources.shape)
        return [np.eye(dims), *flockkit.rigid.kabsch(targets, sources)]

    def _match(self, pa, pb, rotation):
        """The optimal matching of pb (turned by `rotation`) to pa, and its mean squared cost."""
        moved = pb @ rotation.T
        cost = np.sum((pa[:, None, :] - moved[None, :, :]) ** 2, axis=-1)
        rows, columns = linear_sum_assignment(cost)
        return columns, float(cost[rows, columns].mean())

    def _descend(self, pa, pb, rotation):
        """Alternate matching and Kabsch from `rotation` while the distance falls."""
        assignment, distance = self._match(pa, pb, rotation)
        for _ in range(self.max_iterations):
            turned = flockkit.rigid.kabsch(pa, pb[assignment])
            matched, found = self._match(pa, pb, turned)
            if found >= distance:
                break
            rotation, assignment, distance = turned, matched, found
        return distance, assignment, rotation
''',
    properties='''
"""Properties of $Class for any pair of configurations: hypothesis draws them."""

import numpy as np
from flockkit.testing import strategies as fst
from hypothesis import given, settings
from hypothesis import strategies as st

from $package import $Class


def _scale(*configurations):
    return 1.0 + sum(float(np.mean(np.sum(c.positions**2, axis=1))) for c in configurations)


@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_symmetric_zero_on_itself_and_true_to_its_alignment(data):
    a = data.draw(fst.configurations(max_agents=7, max_coordinate=10.0))
    same_size = fst.configurations(
        min_agents=a.n_agents, max_agents=a.n_agents, dims=a.dims, max_coordinate=10.0
    )
    b = data.draw(same_size)
    metric = $Class()
    found = metric.compare(a, b)
    assert found.distance == metric.compare(b, a).distance
    assert abs(found.distance - found.residual(a, b)) <= 1e-9 * _scale(a, b)
    assert metric.compare(a, a).distance <= 1e-9 * _scale(a)
''',
    change="""
The distance is `_match`'s mean squared distance after alignment. To compare velocities too, add
their weighted squared differences to the matching cost in `_match` (and keep the distance a mean
of squared residuals: the kit checks the relaxed triangle inequality that builders rely on). For
large groups, fewer starts (in `_starts`) keep it fast; declaring `lower_bound`, `pairs_within`
or `pairwise` in `capabilities` lets graph builders prune and batch.
""",
)

_BUILDER = _KindTemplate(
    summary="joins the most similar frames of a recording into a motion graph",
    component='''
"""A graph builder: transitions join the most similar configurations of a recording.

Candidate frames are taken every `interval` seconds, up to `blend` seconds before the end (a
transition's blend still plays the motion it leaves). The metric compares every pair of
candidates at least `min_gap` seconds apart (all at once where it declares ``pairwise``), and the
pairs in the lowest `quantile` of those distances become transitions, each both ways, blended over
`blend` seconds. ``flockkit.MotionGraph.assemble`` puts nodes at the transition frames, joins
them by clips and keeps the largest strongly connected part, so a walk never reaches a dead end.
Taking a share of the pairs rather than a fixed threshold works whatever the units of the
recording.
"""

import attrs
import flockkit
import numpy as np
from flockkit import validate
from flockkit.errors import ValidationError

NAME = "$name"  # the name it is registered under


def _seconds(default):
    return validate.parameter(NAME, default=default, minimum=0, strict=True)


@attrs.frozen(kw_only=True)
class $Class:
    """Parameters: interval, min_gap and blend (seconds), quantile (the share of the candidate
    pairs that become transitions, in (0, 1])."""

    interval: float = _seconds(0.3)
    min_gap: float = _seconds(1.0)
    blend: float = _seconds(0.5)
    quantile: float = validate.parameter(NAME, default=0.05, minimum=0, strict=True, maximum=1)

    def build(self, motion, metric, rng):
        if not isinstance(motion, flockkit.Motion):
            raise ValidationError(f"{NAME}: motion must be a flockkit.Motion")
        blend = round(self.blend / motion.dt)
        stride = max(1, round(self.interval / motion.dt))
        # a transition leaving frame s blends in frames s .. s + blend of the motion it leaves
        frames = np.arange(0, motion.n_frames - blend - 1, stride)
        first, second = np.triu_indices(len(frames), 1)
        apart = frames[second] - frames[first] >= self.min_gap / motion.dt
        pairs = np.column_stack([first[apart], second[apart]])
        if not len(pairs):
            raise ValidationError(
                f"{NAME}: a recording of {motion.duration:g} s has no candidate frames "
                f"{self.min_gap:g} s apart and {self.blend:g} s before its end; give a longer one, "
                "or a smaller min_gap or blend"
            )
        configs = [motion.configuration(int(frame)) for frame in frames]
        if flockkit.capabilities(metric).pairwise:  # all distances in one call
            distances = np.asarray(metric.pairwise(configs, pairs), dtype=np.float64)
        else:
            distances = np.array(
                [metric.compare(configs[i], configs[j]).distance for i, j in pairs]
            )
        transitions = []
        for i, j in pairs[distances <= np.quantile(distances, self.quantile)]:
            start, end = int(frames[i]), int(frames[j])
            transitions.append((start, end, metric.compare(configs[i], configs[j]), blend))
            transitions.append((end, start, metric.compare(configs[j], configs[i]), blend))
        provenance = {"builder": NAME}
        return flockkit.MotionGraph.assemble(
            motion, transitions, params=attrs.asdict(self), provenance=provenance
        )
''',
    properties='''
"""Properties of $Class for any recording: hypothesis draws the motions."""

import flockkit
import numpy as np
from flockkit.testing import strategies as fst
from hypothesis import given, settings

from $package import $Class

# the partner the graph is built with: flockkit's built-in metric, by its registered name
METRIC = flockkit.get("metric", "icp-hungarian")


@settings(max_examples=10, deadline=None)
@given(motion=fst.motions(min_frames=20, max_frames=50, max_agents=5, dt=0.1, max_coordinate=10.0))
def test_builds_a_graph_whose_alignments_hold_and_that_plays(motion):
    graph = $Class().build(motion, METRIC, np.random.default_rng(0))
    assert graph.motion == motion
    scale = 1.0 + float(np.max(np.abs(motion.positions))) ** 2
    for transition in graph.transitions:
        a, b = motion.configuration(transition.start), motion.configuration(transition.end)
        assert transition.alignment.residual(a, b) <= transition.alignment.distance + 1e-9 * scale
    played = flockkit.synthesize(graph, flockkit.walk(graph, duration=10.0, seed=0))
    assert played.duration >= 10.0 - 1e-9
''',
    change="""
Which pairs become transitions is decided in `build`: the share of the lowest distances
(`quantile`), or put your own rule there (local minima of the distance matrix, as Kovar et al.; a
threshold in the recording's units). `flockkit.MotionGraph.assemble` does the rest. A builder that
reports progress declares `progress=True` in `capabilities` and takes `progress=`.
""",
)

_WALK = _KindTemplate(
    summary="walks a motion graph taking the edges it has used least",
    component='''
"""A walk strategy: a random walk that spreads over its graph.

At each node it takes, among the edges it may take (``graph.allowed_edges``: a transition only
once the last one's blend has played), one it has taken least so far, choosing among ties at
random; so a long walk plays every part of the graph instead of circling one loop. It starts at
`start`, or at a random node.
"""

import math

import attrs
import flockkit
from flockkit import validate
from flockkit.errors import ValidationError

NAME = "$name"  # the name it is registered under


@attrs.frozen(kw_only=True)
class $Class:
    """Parameters: start (the node to start at; None: a random one)."""

    start: int | None = validate.parameter(
        NAME, default=None, kind="integer", minimum=0, optional=True
    )

    def walk(self, graph, rng, duration):
        if not isinstance(graph, flockkit.MotionGraph):
            raise ValidationError(f"{NAME}: graph must be a flockkit.MotionGraph")
        duration = validate.number(duration, f"{NAME}: duration", minimum=0, strict=True)
        frames = duration / graph.motion.dt
        size = frames * graph.motion.n_agents * graph.motion.dims  # of the motion it plays
        validate.allocation(size, f"{NAME}: a walk of {duration:g} s")
        if not graph.clips:
            raise ValidationError(f"{NAME}: the graph has no clip, so a walk would play nothing")
        node = int(rng.integers(len(graph.nodes))) if self.start is None else self.start
        if node >= len(graph.nodes):
            raise ValidationError(f"{NAME}: start {node} is not a node of the graph")
        first, edges, used = node, [], {}
        needed, played = math.ceil(frames - 1e-9), 0  # frames to play after the first
        since = math.inf  # frames since the last transition: none yet, so any may be taken
        while played < needed:
            options = graph.allowed_edges(node, since)
            if not options:
                raise ValidationError(f"{NAME}: no edge leaves node {node}")
            fewest = min(used.get(edge, 0) for edge in options)
            ties = [edge for edge in options if used.get(edge, 0) == fewest]
            edge = ties[int(rng.integers(len(ties)))]
            used[edge] = fewest + 1
            edges.append(edge)
            if edge[0] == "clip":
                length = graph.clips[edge[1]].n_frames - 1
                played, since = played + length, since + length
            else:
                since = 0
            node = graph.edge_target(edge)
        return flockkit.Walk(start=first, edges=edges)
''',
    properties='''
"""Properties of $Class on the conformance kit's graph: hypothesis draws durations and seeds."""

import flockkit
import numpy as np
import pytest
from flockkit.errors import ValidationError
from flockkit.testing import inputs
from flockkit.testing import strategies as fst
from hypothesis import given, settings
from hypothesis import strategies as st

from $package import $Class

GRAPH = inputs.graph()  # a group circling the origin, made without any plugin


@settings(max_examples=20, deadline=None)
@given(duration=st.floats(0.05, 60.0), seed=st.integers(0, 2**32 - 1))
def test_a_walk_plays_at_least_its_duration(duration, seed):
    walk = $Class().walk(GRAPH, np.random.default_rng(seed), duration)
    assert flockkit.synthesize(GRAPH, walk).duration >= duration - 1e-9


@settings(max_examples=30, deadline=None)
@given(duration=fst.anything().filter(lambda value: not isinstance(value, int | float)))
def test_a_duration_that_is_not_a_number_is_refused(duration):
    with pytest.raises(ValidationError):
        $Class().walk(GRAPH, np.random.default_rng(0), duration)
''',
    change="""
The choice is the `ties` line in `walk`: score the allowed edges by what your walk wants (where the
group ends up, the arrows it plays, a target to follow) and take the best. Keep to
`graph.allowed_edges`, and raise a flockkit error rather than loop when a goal cannot be met. A
walk that follows targets declares `targets=True` in `capabilities` and takes `target`,
`features` and `avoid`.
""",
)

_PROPOSAL = _KindTemplate(
    summary="nudges one free agent's path with a smooth bump",
    component='''
"""A proposal move: nudges one agent's path.

Over `min_frames` to `max_frames` consecutive frames it adds a bump shaped sin^2 (so that it
fades in and out) in a random direction, its size drawn from a Gaussian of `size` length units
times the sampler's ``context.scale``. The agent is drawn from those no point constraint pins over
those frames, so every constraint stays exactly met, and the proposal reports those frames and
that agent, which is all it changes.
"""

import attrs
import flockkit
import numpy as np
from flockkit import validate
from flockkit.errors import ValidationError

NAME = "$name"  # the name it is registered under


def _frames(default):
    return validate.parameter(NAME, default=default, kind="integer", minimum=1)


@attrs.frozen(kw_only=True)
class $Class:
    """Parameters: size (length units), min_frames and max_frames (the bump's span)."""

    size: float = validate.parameter(NAME, default=0.1, minimum=0, strict=True)
    min_frames: int = _frames(3)
    max_frames: int = _frames(10)

    def __attrs_post_init__(self):
        if self.min_frames > self.max_frames:
            raise ValidationError(
                f"{NAME}: min_frames {self.min_frames} exceeds max_frames {self.max_frames}"
            )

    def propose(self, current, context, rng):
        length = min(int(rng.integers(self.min_frames, self.max_frames + 1)), current.n_frames)
        start = int(rng.integers(0, current.n_frames - length + 1))
        stop = start + length
        free = context.free_agents(start, stop)
        if not len(free):
            return None
        agent = int(free[rng.integers(len(free))])
        shape = np.sin(np.pi * np.arange(1, length + 1) / (length + 1)) ** 2
        offset = rng.normal(0.0, self.size * context.scale, current.dims)
        positions = np.array(current.positions)
        positions[start:stop, agent] += shape[:, None] * offset
        motion = flockkit.Motion(positions=positions, dt=current.dt, channels=current.channels)
        return flockkit.Proposal(motion=motion, start=start, stop=stop, agents=(agent,))
''',
    properties='''
"""Properties of $Class for any motion and any pinned agents: hypothesis draws them."""

import flockkit
import numpy as np
from flockkit.constrained import ProposalContext
from flockkit.testing import strategies as fst
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from $package import $Class


@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_changes_only_what_it_reports_and_never_a_pinned_agent(data):
    motion = data.draw(
        fst.motions(min_frames=2, max_frames=30, max_agents=6, dt=0.1, max_coordinate=10.0)
    )
    pinned = data.draw(hnp.arrays(bool, (motion.n_frames, motion.n_agents)))
    problem = flockkit.Problem(
        n_agents=motion.n_agents, dims=motion.dims, duration=(motion.n_frames - 1) * motion.dt
    )
    context = ProposalContext(
        problem=problem, behavior=None, windows=(), scores=np.zeros(motion.n_frames), pinned=pinned
    )
    before = motion.positions.copy()
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    proposal = $Class().propose(motion, context, rng)
    assert np.array_equal(motion.positions, before)
    if proposal is not None:
        frames, agents = np.nonzero(np.any(proposal.motion.positions != before, axis=2))
        assert np.all((proposal.start <= frames) & (frames < proposal.stop))
        assert np.all(np.isin(agents, proposal.agents))
        assert not np.any(pinned[frames, agents])
''',
    change="""
The change is made in `propose`: keep to agents and frames that `context.free_agents(start, stop)`
allows (or move a pinned agent only where its constraint is not), and report every frame and
agent you change, since the sampler re-scores only those (widened by the behavior's
`plausibility_reach`). `context` also holds the problem, the behavior and the current per-frame
scores, for moves that aim where the motion is least plausible.
""",
)

_OBJECTIVE = _KindTemplate(
    summary="penalizes agents that come closer than a personal-space radius",
    component='''
"""An objective term that keeps agents out of each other's personal space.

At each frame it is -weight times the sum, over the pairs of agents closer than `radius`, of
the squared overlap (radius - distance)^2: zero where everybody keeps their distance, and growing
smoothly as agents crowd in, agents on one spot included. A frame's term reads that frame alone,
so the sampler can re-score only the frames a proposal changed.
"""

import attrs
import flockkit
import numpy as np
from flockkit import validate
from flockkit.errors import ValidationError
from scipy.spatial import cKDTree

NAME = "$name"  # the name it is registered under


def _positive(default):
    return validate.parameter(NAME, default=default, minimum=0, strict=True)


@attrs.frozen(kw_only=True)
class $Class:
    """Parameters: radius (length units), weight (per squared length unit of overlap)."""

    radius: float = _positive(0.5)
    weight: float = _positive(100.0)

    def log_terms(self, motion, problem, start=0, stop=None):
        if not isinstance(motion, flockkit.Motion) or not isinstance(problem, flockkit.Problem):
            raise ValidationError(
                f"{NAME}: log_terms needs a flockkit.Motion and a flockkit.Problem"
            )
        if (motion.n_agents, motion.dims) != (problem.n_agents, problem.dims):
            raise ValidationError(
                f"{NAME}: the motion has {motion.n_agents} agents in {motion.dims}D, "
                f"the problem {problem.n_agents} in {problem.dims}D"
            )
        start, stop = validate.window(motion, start, stop, owner=NAME)
        terms = np.zeros(stop - start)
        for frame in range(start, stop):
            x = motion.positions[frame]
            pairs = cKDTree(x).query_pairs(self.radius, output_type="ndarray")
            overlap = self.radius - np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
            terms[frame - start] = -self.weight * float(overlap @ overlap)
        return terms
''',
    properties='''
"""Properties of $Class for any motion: hypothesis draws them."""

import flockkit
import numpy as np
from flockkit.testing import strategies as fst
from hypothesis import given, settings
from hypothesis import strategies as st

from $package import $Class


@settings(max_examples=30, deadline=None)
@given(motion=fst.motions(max_frames=12, max_agents=8, dt=0.1, max_coordinate=3.0), data=st.data())
def test_a_finite_penalty_per_frame_and_windows_are_slices(motion, data):
    duration = max(motion.n_frames - 1, 1) * motion.dt
    problem = flockkit.Problem(n_agents=motion.n_agents, dims=motion.dims, duration=duration)
    objective = $Class()
    full = objective.log_terms(motion, problem)
    assert full.shape == (motion.n_frames,)
    assert np.all(np.isfinite(full)) and np.all(full <= 0)
    start = data.draw(st.integers(0, motion.n_frames))
    stop = data.draw(st.integers(start, motion.n_frames))
    assert np.array_equal(objective.log_terms(motion, problem, start, stop), full[start:stop])
''',
    change="""
The term is computed per frame in `log_terms`. Read what it needs from the `problem` (its
constraints, `visibility`, weights) so that one Problem describes the whole objective; return
-inf for an impossible frame, never NaN, and keep a frame's term a function of that frame alone.
""",
)

_SEGMENTER = _KindTemplate(
    summary="groups points whose speed rises and falls together",
    component='''
"""A segmenter: splits points by when they move.

A point's speed at each frame, divided by its own largest speed, is its activity profile;
points whose profiles differ by at most `tolerance` at every frame share a part (and so, in a
chain, do points linked through such neighbors). Points whose largest speed is under `still`
times the fastest point's never move: they form one part of their own. Parts that move at
different times are told apart; the points of a rigid body that turns as it travels speed up and
slow down differently, so parts that together move rigidly are merged
(flockkit.scene.merge_rigid_parts). The partition depends neither on the order of the points nor
on the generator.
"""

import attrs
import flockkit
import numpy as np
from flockkit import validate
from flockkit.errors import ValidationError
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

NAME = "$name"  # the name it is registered under


@attrs.frozen(kw_only=True)
class $Class:
    """Parameters: tolerance (of the activity profiles, in (0, 1]), still (the share of the
    fastest point's speed under which a point counts as never moving)."""

    tolerance: float = validate.parameter(NAME, default=0.2, minimum=0, strict=True, maximum=1)
    still: float = validate.parameter(NAME, default=1e-6, minimum=0, strict=True, maximum=1)

    def segment(self, motion, rng):
        if not isinstance(motion, flockkit.Motion):
            raise ValidationError(f"{NAME}: motion must be a flockkit.Motion")
        speeds = np.linalg.norm(motion.velocities(), axis=2).T  # (N, T)
        top = speeds.max(axis=1)
        moving = top > self.still * top.max()  # none if nothing moves
        profiles = speeds[moving] / top[moving, None]
        labels = np.zeros(motion.n_agents, dtype=np.int64)
        parts = 0
        if len(profiles):
            pairs = cKDTree(profiles).query_pairs(self.tolerance, p=np.inf, output_type="ndarray")
            links = coo_matrix(
                (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(profiles),) * 2
            )
            parts, found = connected_components(links, directed=False)
            labels[moving] = found
        labels[~moving] = parts
        labels = flockkit.scene.merge_rigid_parts(motion, labels)
        return flockkit.Segmentation(labels=labels, n_parts=int(labels.max()) + 1)
''',
    properties='''
"""Properties of $Class for any motion: hypothesis draws them."""

import flockkit
import numpy as np
from flockkit.scene import same_partition
from flockkit.testing import strategies as fst
from hypothesis import given, settings
from hypothesis import strategies as st

from $package import $Class


@settings(max_examples=30, deadline=None)
@given(
    motion=fst.motions(max_frames=15, max_agents=8, max_coordinate=10.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_every_point_gets_a_part_whatever_their_order(motion, seed):
    segmenter = $Class()
    labels = segmenter.segment(motion, np.random.default_rng(0)).labels
    assert labels.shape == (motion.n_agents,)
    order = np.random.default_rng(seed).permutation(motion.n_agents)
    shuffled = flockkit.Motion(positions=motion.positions[:, order], dt=motion.dt)
    assert same_partition(
        labels[order], segmenter.segment(shuffled, np.random.default_rng(0)).labels
    )
''',
    change="""
The grouping is in `segment`: put your own features in place of the activity profiles (the
velocity-energy matrix and ICA of paper 002, trajectories' shapes, distances on a mesh). Keep
still points apart from moving ones, points that move alike together, and the partition
independent of the order of the points: the kit checks all three.
""",
)

_CONTROLLER = _KindTemplate(
    summary="sways every joint of a skeleton about its up axis, with no clip",
    component='''
"""A controller that needs no clip: every joint sways.

On top of its rest rotation every joint of `skeleton` turns about its local z (up) axis by
amplitude sin(2 pi t / period) degrees, so a chain of joints (a stalk, a tail, an antenna) bends
back and forth as one; an event named "sway" marks the start of each cycle (t = 0, period,
2 period, ...). The default skeleton is a three-joint stalk standing on the z axis.
"""

import math

import attrs
import flockkit
import numpy as np
from flockkit import validate
from flockkit.crowd import stream_times
from flockkit.errors import ValidationError

NAME = "$name"  # the name it is registered under


def _stalk():
    rest = flockkit.Pose(
        rotations=np.tile([0.0, 0.0, 0.0, 1.0], (3, 1)),
        translations=[[0, 0, 0], [0, 0, 0.5], [0, 0, 0.5]],
    )
    return flockkit.Skeleton(names=["root", "middle", "tip"], parents=[-1, 0, 1], rest=rest)


def _skeleton(value):
    if not isinstance(value, flockkit.Skeleton):
        raise ValidationError(
            f"{NAME} parameter skeleton must be a flockkit.Skeleton; got {type(value).__name__}"
        )
    return value


@attrs.frozen(kw_only=True)
class $Class:
    """Parameters: skeleton, amplitude (degrees each way), period (seconds)."""

    skeleton: flockkit.Skeleton = attrs.field(factory=_stalk, converter=_skeleton)
    amplitude: float = validate.parameter(NAME, default=10.0, minimum=0)
    period: float = validate.parameter(NAME, default=2.0, minimum=0, strict=True)

    capabilities = flockkit.Capabilities(dims=(3,))  # skeletons are 3D

    def pose(self, times):
        t = self._times(times)
        angle = math.radians(self.amplitude) * np.sin(2 * math.pi * t / self.period)
        sway = np.zeros((len(t), 1, 4))
        sway[..., 2], sway[..., 3] = np.sin(angle / 2)[:, None], np.cos(angle / 2)[:, None]
        rest = self.skeleton.rest
        rotations = flockkit.rigid.quaternion_product(
            rest.rotations, sway
        )  # the sway after the rest turn
        translations = np.broadcast_to(rest.translations, (len(t), *rest.translations.shape))
        return flockkit.Pose(rotations=rotations, translations=translations)

    def events(self, start, stop):
        start = validate.number(start, f"{NAME}: events start", minimum=0)
        stop = validate.number(stop, f"{NAME}: events stop", minimum=0)
        first = max(0, math.floor(start / self.period) - 1)
        times = (k * self.period for k in range(first, math.ceil(stop / self.period) + 1))
        return [flockkit.Event(time=t, name="sway") for t in times if start <= t < stop]

    def _times(self, times):
        """`times` as a 1D array of seconds >= 0, anything else a ValidationError."""
        try:
            kind = np.asarray(times).dtype.kind
        except (TypeError, ValueError, OverflowError):
            kind = None
        if kind not in ("i", "u", "f"):
            raise ValidationError(
                f"{NAME}.pose needs times in seconds (real numbers); got {type(times).__name__}"
            )
        return stream_times(times, owner=NAME)
''',
    properties='''
"""Properties of $Class at any times: hypothesis draws them."""

import flockkit
import numpy as np
from flockkit.errors import ValidationError
from flockkit.testing import strategies as fst
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from $package import $Class

TIMES = hnp.arrays(np.float64, st.integers(1, 12), elements=st.floats(0.0, 1e4))


@settings(max_examples=30, deadline=None)
@given(times=TIMES)
def test_the_pose_at_a_time_is_the_same_alone_and_in_a_batch(times):
    controller = $Class()
    batch = controller.pose(times)
    for k in range(len(times)):
        alone = controller.pose(times[k : k + 1])
        assert np.allclose(alone.rotations[0], batch.rotations[k], atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(times=fst.anything())
def test_any_times_give_poses_or_are_refused(times):
    controller = $Class()
    try:
        pose = controller.pose(times)
    except ValidationError:
        return
    assert isinstance(pose, flockkit.Pose) and pose.n_joints == controller.skeleton.n_joints
''',
    change="""
The pose is made in `pose`: play clips (`flockkit.SkeletalClip.sample`), blend children, or drive
joints procedurally as here; keep it a function of time alone, and give the events of
`[start, stop)` in `events` so that consecutive windows split them without loss or repeat. A
controller that plays one clip at a rate declares `clip_player=True` in `capabilities` and takes
`clip` and `rate`.
""",
)

_KIND_TEMPLATES = {
    "behavior": _BEHAVIOR,
    "metric": _METRIC,
    "builder": _BUILDER,
    "walk": _WALK,
    "proposal": _PROPOSAL,
    "objective": _OBJECTIVE,
    "segmenter": _SEGMENTER,
    "controller": _CONTROLLER,
}
