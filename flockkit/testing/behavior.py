"""Conformance checks for behavior models (``flockkit.interfaces.BehaviorModel``).

Each check is ``check_<property>(name, model)`` and raises AssertionError saying what is wrong.
They run on a few fixed flocks (one agent to a hundred) in the dimensions the model declares, and
on tied and symmetric ones (``inputs.degenerate_configurations``), so results are reproducible;
the checks of ``guide``, ``group_guide``, ``progress``, ``plausibility_reach``, ``residuals`` and
``coupling`` run only for models that declare them.
"""

from __future__ import annotations

import numpy as np

from ..errors import ValidationError
from ..motion import Motion, State, random_flock
from ._expect import agents, applies_when, dims_of, expect_validation_error, fixed_by, on_input

STEPS = 12
SEED = 20031
# flock sizes per dimension: a lone agent, a small flock, and one large enough for spatial search
_SIZES = {2: (1, 12, 100), 3: (1, 8, 30)}


def _flocks(model) -> list[State]:
    """The fixed flocks in the model's declared dimensions."""
    return [
        random_flock(n_agents=n, dims=d, rng=np.random.default_rng(SEED + 100 * d + n))
        for d in dims_of(model)
        for n in _SIZES[d]
    ]


def _flock(model) -> State:
    """One small flock in the model's first declared dimension."""
    d = dims_of(model)[0]
    return random_flock(n_agents=_SIZES[d][1], dims=d, rng=np.random.default_rng(SEED + 100 * d))


def _each(name, model):
    """(flock, context) for every fixed flock; the context names the flock in failures."""
    for state in _flocks(model):
        yield state, on_input(name, model, state.dims, f"a flock of {agents(state.n_agents)}")


def _forward(model, state, steps=STEPS, seed=0) -> Motion:
    return model.forward(state, steps, np.random.default_rng(seed))


def _backward(model, state, steps=STEPS, seed=0) -> Motion:
    return model.backward(state, steps, np.random.default_rng(seed))


def _check_motion(name, motion, state, steps, operation):
    assert isinstance(motion, Motion), f"{name}.{operation} returned {type(motion).__name__}, not a flockkit.Motion"
    expected = (steps + 1, state.n_agents, state.dims)
    assert motion.positions.shape == expected, (
        f"{name}.{operation}(state of {agents(state.n_agents)} in {state.dims}D, steps={steps}) returned positions "
        f"of shape {motion.positions.shape}; expected {expected}"
    )
    assert motion.positions.dtype == np.float64, f"{name}.{operation} positions have dtype {motion.positions.dtype}"
    assert np.all(np.isfinite(motion.positions)), f"{name}.{operation} returned non-finite positions"


def _shaken(motion, rng) -> Motion:
    """`motion` with positional noise of a quarter of its median step."""
    step = np.linalg.norm(np.diff(motion.positions, axis=0), axis=-1)
    noise = rng.normal(0.0, 0.25 * float(np.median(step)), motion.positions.shape)
    return Motion(positions=motion.positions + noise, dt=motion.dt, channels=motion.channels)


def _close(a, b, scale=1.0) -> bool:
    return np.allclose(a, b, rtol=1e-9, atol=1e-9 * scale)


def check_forward_shape(name, model):
    """forward returns a finite float64 Motion of steps + 1 frames with the state's agents and
    dims, at the model's time step where it has one (a ``dt`` attribute)."""
    for state, context in _each(name, model):
        with context:
            for steps in (0, 1, STEPS):
                motion = _forward(model, state, steps)
                _check_motion(name, motion, state, steps, "forward")
                step = getattr(model, "dt", None)
                assert step is None or motion.dt == step, (
                    f"{name}.forward returned a Motion at dt = {motion.dt:g} s; the model's dt is {step:g} s"
                )


def check_backward_shape(name, model):
    """backward returns a finite float64 Motion of steps + 1 frames with the state's agents and dims."""
    for state, context in _each(name, model):
        with context:
            for steps in (0, 1, STEPS):
                _check_motion(name, _backward(model, state, steps), state, steps, "backward")


def check_forward_starts_at_initial(name, model):
    """The first frame of forward has the initial positions exactly, and its velocities."""
    for state, context in _each(name, model):
        with context:
            motion = _forward(model, state)
            assert np.array_equal(motion.positions[0], state.positions), (
                f"{name}.forward: frame 0 positions differ from the initial state"
            )
            assert _close(motion.velocities()[0], state.velocities), (
                f"{name}.forward: frame 0 velocities differ from the initial state"
            )


