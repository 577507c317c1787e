"""Plugin discovery, validation and lookup.

Plugins are modules found through entry points in the ``flockkit`` group (the built-ins too),
plus any plugin object passed to :func:`register`. The pluggy manager is built lazily, on the
first lookup, never at import time; :func:`reset` drops it so the next lookup rebuilds it (tests
use this after changing the environment).

Set ``FLOCKKIT_BLOCK_PLUGINS=name,...`` to skip plugins by their entry-point name (the ``plugin``
column of ``flockkit plugins``).
"""

from __future__ import annotations

import contextlib
import difflib
import functools
import importlib.metadata
import inspect
import os
import re
import sys
import threading
import warnings
from collections.abc import Callable

import attrs
import pluggy

from . import hookspecs
from .errors import FlockkitWarning, PluginError, UnknownPluginError, ValidationError
from .interfaces import capabilities
from .kinds import KINDS as _KINDS
from .kinds import page

__all__ = [
    "Component",
    "Registry",
    "get",
    "resolve",
    "label",
    "require_dims",
    "require",
    "capabilities_of",
    "available",
    "describe",
    "register",
    "registered",
    "reset",
    "plugin_manager",
    "interface_problems",
]

ENTRY_POINT_GROUP = "flockkit"
BLOCK_VARIABLE = "FLOCKKIT_BLOCK_PLUGINS"
KINDS = tuple(_KINDS)  # the kinds' names, in the order of flockkit.kinds.KINDS
_NAME = re.compile(r"^[a-z][a-z0-9]*(?:[-_][a-z0-9]+)*$")


@attrs.frozen(kw_only=True)
class Component:
    """One registered component: what ``flockkit plugins`` lists."""

    kind: str
    name: str
    factory: Callable
    description: str
    plugin: str
    distribution: str | None
    version: str | None

    @property
    def origin(self) -> str:
        where = f"distribution {self.distribution} {self.version}" if self.distribution else "registered at run time"
        return f"plugin {self.plugin!r} ({where})"


@functools.cache
def _protocol_methods(protocol: type) -> dict[str, inspect.Signature]:
    """The public methods of an interface (a Protocol class, fixed once defined) and their call
    signatures from an instance: read once per interface, not at every component made."""
    methods = {}
    for name, value in vars(protocol).items():
        if inspect.isfunction(value) and not name.startswith("_"):
            signature = inspect.signature(value)
            methods[name] = signature.replace(parameters=list(signature.parameters.values())[1:])
    return methods


def _method_signature(owner, name: str) -> inspect.Signature:
    """The call signature of `owner.name` as seen from an instance, for a class or an instance."""
    if isinstance(owner, type):
        raw = inspect.getattr_static(owner, name)
        if isinstance(raw, staticmethod):
            return inspect.signature(raw.__func__)
        signature = inspect.signature(getattr(owner, name))
        if isinstance(raw, classmethod):
            return signature
        return signature.replace(parameters=list(signature.parameters.values())[1:])
    return inspect.signature(getattr(owner, name))


def _parameter_problems(expected: inspect.Signature, actual: inspect.Signature) -> list[str]:
    params = list(actual.parameters.values())
    kinds = {p.kind for p in params}
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    wanted_positional = [
        p for p in expected.parameters.values() if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
    ]
    if (
        any(p.kind == p.VAR_KEYWORD for p in expected.parameters.values())
        and inspect.Parameter.VAR_KEYWORD not in kinds
    ):
        return [f"takes no **{next(p.name for p in expected.parameters.values() if p.kind == p.VAR_KEYWORD)}"]
    problems = []
    for index, wanted in enumerate(wanted_positional):
        if index >= len(positional):
            if inspect.Parameter.VAR_POSITIONAL not in kinds:
                problems.append(f"missing parameter {wanted.name!r}")
            continue
        got = positional[index]
        if got.name != wanted.name:
            problems.append(f"parameter {index + 1} is named {got.name!r}; expected {wanted.name!r}")
        elif wanted.default is not inspect.Parameter.empty and got.default is inspect.Parameter.empty:
            problems.append(f"parameter {wanted.name!r} needs a default (the interface's is {wanted.default!r})")
    by_name = {p.name: p for p in params if p.kind != p.POSITIONAL_ONLY}
    for wanted in (p for p in expected.parameters.values() if p.kind == p.KEYWORD_ONLY):
        got = by_name.get(wanted.name)
        if got is None and inspect.Parameter.VAR_KEYWORD not in kinds:
            problems.append(f"missing keyword parameter {wanted.name!r}")
        elif got is not None and got.default is inspect.Parameter.empty:
            problems.append(
                f"keyword parameter {wanted.name!r} needs a default (the interface's is {wanted.default!r})"
            )
    optional = {p.name for p in expected.parameters.values() if p.kind == p.KEYWORD_ONLY}
    for extra in positional[len(wanted_positional) :] + [p for p in params if p.kind == p.KEYWORD_ONLY]:
        if extra.default is inspect.Parameter.empty and extra.name not in optional:
            problems.append(
                f"extra parameter {extra.name!r} has no default, so callers of the interface cannot call it"
            )
    return problems


