"""What the checks share: expected errors, which checks apply, partner components, input dimensions."""

from __future__ import annotations

import contextlib
import signal
import threading
import traceback
from pathlib import Path

from ..errors import ValidationError
from ..interfaces import capabilities
from ..kinds import page

# partner name -> the kind of component it is
PARTNER_KINDS = {"metric": "metric", "behavior": "behavior", "graph": None}
# the built-in partners used where none is given (convenience defaults, as for flockkit.build_graph)
_DEFAULT_NAMES = {"metric": "icp-hungarian", "behavior": "boids"}
KIT_DT = 0.1  # seconds per frame of every motion the kit makes, and of a behavior partner


def agents(n: int) -> str:
    """ "1 agent", "12 agents": a count of agents as a message says it."""
    return f"{n} agent" if n == 1 else f"{n} agents"


def expect_validation_error(call, description: str) -> None:
    """Assert that `call()` raises flockkit.errors.ValidationError; `description` names the call."""
    try:
        call()
    except ValidationError:
        return
    except Exception as exc:  # noqa: BLE001 - the wrong error type is the failure we report
        raise AssertionError(f"{description} raised {type(exc).__name__}, not ValidationError") from exc
    raise AssertionError(f"{description} raised nothing; expected ValidationError")


def applies_when(field: str):
    """Mark a check as applying only to components whose Capabilities declare `field`."""

    def mark(check):
        check.requires = field
        return check

    return mark


def applies_unless(field: str):
    """Mark a check as not applying to components whose Capabilities declare `field` (a live
    controller's pose is not a function of time alone)."""

    def mark(check):
        check.excluded_by = field
        return check

    return mark


def needs(*partners: str):
    """Mark a check as taking these partner components as keyword arguments."""

    def mark(check):
        check.partners = partners
        return check

    return mark


def fixed_by(advice: str):
    """Mark a check with the advice its failure message ends with, a "to fix:" line."""

    def mark(check):
        check.fix = advice
        return check

    return mark


def advice(check, kind: str, failure: BaseException | None = None) -> str:
    """How to fix a failure of `check`: when the component raised a ValidationError on the kit's
    valid input (its own, or one flockkit raised building a value it returned), what that error
    says and where it was raised; else the check's own advice, else the property its docstring
    states."""
    refused = _validation_error_in(failure)
    if refused is not None:
        return (
            f"the {kind} raised ValidationError at {_raised_at(refused)} on an input the kit holds valid. If it "
            f"builds a flockkit value there (a Motion, a Segmentation, an Alignment, a Walk), give that value "
            f"what the message asks for; if it refuses the input, accept it: see {page(kind)}"
        )
    own = getattr(check, "fix", None)
    if own:
        return own
    promise = " ".join((check.__doc__ or "").split()) or check.__name__
    return f"make the {kind} meet this ({check.__name__}): {promise} The contract: {page(kind, 'What the kit checks')}"


def _validation_error_in(failure: BaseException | None) -> ValidationError | None:
    """The ValidationError a failure came from, following its causes."""
    seen = set()
    while failure is not None and id(failure) not in seen:
        if isinstance(failure, ValidationError):
            return failure
        seen.add(id(failure))
        failure = failure.__cause__ or failure.__context__
    return None


def _raised_at(exc: BaseException) -> str:
    """The last line outside flockkit's own package that led to `exc`: the component's call."""
    package = str(Path(__file__).resolve().parents[1])  # flockkit's own folder
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if not f.filename.startswith((package, "<"))]
    frame = frames[-1] if frames else traceback.extract_tb(exc.__traceback__)[-1]
    return f"{Path(frame.filename).name}:{frame.lineno}"