def check_backward_ends_at_final(name, model):
    """The last frame of backward has the final positions exactly, and its velocities."""
    for state, context in _each(name, model):
        with context:
            motion = _backward(model, state)
            assert np.array_equal(motion.positions[-1], state.positions), (
                f"{name}.backward: last frame positions differ from the final state"
            )
            scale = float(np.abs(state.positions).max()) / motion.dt
            assert _close(motion.velocities()[-1], state.velocities, scale), (
                f"{name}.backward: last frame velocities differ from the final state"
            )


@fixed_by(
    "simulate backward as forward does, drawing the model's random choices from `rng` (paper 004: "
    "forward from the final state with velocities and perception reversed, then time reversed); a "
    "straight line or a copy of the final state gives the sampler no choice of backward motions"
)
def check_backward_is_a_simulation(name, model):
    """backward is a simulation as forward is: where forward's motions from a flock differ between
    seeds, so do backward's to it (the sampler draws backward proposals from it)."""
    for state, context in _each(name, model):
        with context:
            forward = [_forward(model, state, seed=seed).positions for seed in (1, 2)]
            if np.array_equal(*forward):
                continue  # a model without random choices: nothing to vary
            backward = [_backward(model, state, seed=seed).positions for seed in (1, 2)]
            assert not np.array_equal(*backward), (
                f"{name}.backward gives the same motion for seeds 1 and 2, though forward's differ: it does not "
                "simulate (draw from rng)"
            )


def check_deterministic(name, model):
    """The same seeded Generator gives the same motion, forward and backward."""
    state = _flock(model)
    for operation in (_forward, _backward):
        first, second = operation(model, state, seed=7), operation(model, state, seed=7)
        assert first == second, f"{name}: two {operation.__name__[1:]} runs with the same seed differ"


def _snapshot(value):
    if isinstance(value, Motion):
        return value.positions.copy(), {k: v.copy() for k, v in value.channels.items()}
    return value.positions.copy(), value.velocities.copy(), {k: v.copy() for k, v in value.extra.items()}


def _unchanged(before, after) -> bool:
    return all(
        np.array_equal(a, b)
        if isinstance(a, np.ndarray)
        else a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
        for a, b in zip(before, after)
    )


def check_inputs_unchanged(name, model):
    """forward, backward and log_plausibility leave their inputs as they were."""
    state = _flock(model)
    motion = _forward(model, state)
    for label, value, call in (
        ("forward", state, lambda: _forward(model, state)),
        ("backward", state, lambda: _backward(model, state)),
        ("log_plausibility", motion, lambda: model.log_plausibility(motion)),
    ):
        before = _snapshot(value)
        call()
        assert _unchanged(before, _snapshot(value)), f"{name}.{label} changed its input"


def check_rejects_negative_steps(name, model):
    """A negative step count raises flockkit.errors.ValidationError."""
    state = _flock(model)
    for label, call in (("forward", model.forward), ("backward", model.backward)):
        expect_validation_error(
            lambda call=call: call(state, -1, np.random.default_rng(0)), f"{name}.{label}(steps=-1)"
        )


def check_log_plausibility_finite(name, model):
    """log_plausibility of a forward motion is a finite float64 array with one entry per frame."""
    for state, context in _each(name, model):
        with context:
            motion = _forward(model, state)
            values = model.log_plausibility(motion)
            assert isinstance(values, np.ndarray), (
                f"{name}.log_plausibility returned {type(values).__name__}, not a numpy array"
            )
            assert values.shape == (motion.n_frames,), (
                f"{name}.log_plausibility returned shape {values.shape}; expected ({motion.n_frames},)"
            )
            assert values.dtype == np.float64, f"{name}.log_plausibility returned dtype {values.dtype}"
            assert np.all(np.isfinite(values)), f"{name}.log_plausibility is not finite on a forward motion: {values}"


