"""Conversion and validation of array fields: float64, read-only, messages that name the field."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np

from .errors import ValidationError


def readonly_float(value, *, field: str) -> np.ndarray:
    """Return `value` as a new read-only float64 array, or raise ValidationError naming `field`."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", np.exceptions.ComplexWarning)  # complex values are refused
            array = np.array(value, dtype=np.float64, copy=True, order="C")  # C order: fast slices of frames
    except (TypeError, ValueError, OverflowError, np.exceptions.ComplexWarning) as exc:  # Overflow: a huge int
        raise ValidationError(f"{field} must be an array of numbers; got {type(value).__name__}: {exc}") from None
    array.setflags(write=False)
    return array


def readonly_int(value, *, field: str, dtype=np.int64) -> np.ndarray:
    """Return `value` as a new read-only integer array, or raise ValidationError naming `field`."""
    try:
        array = np.array(value, copy=True)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{field} must be an array of integers; got {type(value).__name__}: {exc}") from None
    if array.dtype.kind not in "iu" and array.size:
        raise ValidationError(f"{field} must be an array of integers; got dtype {array.dtype}")
    array = array.astype(dtype)
    array.setflags(write=False)
    return array


def check_finite(array: np.ndarray, *, field: str) -> None:
    """Raise ValidationError naming `field` and the first bad index if `array` holds NaN or inf."""
    if np.isfinite(np.sum(array)):  # one pass, no mask; a NaN or inf anywhere makes the sum one
        return
    bad = ~np.isfinite(array)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValidationError(
            f"{field} must be finite; found {array[first]} at index {first} ({int(bad.sum())} bad values in all)"
        )


def check_agent_array(array: np.ndarray, *, field: str, shape: tuple[int, ...] | None = None) -> None:
    """Validate an (N, D) array of agent vectors: D in {2, 3}, N >= 1, finite, optionally a given shape."""
    if shape is not None and array.shape != shape:
        raise ValidationError(f"{field} must have shape {shape}; got {array.shape}")
    if array.ndim != 2 or array.shape[1] not in (2, 3) or array.shape[0] < 1:
        raise ValidationError(f"{field} must have shape (N, D) with N >= 1 and D in {{2, 3}}; got {array.shape}")
    check_finite(array, field=field)


def readonly_mapping(value, *, field: str) -> Mapping[str, np.ndarray]:
    """Return a read-only name -> read-only float64 array mapping; names must be identifiers."""
    if value is None:
        value = {}
    if not isinstance(value, Mapping):
        raise ValidationError(f"{field} must be a mapping of names to arrays; got {type(value).__name__}")
    converted = {}
    for name, array in value.items():
        if not isinstance(name, str) or not name.isidentifier():
            raise ValidationError(f"{field} names must be Python identifiers; got {name!r}")
        converted[name] = readonly_float(array, field=f"{field}[{name!r}]")
    return MappingProxyType(converted)