def skip_reason(check, declared) -> str | None:
    """Why `check` does not apply to a component declaring `declared`, or None if it does. A
    declared value of 0 (a plausibility reach of zero frames) is a declaration, checked as such."""
    excluded = getattr(check, "excluded_by", None)
    if excluded is not None and getattr(declared, excluded):
        return f"the component declares Capabilities.{excluded} (this check is of components without it)"
    field = getattr(check, "requires", None)
    value = None if field is None else getattr(declared, field)
    if field is None or (value is not None and value is not False):
        return None
    return f"the component does not declare Capabilities.{field} (this check is of that optional operation)"


def default_partner(partner: str, kind: str):
    """The default partner `partner` (a metric or behavior) for `kind`'s checks: the built-in;
    ValidationError naming what to pass when it is not installed. (A walk's default graph is the
    kit's own, made by each check in the walk's dimension.)"""
    from ..registry import available, get

    name = _DEFAULT_NAMES[partner]
    if name not in available(PARTNER_KINDS[partner]):
        raise ValidationError(
            f"the {kind} checks need a {partner}: pass partners={{'{partner}': ...}} (the default, the built-in "
            f"{name!r}, is not installed or is blocked)"
        )
    return get(PARTNER_KINDS[partner], name, dt=KIT_DT) if partner == "behavior" else get(PARTNER_KINDS[partner], name)


def partner(value, name: str, kind: str):
    """`value` if given, else the default partner."""
    return default_partner(name, kind) if value is None else value


def dims_of(component) -> tuple[int, ...]:
    """The dimensions to check `component` in: those it declares."""
    return capabilities(component).dims


@contextlib.contextmanager
def on_input(name: str, component, dims: int, what: str):
    """Turn an exception raised while `component` handles a `dims`-D input into an AssertionError
    that says so and, where declaring fewer dimensions would explain it, which declaration to add."""
    try:
        yield
    except AssertionError as exc:
        raise AssertionError(f"{said(exc)} (on {what} in {dims}D)") from exc
    except Exception as exc:  # noqa: BLE001 - reported as this check failing, with the input
        raise AssertionError(
            f"{type(exc).__name__}: {said(exc)} (on {what} in {dims}D){_hint(name, component, dims, exc)}"
        ) from exc


def said(exc: BaseException) -> str:
    """What an exception says, or where it was raised when it says nothing (a bare ``assert``)."""
    text = str(exc)
    if text:
        return text
    frames = traceback.extract_tb(exc.__traceback__)
    return f"(no message) at {frames[-1].filename}:{frames[-1].lineno}" if frames else "(no message)"


# words of an error that a component handling fewer dimensions than it declares would raise
_SHAPE_WORDS = ("dim", "shape", "broadcast", "2d", "3d", "axis", "axes", "index", "size", "unpack")


def _hint(name, component, dims, exc) -> str:
    """Which declaration to add, when the error looks like a mismatch of dimensions and the
    component declares others it may handle alone."""
    declared = dims_of(component)
    others = tuple(d for d in declared if d != dims)
    text = str(exc).lower()
    if (
        not others
        or not isinstance(exc, (ValueError, IndexError, TypeError))
        or not any(w in text for w in _SHAPE_WORDS)
    ):
        return ""
    return (
        f". If {name} handles only {' and '.join(f'{d}D' for d in others)}, declare it: "
        f"capabilities = flockkit.Capabilities(dims={others!r})"
    )


class _Expired(BaseException):
    """Raised by the timer of `within`; a BaseException so that a plugin's ``except Exception``
    does not swallow it."""


@contextlib.contextmanager
def within(seconds: float, what: str):
    """Fail with an AssertionError naming `what` when the block runs past `seconds`, so that a
    component that loops for ever is reported instead of waited for. It uses SIGALRM, so the limit
    holds in the main thread of a POSIX process (where pytest runs tests); elsewhere the block runs
    without one."""
    if not hasattr(signal, "setitimer") or threading.current_thread() is not threading.main_thread():
        yield
        return

    def expire(signum, frame):
        raise _Expired

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    except _Expired:
        raise AssertionError(f"{what} ran past {seconds:g} s") from None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