def _method_problems(component, protocol: type) -> list[str]:
    problems = []
    for name, expected in _protocol_methods(protocol).items():
        shown = f"{name}({', '.join(_shown(p) for p in expected.parameters.values())})"
        if not callable(getattr(component, name, None)):
            problems.append(f"{shown}: missing")
            continue
        try:
            actual = _method_signature(component, name)
        except (TypeError, ValueError):
            continue  # builtins without signatures: nothing to check
        problems.extend(f"{shown}: {problem}" for problem in _parameter_problems(expected, actual))
    return problems


def _shown(parameter: inspect.Parameter) -> str:
    return f"{parameter.name}=" if parameter.kind == parameter.KEYWORD_ONLY else parameter.name


def interface_problems(component, kind: str) -> list[str]:
    """What `component` (a class or an instance) lacks to honour the protocol of `kind`, and the
    operations its ``Capabilities`` declare; [] if nothing."""
    declaration = _KINDS[kind]
    problems = _method_problems(component, declaration.protocol)
    problems += [f"{name}: missing (an attribute)" for name in declaration.attributes if not hasattr(component, name)]
    try:
        declared = capabilities(component).declared()
    except ValidationError as exc:
        return [*problems, str(exc)]
    for field in declared:
        if field == "dims":
            continue
        if field not in declaration.fields:
            users = sorted(k.name for k in _KINDS.values() if field in k.fields)
            problems.append(f"capabilities.{field} is declared, but only {' and '.join(users)} components use it")
            continue
        protocol = declaration.optional.get(field)
        if protocol is not None:
            problems.extend(f"{p} (capabilities.{field} is declared)" for p in _method_problems(component, protocol))
    return problems


def _interface_error(component: Component, problems: list[str]) -> PluginError:
    protocol = _KINDS[component.kind].protocol.__name__
    lines = "\n".join(f"  - {p}" for p in problems)
    return PluginError(
        f"{component.origin} registers {component.kind} {component.name!r}, which does not honour the "
        f"{protocol} interface:\n{lines}\nFix the plugin, or skip it with {BLOCK_VARIABLE}={component.plugin}."
    )


class Registry:
    """The object passed to each ``flockkit_register_<kind>s`` hook.

    The hook is called once per kind through pluggy (``pm.hook.flockkit_register_<kind>s``), so
    hook wrappers and pluggy's call monitoring see it like any other hook call. Each component
    still records the plugin that added it: the plugin whose hook implementation is on the call
    stack of :meth:`add`.
    """

    def __init__(self, kind: str, table: dict[str, Component], owners: dict):
        self.kind = kind
        self._table = table
        self._owners = owners

    def add(self, name: str, factory: Callable, *, description: str = "") -> None:
        """Register `factory` under `name`; ``factory(**params)`` must return a component of this kind.

        Raises PluginError, naming the plugin and the component, for a bad name, a name already
        taken, a factory that is not callable, or a class without the methods of the interface or
        of the operations its ``capabilities`` declare.
        """
        plugin = _owner(self._owners, _frames(sys._getframe(1)))
        dist = _state.distributions.get(plugin)
        component = Component(
            kind=self.kind,
            name=name,
            factory=factory,
            description=str(description),
            plugin=plugin,
            distribution=dist.project_name if dist else None,
            version=dist.version if dist else None,
        )
        if not isinstance(name, str) or not _NAME.match(name):
            raise PluginError(
                f"{component.origin} registers a {self.kind} named {name!r}:\n"
                "  names are lower case letters and digits, words joined by '-' or '_', starting with a letter"
            )
        if name in self._table:
            other = self._table[name]
            raise PluginError(
                f"{self.kind} {name!r} is registered twice:\n  - by {other.origin}\n  - by {component.origin}\n"
                f"Uninstall one, or skip one with {BLOCK_VARIABLE}=<plugin>."
            )
        if not callable(factory):
            raise PluginError(
                f"{component.origin} registers {self.kind} {name!r} with a factory that is not callable: {factory!r}"
            )
        if isinstance(factory, type):
            problems = interface_problems(factory, self.kind) + _factory_problems(factory, self.kind)
            if problems:
                raise _interface_error(component, problems)
        self._table[name] = component


