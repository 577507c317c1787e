"""flockkit.testing: the conformance kit for plugins, modelled on scikit-learn's ``check_estimator``.

Run every check of a kind on a component::

    import flockkit
    from flockkit.testing import check_plugin

    check_plugin("behavior", flockkit.get("behavior", "boids"))

or one pytest test per check::

    from flockkit.testing import parametrize_with_checks

    @parametrize_with_checks([("behavior", MyModel())])
    def test_conformance(component, check):
        check(component)

Hypothesis strategies for flockkit values are in ``flockkit.testing.strategies``.
"""

from __future__ import annotations

import functools

from ..interfaces import PROTOCOLS
from ..registry import interface_problems
from . import behavior, builder, metric, objective, proposal, strategies, walk

__all__ = ["check_plugin", "parametrize_with_checks", "checks_for", "check_interface", "strategies"]


def check_interface(name, component, *, kind):
    """The component has every method of its kind's protocol, with compatible signatures."""
    problems = interface_problems(component, kind)
    assert not problems, f"{name} does not honour the {PROTOCOLS[kind].__name__} interface:\n" + "\n".join(
        f"  - {p}" for p in problems
    )


_KIND_CHECKS = {
    "behavior": behavior.CHECKS,
    "metric": metric.CHECKS,
    "builder": builder.CHECKS,
    "walk": walk.CHECKS,
    "objective": objective.CHECKS,
    "proposal": proposal.CHECKS,
}


def checks_for(kind: str) -> tuple:
    """The checks of `kind`, each a callable ``check(name, component)``, the interface check first."""
    if kind not in PROTOCOLS:
        raise ValueError(f"unknown plugin kind {kind!r}; the kinds are {', '.join(PROTOCOLS)}")
    interface = functools.partial(check_interface, kind=kind)
    functools.update_wrapper(interface, check_interface)
    return (interface, *_KIND_CHECKS.get(kind, ()))


def _name_of(component) -> str:
    return getattr(component, "__name__", None) or type(component).__name__


def check_plugin(kind: str, component, *, name: str | None = None, progress: bool = False) -> None:
    """Run every check of `kind` on `component` (a configured instance).

    Raises AssertionError naming the first failed check and the plugin; an unexpected exception
    inside a check counts as that check failing. `progress` shows a bar over the checks.
    """
    name = name or _name_of(component)
    checks = checks_for(kind)
    if progress:
        from tqdm.auto import tqdm

        checks = tqdm(checks, desc=f"checking {kind} {name}", unit="check")
    for check in checks:
        try:
            check(name, component)
        except Exception as exc:  # noqa: BLE001 - every failure is reported the same way
            raise AssertionError(f"{check.__name__} failed for {kind} {name!r}: {type(exc).__name__}: {exc}") from exc


def parametrize_with_checks(components):
    """A pytest parametrize mark over (component, check) for every check of each component.

    `components` holds ``(kind, component)`` pairs. The decorated test receives `component` and a
    `check` to call as ``check(component)``; test ids read ``<kind>:<name>-<check>``.
    """
    import pytest

    params, ids = [], []
    for kind, component in components:
        name = _name_of(component)
        for check in checks_for(kind):
            params.append((component, functools.partial(check, name)))
            ids.append(f"{kind}:{name}-{check.__name__}")
    return pytest.mark.parametrize("component, check", params, ids=ids)
