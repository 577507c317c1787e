"""flockkit's pytest plugin, loaded wherever flockkit is installed (a ``pytest11`` entry point).

Fixtures:

- ``flockkit_register``: ``flockkit_register(kind, name, factory)`` registers a component for one
  test; the registry is as before once the test ends.
- the kit's inputs: ``flockkit_recording`` (a 2D group motion with known recurrences),
  ``flockkit_graph`` (a motion graph over it), ``flockkit_parts`` (a motion of three rigid parts
  and the part of each point), ``flockkit_walker`` (a looping skeletal clip) and
  ``flockkit_degenerate_configurations`` (tied and symmetric configurations, 2D and 3D).

Option ``--flockkit-kit`` adds one test per check of the conformance kit for every installed
component (each made with its default parameters; a clip player plays the kit's walker clip),
with ids ``kit:<kind>:<name>-<check>``; ``--flockkit-kit=KIND[,KIND]`` limits it to those kinds,
and ``--flockkit-kit-from=DIST[,DIST]`` (alone or with it) to the components those installed distributions register
(names as pip lists them), so a plugin's own test run checks its components and nobody else's.
A check that does not apply to what the component declares is reported skipped, with the reason.
"""

from __future__ import annotations

import pytest


def pytest_addoption(parser):
    group = parser.getgroup("flockkit")
    group.addoption(
        "--flockkit-kit",
        nargs="?",
        const="all",
        default=None,
        metavar="KIND[,KIND]",
        help="run flockkit's conformance kit on every installed component (or those of the kinds given)",
    )
    group.addoption(
        "--flockkit-kit-from",
        default=None,
        metavar="DIST[,DIST]",
        help="run flockkit's conformance kit on the components these installed distributions register",
    )


@pytest.fixture
def flockkit_register():
    """``register(kind, name, factory, description="")``: `factory` is ``flockkit.get(kind,
    name)``'s for this test only."""
    import contextlib

    from ..kinds import KINDS
    from ..registry import registered

    with contextlib.ExitStack() as stack:

        def register(kind: str, name: str, factory, description: str = ""):
            if kind not in KINDS:
                from ..errors import ValidationError

                raise ValidationError(f"flockkit_register: unknown kind {kind!r}; the kinds are {', '.join(KINDS)}")
            stack.enter_context(registered(_one_component(kind, name, factory, description), f"test-{kind}-{name}"))
            return factory

        yield register


def _one_component(kind, name, factory, description):
    """A plugin object registering `factory` as `kind` `name`."""
    from ..hookspecs import hookimpl
    from ..kinds import KINDS

    def add(registry):
        registry.add(name, factory, description=description)

    return type(f"Test{kind.title()}Plugin", (), {KINDS[kind].hook: staticmethod(hookimpl(add))})


@pytest.fixture
def flockkit_recording():
    """``flockkit.testing.inputs.recording()``: six agents circling, a configuration recurring
    (turned) every 2.3 s."""
    from . import inputs

    return inputs.recording()


@pytest.fixture
def flockkit_graph():
    """``flockkit.testing.inputs.graph()``: a motion graph over the recording, made without any
    metric or builder."""
    from . import inputs

    return inputs.graph()


@pytest.fixture
def flockkit_parts():
    """``flockkit.testing.inputs.parts()``: (a motion of 44 points in three rigid parts, the part
    of each point)."""
    from . import inputs

    return inputs.parts()


@pytest.fixture
def flockkit_walker():
    """``flockkit.testing.inputs.walker()``: a looping skeletal clip of eleven joints."""
    from . import inputs

    return inputs.walker()


@pytest.fixture(params=[2, 3], ids=["2d", "3d"])
def flockkit_degenerate_configurations(request):
    """``flockkit.testing.inputs.degenerate_configurations(dims)``, in 2D and in 3D: (label,
    Configuration) pairs of squares, grids, coincident, lone and collinear agents."""
    from . import inputs

    return inputs.degenerate_configurations(request.param)


def _made(kind: str, name: str):
    """The installed component `name` with its default parameters; a clip player (a controller
    declaring ``clip_player``) plays the kit's walker clip."""
    from ..registry import capabilities_of, get
    from . import inputs

    if kind == "controller" and capabilities_of(kind, name).clip_player:
        return get(kind, name, clip=inputs.walker())
    return get(kind, name)


class KitItem(pytest.Item):
    """One check of the kit on one installed component."""

    def __init__(self, *, kind, component_name, check, skip, **kwargs):
        super().__init__(**kwargs)
        self.kind, self.component_name, self.check, self.skip = kind, component_name, check, skip

    def runtest(self):
        if self.skip:
            pytest.skip(self.skip)
        from . import _run

        _run(self.check, self.kind, self.component_name, _made(self.kind, self.component_name))

    def repr_failure(self, excinfo):
        if isinstance(excinfo.value, AssertionError):
            return str(excinfo.value)
        return super().repr_failure(excinfo)

    def reportinfo(self):
        return self.path, None, f"kit:{self.kind}:{self.component_name}-{self.check.__name__}"


def pytest_collection_modifyitems(session, config, items):
    wanted, sources = config.getoption("flockkit_kit"), config.getoption("flockkit_kit_from")
    if wanted is None and sources is None:
        return
    from ..errors import ValidationError
    from ..kinds import KINDS
    from ..registry import describe
    from . import _plan, checks_for

    kinds = list(KINDS) if wanted in (None, "all") else _names(wanted)
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        raise pytest.UsageError(f"--flockkit-kit: unknown kind {unknown[0]!r}; the kinds are {', '.join(KINDS)}")
    components = [(kind, found) for kind in kinds for found in describe(kind)]
    if sources is not None:
        wanted_from = {_canonical(d) for d in _names(sources)}
        installed = {_canonical(found.distribution) for _, found in components if found.distribution}
        missing = sorted(wanted_from - installed)
        if missing:
            raise pytest.UsageError(
                f"--flockkit-kit-from: no installed distribution {missing[0]!r} registers a flockkit component "
                f"of the kinds asked for; those that do: {', '.join(sorted(installed)) or 'none'}"
            )
        components = [(k, f) for k, f in components if f.distribution and _canonical(f.distribution) in wanted_from]
    for kind, found in components:
        try:
            plan = _plan(kind, _made(kind, found.name))
        except ValidationError as exc:  # parameters without defaults: a test must configure it
            reason = (
                f"{kind} {found.name!r} cannot be made with its default parameters ({exc}); check it "
                "from a test: flockkit.testing.parametrize_with_checks([(kind, configured_component)])"
            )
            plan = [(check, reason) for check in checks_for(kind)]
        for check, skip in plan:
            items.append(
                KitItem.from_parent(
                    session,
                    name=f"kit:{kind}:{found.name}-{check.__name__}",
                    kind=kind,
                    component_name=found.name,
                    check=check,
                    skip=skip,
                )
            )


def _names(option: str) -> list[str]:
    return [n.strip() for n in option.split(",") if n.strip()]


def _canonical(distribution: str) -> str:
    """A distribution name as packaging compares them: case, '-', '_' and '.' do not matter."""
    import re

    return re.sub(r"[-_.]+", "-", distribution).lower()
