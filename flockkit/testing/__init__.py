"""flockkit.testing: the conformance kit for plugins, modelled on scikit-learn's ``check_estimator``.

Run every check of a kind that applies to a component::

    from flockkit.testing import check_plugin

    report = check_plugin("behavior", MyModel())
    print(report.passed, report.skipped)

or one pytest test per check::

    from flockkit.testing import parametrize_with_checks

    @parametrize_with_checks([("behavior", MyModel())])
    def test_conformance(component, check):
        check(component)

Which checks apply follows the component's declared ``flockkit.Capabilities``, as scikit-learn's
estimator tags do: a 2D-only model is checked on 2D flocks only, and the checks of an optional
operation it does not declare are skipped with the reason, never counted as passed. Checks that
need a partner component take it from `partners`: a ``metric`` for builders, a ``behavior`` (with
dt = 0.1 s) for proposals, a ``graph`` for walks. The defaults are the built-in ``icp-hungarian``
and ``boids`` where installed, and the kit's own graph (``flockkit.testing.inputs``); no check
needs a built-in when its partners are given.

Hypothesis strategies for every value a kind handles are in ``flockkit.testing.strategies``;
the pytest plugin (fixtures, ``--flockkit-kit``) is ``flockkit.testing.pytest_plugin``, and
``flockkit.testing.template.write_plugin`` (``flockkit new-plugin``) writes a new plugin's
distribution.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable, Mapping

import attrs

from ..errors import ValidationError
from ..interfaces import capabilities
from ..kinds import KINDS
from ..registry import interface_problems
from . import inputs, strategies
from ._expect import PARTNER_KINDS, advice, default_partner, said, skip_reason

__all__ = [
    "check_plugin",
    "parametrize_with_checks",
    "checks_for",
    "skipped_checks",
    "check_interface",
    "component_id",
    "CheckReport",
    "inputs",
    "strategies",
]


def check_interface(name, component, *, kind):
    """The component has every method of its kind's protocol, with compatible signatures, and every
    operation its capabilities declare."""
    problems = interface_problems(component, kind)
    assert not problems, f"{name} does not honour the {KINDS[kind].protocol.__name__} interface:\n" + "\n".join(
        f"  - {p}" for p in problems
    )


def _all_checks(kind: str) -> tuple:
    if kind not in KINDS:
        raise ValidationError(f"unknown plugin kind {kind!r}; the kinds are {', '.join(KINDS)}")
    interface = functools.partial(check_interface, kind=kind)
    functools.update_wrapper(interface, check_interface)
    return (interface, *importlib.import_module(KINDS[kind].kit).CHECKS)


def _bound(check, partners: Mapping) -> Callable:
    """`check` with the partners it takes filled in, keeping its name."""
    wanted = {k: partners[k] for k in getattr(check, "partners", ()) if k in partners}
    if not wanted:
        return check
    bound = functools.partial(check, **wanted)
    functools.update_wrapper(bound, check)
    return bound


def _partners(kind: str, given: Mapping | None) -> dict:
    """The partner components of `kind`'s checks: those given, else the defaults (which raise a
    ValidationError naming what to pass when no default is installed)."""
    given = dict(given or {})
    unknown = set(given) - set(PARTNER_KINDS)
    if unknown:
        raise ValidationError(f"unknown partners {sorted(unknown)}; the kit's partners are {', '.join(PARTNER_KINDS)}")
    needed = {p for check in _all_checks(kind) for p in getattr(check, "partners", ())}
    found = {p: given[p] for p in needed if p in given}
    found.update({p: default_partner(p, kind) for p in needed - set(given) if PARTNER_KINDS[p] is not None})
    return found


def checks_for(kind: str, component=None, *, partners: Mapping | None = None) -> tuple:
    """The checks of `kind`, each a callable ``check(name, component)``, the interface check first.

    With a `component`, only the checks that apply to what it declares, with their partner
    components bound (see the module docstring); :func:`skipped_checks` says why the others
    were left out. Without one, every check of the kind (partners then default when called)."""
    checks = _all_checks(kind)
    if component is None:
        return checks
    declared = capabilities(component)
    bound = _partners(kind, partners)
    return tuple(_bound(check, bound) for check in checks if skip_reason(check, declared) is None)


def skipped_checks(kind: str, component) -> dict[str, str]:
    """Check name -> why it does not apply to `component` (what it does not declare)."""
    declared = capabilities(component)
    reasons = {check.__name__: skip_reason(check, declared) for check in _all_checks(kind)}
    return {name: reason for name, reason in reasons.items() if reason is not None}


@attrs.frozen(kw_only=True)
class CheckReport:
    """What :func:`check_plugin` found: the checks passed, skipped (with the reason) and failed as
    expected (with the reason given)."""

    passed: tuple = ()
    skipped: Mapping = attrs.field(factory=dict)
    expected_failures: Mapping = attrs.field(factory=dict)

    def summary(self) -> str:
        parts = [f"{len(self.passed)} passed"]
        if self.skipped:
            parts.append(f"{len(self.skipped)} skipped ({'; '.join(f'{k}: {v}' for k, v in self.skipped.items())})")
        if self.expected_failures:
            parts.append(f"{len(self.expected_failures)} failed as expected ({', '.join(self.expected_failures)})")
        return ", ".join(parts)


def component_id(kind: str, component) -> str:
    """A name that tells configurations apart: the name `component`'s class is registered under
    for `kind` (else the class's name) and, for an attrs class, the parameters that differ from
    their defaults, as in ``icp-hungarian(velocity_weight=0)``."""
    from ..registry import describe

    if getattr(component, "__name__", None):
        return component.__name__
    kind_of = type(component)
    names = [c.name for c in describe(kind) if c.factory is kind_of] if kind in KINDS else []
    label = names[0] if names else kind_of.__name__
    if not attrs.has(kind_of):
        return label
    changed = []
    for field in attrs.fields(kind_of):
        value = getattr(component, field.name, None)
        default = field.default.factory() if isinstance(field.default, attrs.Factory) else field.default
        if field.init and field.default is not attrs.NOTHING and not _same(value, default):
            changed.append(f"{field.name}={value!r}")
    return f"{label}({', '.join(changed)})" if changed else label


def _same(value, default) -> bool:
    try:
        return bool(value == default)
    except Exception:  # noqa: BLE001 - arrays and other values without a truthy ==
        return value is default


def _run(check, kind: str, name: str, component) -> None:
    """Run one check; any failure becomes an AssertionError naming the check and the component,
    ending with a "to fix:" line."""
    try:
        check(name, component)
    except Exception as exc:  # noqa: BLE001 - every failure is reported the same way
        raise AssertionError(
            f"{check.__name__} failed for {kind} {name!r}: {type(exc).__name__}: {said(exc)}\n"
            f"  to fix: {advice(check, kind, exc)}"
        ) from exc


def _plan(kind: str, component, partners: Mapping | None = None) -> list[tuple[Callable, str | None]]:
    """Every check of `kind`, in order, with why it does not apply to `component` (None where it
    does, the check then bound to its partners)."""
    applicable = {c.__name__: c for c in checks_for(kind, component, partners=partners)}
    skipped = skipped_checks(kind, component)
    return [(applicable.get(c.__name__, c), skipped.get(c.__name__)) for c in _all_checks(kind)]


def _expected(expected_failed_checks, component) -> dict:
    if expected_failed_checks is None:
        return {}
    found = expected_failed_checks(component) if callable(expected_failed_checks) else expected_failed_checks
    return dict(found or {})


def check_plugin(
    kind: str,
    component,
    *,
    name: str | None = None,
    partners: Mapping | None = None,
    expected_failed_checks=None,
    progress: bool = False,
) -> CheckReport:
    """Run every check of `kind` that applies to `component` (a configured instance).

    Raises AssertionError listing every failed check with the plugin, each with its "to fix:"
    line (an unexpected exception inside a check counts as that check failing; a failed
    ``check_interface`` ends the run, since every later check relies on it), and naming any check
    listed in `expected_failed_checks` (check name -> reason, or a callable taking the component
    and returning that) that passed. Returns a CheckReport. `progress` shows a bar over the checks.
    """
    name = name or component_id(kind, component)
    expected = _expected(expected_failed_checks, component)
    checks = checks_for(kind, component, partners=partners)
    if progress:
        from tqdm.auto import tqdm

        checks = tqdm(checks, desc=f"checking {kind} {name}", unit="check")
    passed, failed_as_expected, failures = [], {}, []
    for check in checks:
        try:
            _run(check, kind, name, component)
        except AssertionError as failure:
            if check.__name__ in expected:
                failed_as_expected[check.__name__] = expected[check.__name__]
                continue
            failures.append(failure)
            if check.__name__ == "check_interface":
                break
            continue
        if check.__name__ in expected:
            failures.append(
                AssertionError(
                    f"{check.__name__} passed for {kind} {name!r} although it is listed in expected_failed_checks "
                    f"({expected[check.__name__]}); remove it from the list"
                )
            )
            continue
        passed.append(check.__name__)
    if len(failures) == 1:
        raise failures[0]
    if failures:
        listed = "\n\n".join(f"{i}. {failure}" for i, failure in enumerate(failures, 1))
        raise AssertionError(f"{len(failures)} checks failed for {kind} {name!r}:\n\n{listed}") from failures[0]
    return CheckReport(
        passed=tuple(passed), skipped=skipped_checks(kind, component), expected_failures=failed_as_expected
    )


def parametrize_with_checks(components, *, partners: Mapping | None = None, expected_failed_checks=None, ids=None):
    """A pytest parametrize mark over (component, check) for every check of each component.

    `components` holds ``(kind, component)`` pairs. The decorated test receives `component` and a
    `check` to call as ``check(component)``; test ids read ``<kind>:<name>-<check>``, the name
    from `ids` (one per component) or else :func:`component_id` (the registered name and the
    parameters set), so that two configurations of one class are told apart. A failure names the
    check and the component and ends with a "to fix:" line. Checks that
    do not apply to a component's declared capabilities are marked skipped with the reason;
    `expected_failed_checks` (check name -> reason, or a callable taking the component and
    returning that) marks known failures as strict xfail. `partners` as for :func:`check_plugin`.
    """
    import pytest

    components = list(components)
    ids = None if ids is None else [str(i) for i in ids]
    if ids is not None and len(ids) != len(components):
        raise ValidationError(f"ids: expected one name per component ({len(components)}); got {len(ids)}")
    params = []
    for index, (kind, component) in enumerate(components):
        name = component_id(kind, component) if ids is None else ids[index]
        expected = _expected(expected_failed_checks, component)
        for run, reason in _plan(kind, component, partners):
            check_name = run.__name__
            marks = [] if reason is None else [pytest.mark.skip(reason=reason)]
            if check_name in expected:
                marks.append(pytest.mark.xfail(reason=expected[check_name], strict=True))
            params.append(
                pytest.param(
                    component, functools.partial(_run, run, kind, name), marks=marks, id=f"{kind}:{name}-{check_name}"
                )
            )
    return pytest.mark.parametrize("component, check", params)