@fixed_by(
    "score a motion at its own time step, motion.dt (velocities are (x[t+1] - x[t]) / motion.dt), or, "
    "if the model can only score the step it simulates, raise flockkit.errors.ValidationError when "
    "motion.dt differs from it (a model whose plausibility reads positions alone, never how fast they "
    "change, lists this check in expected_failed_checks)"
)
def check_log_plausibility_at_motion_dt(name, model):
    """log_plausibility scores a motion at its own dt: the same positions (a forward motion with
    noise) labelled with twice the time step (half the speeds) score differently on some flock,
    or are refused with a ValidationError."""
    scored, dt = [], None
    for state, context in _each(name, model):
        with context:
            motion = _shaken(_forward(model, state), np.random.default_rng(SEED))
            dt = motion.dt
            slower = Motion(positions=motion.positions, dt=2 * motion.dt, channels=motion.channels)
            try:
                relabelled = np.asarray(model.log_plausibility(slower), dtype=np.float64)
            except ValidationError:
                return
            scored.append(np.allclose(np.asarray(model.log_plausibility(motion)), relabelled, rtol=1e-9, atol=0.0))
    assert not all(scored), (
        f"{name}.log_plausibility gives the same values for each noisy forward motion at dt = {dt:g} s as for its "
        f"positions at dt = {2 * dt:g} s: it reads a time step of its own instead of motion.dt"
    )


@fixed_by(
    "return every agent in every frame whatever the flock (a lone agent, agents on one spot or on a "
    "line, agents at rest); guard every division by a distance, a speed or a count of neighbours; "
    "break ties between equally near neighbours the same way every time"
)
def check_degenerate_flocks(name, model):
    """Tied and symmetric flocks (a square, a hexagon, a grid, agents on one spot, pairs of
    coincident agents, a lone agent, agents on a line; at rest, heading one way, turning) go
    forward and backward to finite motions of the right shape, which log_plausibility scores
    with finite values."""
    from .inputs import degenerate_configurations

    for d in dims_of(model):
        for label, config in degenerate_configurations(d):
            state = State(positions=config.positions, velocities=config.velocities)
            with on_input(name, model, d, label):
                for operation, run in (("forward", _forward), ("backward", _backward)):
                    motion = run(model, state, steps=6)
                    _check_motion(name, motion, state, 6, operation)
                    values = np.asarray(model.log_plausibility(motion))
                    assert values.shape == (motion.n_frames,) and np.all(np.isfinite(values)), (
                        f"{name}.log_plausibility of its {operation} motion from {label} is not finite: {values}"
                    )


def check_log_plausibility_prefers_forward(name, model):
    """On average a forward motion is more plausible than the same motion with positional noise."""
    rng = np.random.default_rng(SEED)
    clean, noisy = [], []
    for index, state in enumerate(_flocks(model)):
        motion = _forward(model, state, steps=30, seed=index)
        shaken = _shaken(motion, rng)
        clean.append(float(np.sum(model.log_plausibility(motion))))
        noisy.append(float(np.sum(model.log_plausibility(shaken))))
    assert np.mean(clean) > np.mean(noisy), (
        f"{name}.log_plausibility does not prefer forward motions: mean {np.mean(clean):.4g} for forward motions, "
        f"{np.mean(noisy):.4g} for the same with noise"
    )


def check_log_plausibility_window(name, model):
    """log_plausibility(motion, start, stop) equals log_plausibility(motion)[start:stop]."""
    rng = np.random.default_rng(SEED)
    for state, context in _each(name, model):
        with context:
            motion = _forward(model, state, steps=20)
            full = np.asarray(model.log_plausibility(motion))
            t = motion.n_frames
            windows = [(0, t), (0, 0), (t, t), (0, 1), (t - 1, t), (1, 3)]
            windows += [tuple(sorted(int(i) for i in rng.integers(0, t + 1, 2))) for _ in range(6)]
            for start, stop in windows:
                part = np.asarray(model.log_plausibility(motion, start, stop))
                scale = max(1.0, float(np.abs(full).max(initial=0.0)))
                assert part.shape == (stop - start,) and _close(part, full[start:stop], scale), (
                    f"{name}.log_plausibility(motion, {start}, {stop}) differs from the full evaluation's slice"
                )


def check_rejects_bad_window(name, model):
    """A window outside the motion raises flockkit.errors.ValidationError."""
    motion = _forward(model, _flock(model))
    for start, stop in ((3, 2), (0, motion.n_frames + 1), (-1, 2)):
        expect_validation_error(
            lambda start=start, stop=stop: model.log_plausibility(motion, start, stop),
            f"{name}.log_plausibility(start={start}, stop={stop})",
        )


