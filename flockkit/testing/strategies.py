"""Hypothesis strategies for flockkit values, in the style of ``hypothesis.extra.numpy``.

Arguments are keyword-only; bad arguments raise ``hypothesis.errors.InvalidArgument`` when the
strategy is created, not when it is drawn from::

    from hypothesis import given
    from flockkit.testing import strategies as fst

    @given(fst.motions(max_frames=30, dims=3))
    def test_something(motion): ...
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument
from hypothesis.extra import numpy as hnp

from ..constrained.problem import ComConstraint
from ..motion import Configuration, Motion, State

__all__ = ["configurations", "states", "motions", "com_tracks", "difference_matrices", "anything", "damaged"]


def _check_count(name, value, low=1):
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise InvalidArgument(f"{name} must be an integer >= {low}; got {value!r}")


def _check_range(low_name, low, high_name, high, floor=1):
    _check_count(low_name, low, floor)
    _check_count(high_name, high, floor)
    if low > high:
        raise InvalidArgument(f"{low_name}={low} must be <= {high_name}={high}")


def _check_positive(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise InvalidArgument(f"{name} must be a finite number > 0; got {value!r}")


def _dims(dims):
    if dims is None:
        return st.sampled_from((2, 3))
    if dims not in (2, 3):
        raise InvalidArgument(f"dims must be 2, 3 or None (either); got {dims!r}")
    return st.just(dims)


def _names(name, value):
    names = tuple(value)
    for item in names:
        if not isinstance(item, str) or not item.isidentifier():
            raise InvalidArgument(f"{name} must hold Python identifiers; got {item!r}")
    return names


def _vectors(shape, bound):
    return hnp.arrays("float64", shape, elements=st.floats(-bound, bound, allow_nan=False, allow_infinity=False))


def _validate(min_agents, max_agents, max_coordinate, max_speed):
    _check_range("min_agents", min_agents, "max_agents", max_agents)
    _check_positive("max_coordinate", max_coordinate)
    _check_positive("max_speed", max_speed)


def configurations(*, min_agents=1, max_agents=10, dims=None, max_coordinate=100.0, max_speed=10.0):
    """Configurations with N in [min_agents, max_agents], D = `dims` (None: 2 or 3), coordinates
    in [-max_coordinate, max_coordinate] and velocity components in [-max_speed, max_speed]."""
    _validate(min_agents, max_agents, max_coordinate, max_speed)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_configuration(draw):
        shape = (draw(st.integers(min_agents, max_agents)), draw(dims_strategy))
        return Configuration(
            positions=draw(_vectors(shape, max_coordinate)), velocities=draw(_vectors(shape, max_speed))
        )

    return draw_configuration()


def states(*, min_agents=1, max_agents=10, dims=None, max_coordinate=100.0, max_speed=10.0, extra=()):
    """States as in :func:`configurations`, with one (N, D) array per name in `extra`, its
    components in [-max_speed, max_speed]."""
    _validate(min_agents, max_agents, max_coordinate, max_speed)
    names = _names("extra", extra)
    dims_strategy = _dims(dims)

    @st.composite
    def draw_state(draw):
        shape = (draw(st.integers(min_agents, max_agents)), draw(dims_strategy))
        return State(
            positions=draw(_vectors(shape, max_coordinate)),
            velocities=draw(_vectors(shape, max_speed)),
            extra={name: draw(_vectors(shape, max_speed)) for name in names},
        )

    return draw_state()


def motions(
    *,
    min_frames=1,
    max_frames=20,
    min_agents=1,
    max_agents=10,
    dims=None,
    dt=None,
    max_coordinate=100.0,
    channels=(),
):
    """Motions with T in [min_frames, max_frames], N in [min_agents, max_agents], D = `dims`
    (None: 2 or 3), coordinates in [-max_coordinate, max_coordinate], `dt` seconds per frame
    (None: drawn from [0.01, 1]) and one channel per name in `channels`."""
    _check_range("min_frames", min_frames, "max_frames", max_frames)
    _validate(min_agents, max_agents, max_coordinate, 1.0)
    if dt is not None:
        _check_positive("dt", dt)
    names = _names("channels", channels)
    dims_strategy = _dims(dims)
    dt_strategy = st.just(float(dt)) if dt is not None else st.floats(0.01, 1.0)

    @st.composite
    def draw_motion(draw):
        shape = (
            draw(st.integers(min_frames, max_frames)),
            draw(st.integers(min_agents, max_agents)),
            draw(dims_strategy),
        )
        return Motion(
            positions=draw(_vectors(shape, max_coordinate)),
            dt=draw(dt_strategy),
            channels={name: draw(_vectors(shape, max_coordinate)) for name in names},
        )

    return draw_motion()


def com_tracks(*, min_constraints=2, max_constraints=5, dims=None, max_coordinate=10.0, max_gap=3.0):
    """Tracks of center-of-mass constraints on all agents, as ``Problem.tracks`` holds them: a
    tuple of `min_constraints` to `max_constraints` ComConstraints in time order, the first at
    time 0, each the one before plus a gap in [0.5, max_gap] seconds (whole tenths, so that no two
    share a frame at the paper's 10 Hz), positions in [-max_coordinate, max_coordinate] and D =
    `dims` (None: 2 or 3)."""
    _check_range("min_constraints", min_constraints, "max_constraints", max_constraints)
    _check_positive("max_coordinate", max_coordinate)
    _check_positive("max_gap", max_gap)
    if max_gap < 0.5:
        raise InvalidArgument(f"max_gap must be >= 0.5 seconds; got {max_gap!r}")
    dims_strategy = _dims(dims)

    @st.composite
    def draw_track(draw):
        count, dims = draw(st.integers(min_constraints, max_constraints)), draw(dims_strategy)
        gaps = draw(st.lists(st.integers(5, int(max_gap * 10)), min_size=count - 1, max_size=count - 1))
        times = np.concatenate([[0], np.cumsum(gaps)]) / 10
        positions = draw(_vectors((count, dims), max_coordinate))
        return tuple(ComConstraint(time=float(t), position=p) for t, p in zip(times, positions))

    return draw_track()


def difference_matrices(*, max_size: int = 12):
    """Symmetric (K, K) difference matrices, K in [1, max_size], of a few distinct values (so that
    ties are common) with some cells +inf (not computed), as builders hold them."""
    _check_count("max_size", max_size)

    @st.composite
    def draw_matrix(draw):
        k = draw(st.integers(1, max_size))
        cells = draw(hnp.arrays("float64", (k, k), elements=st.sampled_from([0.0, 0.5, 1.0, 2.0, math.inf])))
        return np.minimum(cells, cells.T)

    return draw_matrix()


def anything(*, max_leaves: int = 4):
    """Values of every kind a careless caller passes where a number, an array or a component is
    expected: None, booleans, integers (huge and negative too), floats (NaN, infinities,
    subnormals, 1e308), strings, bytes, numpy arrays of odd shapes and dtypes, and lists (nested
    up to `max_leaves` values) of these. For robustness tests: a function given one must work or
    raise a documented flockkit error."""
    _check_count("max_leaves", max_leaves)
    scalars = st.one_of(
        st.none(),
        st.booleans(),
        st.integers(min_value=-(2**70), max_value=2**70),
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from([0.0, -0.0, 5e-324, 1e308, -1e308, 1e-300, 2.0, 3.0]),
        st.text(max_size=6),
        st.binary(max_size=6),
    )
    arrays = hnp.arrays(
        dtype=st.sampled_from(["float64", "float32", "int64", "bool", "complex128"]),
        shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4),
    )
    return st.recursive(st.one_of(scalars, arrays), lambda inner: st.lists(inner, max_size=3), max_leaves=max_leaves)


def damaged(data: bytes, *, max_flips: int = 3):
    """Copies of the bytes `data` damaged as storage and transfers damage files: up to `max_flips`
    bytes changed, or cut short at any length, or both."""
    if not isinstance(data, bytes | bytearray) or not data:
        raise InvalidArgument(f"data must be non-empty bytes; got {type(data).__name__}")
    _check_count("max_flips", max_flips, low=0)
    size = len(data)

    @st.composite
    def draw_damaged(draw):
        damaged_data = bytearray(data)
        for _ in range(draw(st.integers(0, max_flips))):
            at = draw(st.integers(0, size - 1))
            damaged_data[at] ^= draw(st.integers(1, 255))
        if draw(st.booleans()):
            damaged_data = damaged_data[: draw(st.integers(0, size - 1))]
        return bytes(damaged_data)

    return draw_damaged()
