"""Checks of numbers, counts and frame windows with messages that name the field: the core uses
them, and plugins import them instead of writing their own.

Each raises ``flockkit.errors.ValidationError`` (a ``ValueError``) saying what was expected::

    import attrs
    from flockkit import validate

    @attrs.frozen(kw_only=True)
    class Drift:
        dt: float = validate.parameter("drift", default=0.1, minimum=0, strict=True)
        sigma: float = validate.parameter("drift", default=0.1, minimum=0, strict=True)

        def log_plausibility(self, motion, start=0, stop=None):
            start, stop = validate.window(motion, start, stop, owner="drift")
            ...
"""

from __future__ import annotations

import math
import os
import re

import attrs
import numpy as np

from .errors import ValidationError

__all__ = ["number", "integer", "dims", "flag", "seed", "window", "parameter", "allocation", "memory_limit"]

_NO_DEFAULT = object()


def _bound(minimum, strict, maximum=None) -> str:
    low = "" if minimum is None else f" {'>' if strict else '>='} {minimum:g}"
    return low + ("" if maximum is None else f"{' and' if low else ''} <= {maximum:g}")


def number(
    value, field: str, *, minimum=None, strict: bool = False, maximum=None, optional: bool = False
) -> float | None:
    """`value` as a float: a finite real number (not a bool, not a string) at least `minimum`
    (above it with `strict`) and at most `maximum`; None passes through with `optional`."""
    if value is None and optional:
        return None
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    if ok:
        converted = _float(value)
        ok = math.isfinite(converted) and (minimum is None or (converted > minimum if strict else converted >= minimum))
        ok = ok and (maximum is None or converted <= maximum)
        value = converted if ok else value
    if not ok:
        expected = f"a finite number{_bound(minimum, strict, maximum)}"
        raise ValidationError(f"{field} must be {'None or ' if optional else ''}{expected}; got {value!r}")
    return value


def _float(value) -> float:
    """`value` as a float; an integer too large for one (Python's are unbounded) as infinity."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def integer(value, field: str, *, minimum=None, optional: bool = False) -> int | None:
    """`value` as an int: an integer (not a bool, not a float) at least `minimum`; None passes
    through with `optional`."""
    if value is None and optional:
        return None
    if (
        isinstance(value, (bool, np.bool_))
        or not isinstance(value, (int, np.integer))
        or (minimum is not None and value < minimum)
    ):
        expected = f"an integer{_bound(minimum, False)}"
        raise ValidationError(f"{field} must be {'None or ' if optional else ''}{expected}; got {value!r}")
    return int(value)


def dims(value, field: str = "dims") -> int:
    """`value` as a number of dimensions: the integer 2 or 3."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value not in (2, 3):
        raise ValidationError(f"{field} must be 2 or 3; got {value!r}")
    return int(value)


def flag(value, field: str) -> bool:
    """`value`, which must be True or False."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValidationError(f"{field} must be True or False; got {value!r}")
    return bool(value)


def seed(value, field: str = "seed") -> int | None:
    """`value` as a random seed: None (fresh entropy) or an integer >= 0, what
    ``numpy.random.default_rng`` takes."""
    return integer(value, field, minimum=0, optional=True)


# What one request may take unless FLOCKKIT_MEMORY_LIMIT says otherwise: the decompression-bomb
# rule of image libraries (Pillow refuses images above about 179 megapixels, 0.5 GiB of RGB),
# scaled to animation: a mesh of 100 000 vertices over 900 frames, a crowd of a million agents.
DEFAULT_MEMORY_LIMIT = 2 * 1024**3
_UNITS = {"": 1, "K": 1024, "M": 1024**2, "G": 1024**3, "T": 1024**4}


def memory_limit() -> float:
    """The most bytes one request may take: FLOCKKIT_MEMORY_LIMIT (bytes, or a number with a K,
    M, G or T suffix, powers of 1024) or DEFAULT_MEMORY_LIMIT, and never more than this machine
    has available (/proc/meminfo's MemAvailable, else physical memory)."""
    text = os.environ.get("FLOCKKIT_MEMORY_LIMIT", "").strip()
    limit = float(DEFAULT_MEMORY_LIMIT)
    if text:
        match = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([KMGT]?)(?:i?B)?", text, re.IGNORECASE)
        if not match:
            raise ValidationError(f"FLOCKKIT_MEMORY_LIMIT must be a number of bytes such as 8G; got {text!r}")
        limit = float(match.group(1)) * _UNITS[match.group(2).upper()]
    return min(limit, _available_memory())


def allocation(n_values, what: str, *, itemsize: int = 8) -> None:
    """Refuse, before any work, a request of `n_values` numbers (`itemsize` bytes each) above the
    memory budget (:func:`memory_limit`): ValidationError stating the memory `what` would need,
    the budget, and how to raise it."""
    needed = _float(n_values) * itemsize
    limit = memory_limit()
    if not needed <= limit:
        raise ValidationError(
            f"{what} needs {_size(needed)} of memory; the budget is {_size(limit)} (the smaller of "
            f"FLOCKKIT_MEMORY_LIMIT, default {_size(DEFAULT_MEMORY_LIMIT)}, and the memory available)"
        )


def _available_memory() -> float:
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return float("inf")


def _size(count: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if count < 1024 or unit == "PiB":
            return f"{count:.3g} {unit}"
        count /= 1024
    return f"{count:.3g} PiB"


def window(motion, start, stop, *, owner: str) -> tuple[int, int]:
    """The frame window (start, stop) of `motion`, ``stop=None`` meaning its end, checked as every
    windowed operation (``log_plausibility``, ``log_terms``) must: integers with
    0 <= start <= stop <= n_frames. `owner` names the component in the message."""
    # a Motion by what it offers (validate stands below flockkit.motion, which it checks numbers for)
    n_frames = getattr(motion, "n_frames", None)
    if type(n_frames) is not int or not hasattr(motion, "positions"):
        raise ValidationError(f"{owner}: motion must be a flockkit.Motion; got {type(motion).__name__}")
    stop = n_frames if stop is None else stop
    start, stop = integer(start, f"{owner}: start"), integer(stop, f"{owner}: stop")
    if not 0 <= start <= stop <= n_frames:
        raise ValidationError(
            f"{owner}: window start={start}, stop={stop} must satisfy 0 <= start <= stop <= {n_frames} "
            "(the frame count)"
        )
    return start, stop


def parameter(
    owner: str,
    *,
    default=_NO_DEFAULT,
    kind: str = "number",
    minimum=None,
    strict: bool = False,
    maximum=None,
    optional: bool = False,
):
    """An ``attrs.field`` for a component parameter, checked on construction with the messages of
    :func:`number`, :func:`integer` or :func:`flag` (`kind`), named "<owner> parameter <name>"."""
    if kind not in ("number", "integer", "flag"):
        raise ValueError(f"kind must be 'number', 'integer' or 'flag'; got {kind!r}")

    def check(instance, attribute, value):
        field = f"{owner} parameter {attribute.name}"
        if kind == "flag":
            flag(value, field)
        elif kind == "integer":
            integer(value, field, minimum=minimum, optional=optional)
        else:
            number(value, field, minimum=minimum, strict=strict, maximum=maximum, optional=optional)

    if default is _NO_DEFAULT:
        return attrs.field(validator=check)
    return attrs.field(default=default, validator=check)