def _factory_problems(factory, kind: str) -> list[str]:
    """What the factory lacks of the parameters its declared capabilities promise."""
    declared = capabilities(factory)
    wanted = [(field, name) for field, names in _KINDS[kind].factory_parameters.items() if getattr(declared, field)
              for name in names]  # fmt: skip
    if not wanted:
        return []
    try:
        parameters = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        return []
    if any(p.kind == p.VAR_KEYWORD for p in parameters.values()):
        return []
    return [f"the factory has no parameter {name!r} (capabilities.{field} is declared)"
            for field, name in wanted if name not in parameters]  # fmt: skip


def _hook_owners(hook) -> dict:
    """code object -> [(plugin name, the instance a bound hook method belongs to)], for every
    implementation (wrappers included) of `hook`."""
    owners: dict = {}
    for impl in hook.get_hookimpls():
        function = impl.function
        code = getattr(getattr(function, "__func__", function), "__code__", None)
        if code is not None:
            owners.setdefault(code, []).append((impl.plugin_name, getattr(function, "__self__", None)))
    return owners


def _frames(frame):
    while frame is not None:
        yield frame
        frame = frame.f_back


def _owner(owners: dict, frames) -> str:
    """The plugin whose hook implementation runs in the first of `frames` that is one ("unknown"
    if none is): two instances of one plugin class are told apart by their `self`."""
    for frame in frames:
        entries = owners.get(frame.f_code)
        if entries:
            me = frame.f_locals.get("self")
            return next((name for name, bound in entries if bound is me), entries[0][0])
    return "unknown"


@attrs.frozen
class _Dist:
    project_name: str
    version: str


class _State:
    def __init__(self):
        self.lock = threading.RLock()
        self.manager: pluggy.PluginManager | None = None
        self.components: dict[str, dict[str, Component]] | None = None
        self.runtime_plugins: list[tuple[object, str]] = []
        self.distributions: dict[str, _Dist] = {}  # plugin name -> its distribution, for listings


_state = _State()


def _blocked() -> set[str]:
    return {name.strip() for name in os.environ.get(BLOCK_VARIABLE, "").split(",") if name.strip()}


def _build_manager() -> pluggy.PluginManager:
    manager = pluggy.PluginManager(hookspecs.PROJECT)
    manager.add_hookspecs(hookspecs)
    for name in _blocked():
        manager.set_blocked(name)
    _state.distributions = {}
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        dist = entry_point.dist
        where = f"distribution {dist.name} {dist.version}" if dist else "an unknown distribution"
        if manager.is_blocked(entry_point.name):
            continue
        if manager.has_plugin(entry_point.name):
            other = _state.distributions.get(entry_point.name)
            raise PluginError(
                f"two distributions declare the flockkit plugin {entry_point.name!r}:\n"
                f"  - {other.project_name if other else '?'}\n  - {dist.name if dist else '?'}\n"
                f"Uninstall one, or skip both with {BLOCK_VARIABLE}={entry_point.name}."
            )
        try:
            plugin = entry_point.load()
        except (Exception, SystemExit) as exc:  # a plugin calling sys.exit() at import is a broken plugin
            raise PluginError(
                f"plugin {entry_point.name!r} ({where}) failed to import {entry_point.value!r}:\n"
                f"  {type(exc).__name__}: {exc}\nFix it, or skip it with {BLOCK_VARIABLE}={entry_point.name}."
            ) from exc
        _register_with(manager, plugin, entry_point.name, where)
        if dist is not None:
            _state.distributions[entry_point.name] = _Dist(dist.name, dist.version)
    for plugin, name in _state.runtime_plugins:
        _register_with(manager, plugin, name, "registered at run time")
    try:
        manager.check_pending()
    except pluggy.PluginValidationError as exc:
        raise PluginError(
            f"plugin {manager.get_name(exc.plugin)!r} implements a hook flockkit does not define:\n  {exc}\n"
            f"Known hooks: {', '.join(k.hook for k in _KINDS.values())}."
        ) from None
    return manager