@applies_when("guide")
def check_guide(name, model):
    """A model declaring ``guide`` keeps each guided agent on its path (frames 1.. of forward, and
    all but the last of backward, whose path is given in forward time) and lets the others move."""
    state = _flock(model)
    rng = np.random.default_rng(SEED + 1)
    path = state.positions[0] + np.cumsum(rng.normal(0.1, 0.05, (STEPS + 1, state.dims)), axis=0)
    forward = model.forward(state, STEPS, np.random.default_rng(0), guide={0: path})
    assert np.allclose(forward.positions[1:, 0], path[1:], rtol=0, atol=1e-9), (
        f"{name}.forward(guide={{0: path}}) does not keep agent 0 on its path"
    )
    backward = model.backward(state, STEPS, np.random.default_rng(0), guide={0: path})
    assert np.allclose(backward.positions[:-1, 0], path[:-1], rtol=0, atol=1e-9), (
        f"{name}.backward(guide={{0: path}}) does not keep agent 0 on its path"
    )


@applies_when("group_guide")
def check_group_guide(name, model):
    """A model declaring ``group_guide`` steers a group's center of mass along its path: sent along
    its own unguided course shifted sideways by the flock's radius over the simulation, the group
    ends nearer the path's end than it does unguided (the same generator seed)."""
    state = _flock(model)
    steps = 4 * STEPS
    free = model.forward(state, steps, np.random.default_rng(0)).positions.mean(axis=1)
    radius = float(np.max(np.linalg.norm(state.positions - state.positions.mean(axis=0), axis=1))) or 1.0
    offset = np.zeros(state.dims)
    offset[-1] = radius
    path = free + np.linspace(0.0, 1.0, steps + 1)[:, None] * offset
    agents = np.arange(state.n_agents)
    guided = model.forward(state, steps, np.random.default_rng(0), group_guide=[(agents, path)]).positions
    miss, unguided_miss = np.linalg.norm(guided[-1].mean(axis=0) - path[-1]), np.linalg.norm(offset)
    assert miss < 0.9 * unguided_miss, (
        f"{name}.forward(group_guide=...) ends {miss:.3g} from its path's end, not nearer than 0.9 times unguided "
        f"({unguided_miss:.3g})"
    )


@applies_when("progress")
def check_progress(name, model):
    """A model declaring ``progress`` reports (done, total, stage) as it simulates, done rising to
    total, and simulates the same motion as without a report."""
    state = _flock(model)
    for label, operation in (("forward", model.forward), ("backward", model.backward)):
        calls = []
        reported = operation(
            state, STEPS, np.random.default_rng(3), progress=lambda *args, calls=calls: calls.append(args)
        )
        assert calls, f"{name}.{label}(progress=...) never called progress"
        done = [c[0] for c in calls]
        assert all(len(c) == 3 and isinstance(c[2], str) for c in calls), (
            f"{name}.{label} must call progress(done, total, stage); got {calls[0]}"
        )
        assert done == sorted(done) and done[-1] == calls[-1][1], (
            f"{name}.{label}: progress must rise to its total; got done {done[:3]}... of {calls[-1][1]}"
        )
        assert reported == operation(state, STEPS, np.random.default_rng(3)), (
            f"{name}.{label} simulates another motion when it reports progress"
        )


@applies_when("plausibility_reach")
def check_plausibility_reach(name, model):
    """A change at one frame changes log_plausibility only within the declared reach of it."""
    from ..interfaces import capabilities

    reach = capabilities(model).plausibility_reach
    state = _flock(model)
    motion = _forward(model, state, steps=24)
    before = np.asarray(model.log_plausibility(motion))
    for frame in (1, 12, motion.n_frames - 2):
        positions = np.array(motion.positions)
        positions[frame, 0] += 0.05
        after = np.asarray(model.log_plausibility(Motion(positions=positions, dt=motion.dt, channels=motion.channels)))
        outside = np.abs(np.arange(motion.n_frames) - frame) > reach
        changed = np.flatnonzero(outside & ~np.isclose(after, before, rtol=1e-12, atol=1e-12))
        assert not len(changed), (
            f"{name} declares plausibility_reach={reach}, but moving agent 0 at frame {frame} changes "
            f"log_plausibility at frame {int(changed[0])}"
        )