def _register_with(manager, plugin, name: str, where: str) -> None:
    if manager.is_blocked(name):
        return
    try:
        manager.register(plugin, name=name)
    except (pluggy.PluginValidationError, ValueError) as exc:
        raise PluginError(f"plugin {name!r} ({where}) cannot be registered:\n  {exc}") from None


def _collect(manager: pluggy.PluginManager) -> dict[str, dict[str, Component]]:
    components: dict[str, dict[str, Component]] = {}
    for kind, declaration in _KINDS.items():
        hook_name = declaration.hook
        table = components[kind] = {}
        hook = getattr(manager.hook, hook_name)
        owners = _hook_owners(hook)
        try:
            hook(registry=Registry(kind, table, owners))
        except PluginError:
            raise
        except Exception as exc:
            innermost = [tb.tb_frame for tb in _tracebacks(exc.__traceback__)][::-1]
            raise PluginError(
                f"plugin {_owner(owners, innermost)!r} failed in {hook_name}:\n  {type(exc).__name__}: {exc}"
            ) from exc
    if not any(components.values()):
        warnings.warn(
            "no flockkit plugin component was found: every plugin is blocked "
            f"({BLOCK_VARIABLE}), or flockkit runs from a source tree without install metadata "
            "(install it: pip install -e .)",
            FlockkitWarning,
            stacklevel=4,
        )
    return components


def _tracebacks(tb):
    while tb is not None:
        yield tb
        tb = tb.tb_next


def plugin_manager() -> pluggy.PluginManager:
    """The pluggy manager, built on first use."""
    with _state.lock:
        if _state.manager is None:
            _state.manager = _build_manager()
        return _state.manager


def _components() -> dict[str, dict[str, Component]]:
    with _state.lock:
        if _state.components is None:
            _state.components = _collect(plugin_manager())
        return _state.components


def register(plugin: object, name: str | None = None) -> None:
    """Add a plugin object (a module or any object with hook implementations) without an entry
    point, for scripts and tests. It is kept until :func:`reset`."""
    with _state.lock:
        _runtime_plugins([*_state.runtime_plugins, (plugin, name or getattr(plugin, "__name__", None) or repr(plugin))])


@contextlib.contextmanager
def registered(plugin: object, name: str | None = None):
    """:func:`register` `plugin` for the ``with`` block only: on leaving it, the run-time plugins
    are those of before (the pytest fixture ``flockkit_register`` uses this)."""
    with _state.lock:
        before = list(_state.runtime_plugins)
    register(plugin, name)
    try:
        yield plugin
    finally:
        _runtime_plugins(before)


def reset() -> None:
    """Forget the plugin manager and run-time plugins; the next lookup discovers plugins afresh."""
    _runtime_plugins([])


def _runtime_plugins(plugins: list) -> None:
    """Make `plugins` the run-time plugins; the next lookup builds the manager afresh."""
    with _state.lock:
        _state.runtime_plugins = list(plugins)
        _state.manager = None
        _state.components = None


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        close = difflib.get_close_matches(str(kind), KINDS, n=1)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        raise UnknownPluginError(f"unknown plugin kind {kind!r}; the kinds are {', '.join(KINDS)}.{hint}")


def describe(kind: str | None = None) -> list[Component]:
    """Every registered component (of one kind, if given), sorted by kind and name."""
    if kind is not None:
        _check_kind(kind)
    return [
        component
        for k, table in _components().items()
        if kind in (None, k)
        for component in sorted(table.values(), key=lambda c: c.name)
    ]


def available(kind: str | None = None):
    """Names of the installed components: a sorted list for one `kind`, else a dict kind -> list."""
    if kind is not None:
        _check_kind(kind)
        return sorted(_components()[kind])
    return {k: sorted(table) for k, table in _components().items()}


def _lookup(kind: str, name: str) -> Component:
    _check_kind(kind)
    table = _components()[kind]
    if name in table:
        return table[name]
    installed = ", ".join(sorted(table)) or "none"
    close = difflib.get_close_matches(str(name), list(table), n=3, cutoff=0.6)
    hint = f" Did you mean {' or '.join(map(repr, close))}?" if close else ""
    raise UnknownPluginError(f"no {kind} named {name!r} is installed; installed {kind}s: {installed}.{hint}")


def takes(kind: str, name: str, parameter: str) -> bool:
    """Whether the factory of the `kind` component `name` takes the keyword `parameter` (True for
    a factory taking any keyword, or one whose signature cannot be read: the call then says)."""
    try:
        parameters = inspect.signature(_lookup(kind, name).factory).parameters
    except (TypeError, ValueError):
        return True
    return parameter in parameters or any(p.kind is p.VAR_KEYWORD for p in parameters.values())


def get(kind: str, name: str, **params):
    """A configured component: ``factory(**params)`` of the `kind` component registered as `name`.

    Raises UnknownPluginError (a KeyError) for an unknown kind or name, listing what is installed
    and close matches; ValidationError for parameters the factory does not take; PluginError if the
    factory returns something that does not honour the interface.
    """
    component = _lookup(kind, name)
    try:
        signature = inspect.signature(component.factory)
    except (TypeError, ValueError):
        signature = None
    if signature is not None:
        try:
            signature.bind(**params)
        except TypeError as exc:
            accepted = ", ".join(p for p in signature.parameters if p not in ("self", "args", "kwargs")) or "none"
            raise ValidationError(f"{kind} {name!r}: {exc}; its parameters are: {accepted}") from None
    try:
        instance = component.factory(**params)
    except ValidationError:
        raise  # a parameter the component refuses, named by it
    except Exception as exc:  # noqa: BLE001 - whatever a plugin raises, say which plugin it was
        raise PluginError(
            f"{component.origin} failed to make {kind} {name!r} (parameters: {', '.join(params) or 'none'}): "
            f"{type(exc).__name__}: {exc}"
        ) from exc
    problems = interface_problems(instance, kind)
    if problems:
        raise _interface_error(component, problems)
    return instance


def resolve(kind: str, spec, **params):
    """A component of `kind`: ``get(kind, spec, **params)`` for a registered name, or `spec` itself
    for an instance (used as it is configured: `params` are for names only).

    Every public function that uses a component resolves it with this, once, in the caller's
    process; only instances travel further (into joblib workers too). Raises ValidationError for
    an instance that does not honour the interface of `kind`, for a class instead of an instance,
    and for parameters given with an instance.
    """
    if isinstance(spec, str):
        return get(kind, spec, **params)
    _check_kind(kind)
    shown = getattr(spec, "__name__", None) or type(spec).__name__
    if isinstance(spec, type):
        raise ValidationError(f"{kind}: got the class {shown}; pass an instance ({shown}(...)) or a registered name")
    if params:
        raise ValidationError(
            f"{kind} {shown}: parameters {', '.join(sorted(params))} are for a {kind} made by name; "
            "an instance is used as it is configured"
        )
    problems = interface_problems(spec, kind)
    if problems:
        lines = "\n".join(f"  - {p}" for p in problems)
        raise ValidationError(
            f"{kind} {shown} does not honour the {_KINDS[kind].protocol.__name__} interface:\n{lines}"
        )
    return spec


def label(spec) -> str:
    """How a component given as `spec` (a name or an instance) is named in reports: the name, or
    the instance's class name."""
    return spec if isinstance(spec, str) else type(spec).__name__


def capabilities_of(kind: str, spec):
    """The ``Capabilities`` of a component given as `spec`: for a registered name, its factory's
    (read before anything is made), for an instance, its own."""
    return capabilities(_lookup(kind, spec).factory if isinstance(spec, str) else spec)


def require(kind: str, spec, field: str, what: str) -> None:
    """Raise ValidationError unless the component `spec` (a name or an instance) declares the
    capability `field` that `what` (the caller, "a Scene's walks") needs, saying how to declare it."""
    if not getattr(capabilities_of(kind, spec), field):
        raise ValidationError(
            f"{what} need a {kind} declaring Capabilities({field}=True); {kind} {label(spec)} does not declare it "
            f"(see {page(kind)})"
        )


def require_dims(kind: str, component, dims: int, what: str, *, spec=None) -> None:
    """Raise ValidationError unless `component` declares that it handles `dims` dimensions; `what`
    names the input ("a 3D problem"), `spec` how the caller named the component (default: its class)."""
    handled = capabilities(component).dims
    if dims not in handled:
        only = " and ".join(f"{d}D" for d in handled)
        raise ValidationError(
            f"{kind} {label(component if spec is None else spec)} handles {only} only "
            f"(its Capabilities.dims is {handled}); got {what}"
        )