@applies_when("residuals")
def check_residuals(name, model):
    """plausibility_residuals gives (stop - start, N, K) finite arrays, a window's rows equal
    to the full evaluation's, and log_plausibility minus half their summed squares is the same
    constant per frame for any two motions (the residuals are what plausibility scores)."""
    state = _flock(model)
    motion = _forward(model, state, steps=STEPS)
    rng = np.random.default_rng(SEED)
    moved = Motion(positions=motion.positions + rng.normal(0.0, 0.02, motion.positions.shape), dt=motion.dt,
                   channels=motion.channels)  # fmt: skip
    offsets = []
    for m in (motion, moved):
        residuals = np.asarray(model.plausibility_residuals(m))
        assert residuals.ndim == 3 and residuals.shape[:2] == (m.n_frames, m.n_agents), (
            f"{name}.plausibility_residuals must be (frames, agents, K); got shape {residuals.shape}"
        )
        assert np.all(np.isfinite(residuals)), f"{name}.plausibility_residuals returned non-finite values"
        window = np.asarray(model.plausibility_residuals(m, 3, 8))
        assert np.allclose(window, residuals[3:8], rtol=1e-9, atol=1e-9), (
            f"{name}.plausibility_residuals(motion, 3, 8) differs from frames 3..7 of the full evaluation"
        )
        offsets.append(np.asarray(model.log_plausibility(m)) + 0.5 * np.sum(residuals**2, axis=(1, 2)))
    assert np.allclose(offsets[0], offsets[1], rtol=1e-9, atol=1e-6), (
        f"{name}: log_plausibility is not minus half the summed squares of plausibility_residuals plus a "
        f"constant per frame (the difference changes with the motion at frame "
        f"{int(np.argmax(np.abs(offsets[0] - offsets[1])))})"
    )


@applies_when("coupling")
def check_coupling(name, model):
    """plausibility_coupling gives a scipy sparse (T N K, T N D) matrix with no entry for an
    agent's own positions, and where it gives an agent's residuals against another agent's
    position at a frame, they are the derivatives finite differences measure (the other agent
    moved alone), on a flock drawn closer together than it keeps itself, so short-range rules act."""
    from scipy import sparse

    motion = _forward(model, _flock(model), steps=STEPS)
    centre = motion.positions.mean(axis=1, keepdims=True)
    x = centre + 0.35 * (motion.positions - centre)
    channels = motion.channels

    def residuals(positions):
        return np.asarray(model.plausibility_residuals(Motion(positions=positions, dt=motion.dt, channels=channels)))

    base = residuals(x)
    frames, n, k = base.shape
    d = x.shape[2]
    coupling = model.plausibility_coupling(Motion(positions=x, dt=motion.dt, channels=channels))
    assert sparse.issparse(coupling) and coupling.shape == (frames * n * k, frames * n * d), (
        f"{name}.plausibility_coupling must be a scipy sparse matrix of shape {(frames * n * k, frames * n * d)}; "
        f"got {type(coupling).__name__} of shape {getattr(coupling, 'shape', None)}"
    )
    given = sparse.csc_matrix(coupling)
    given.eliminate_zeros()
    row_agent = (np.arange(frames * n * k) // k) % n
    step = 1e-6
    for column in np.unique(given.nonzero()[1]):
        frame, agent, dim = np.unravel_index(column, (frames, n, d))
        entries = given[:, column].toarray().ravel()
        assert not np.any(entries[row_agent == agent]), (
            f"{name}.plausibility_coupling has entries for agent {agent}'s own position (frame {frame}); it "
            "gives how residuals follow other agents' positions"
        )
        moved = x.copy()
        moved[frame, agent, dim] += step
        measured = ((residuals(moved) - base) / step).ravel()
        rows = np.isin(row_agent, np.unique(row_agent[entries != 0]))  # the agents it gives, whole
        error = np.max(np.abs(measured[rows] - entries[rows]))
        assert error <= 1e-3 * max(1.0, np.max(np.abs(measured[rows]))), (
            f"{name}.plausibility_coupling differs from finite differences by {error:.3g} for agent {agent}'s "
            f"position at frame {frame} (dimension {dim})"
        )


CHECKS = (
    check_forward_shape,
    check_backward_shape,
    check_forward_starts_at_initial,
    check_backward_ends_at_final,
    check_backward_is_a_simulation,
    check_deterministic,
    check_inputs_unchanged,
    check_rejects_negative_steps,
    check_log_plausibility_finite,
    check_log_plausibility_at_motion_dt,
    check_degenerate_flocks,
    check_log_plausibility_prefers_forward,
    check_log_plausibility_window,
    check_rejects_bad_window,
    check_guide,
    check_group_guide,
    check_progress,
    check_plausibility_reach,
    check_residuals,
    check_coupling,
)
