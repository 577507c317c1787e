"""A small correct behavior model and one broken variant per behavior check of the kit."""

from __future__ import annotations

import math

import numpy as np

import flockkit
from flockkit.errors import ValidationError


class RandomVelocity:
    """Velocity random walk: v[t] = v[t-1] + sigma * noise, x[t+1] = x[t] + v[t] * dt (frame 0 drifts).

    Its plausibility is the Gaussian log density of the inferred noise: a correct, minimal model.
    """

    sigma = 0.05

    def __init__(self, dt=0.1):
        self.dt = dt

    def _steps(self, steps):
        if not isinstance(steps, int) or steps < 0:
            raise ValidationError(f"steps must be an integer >= 0; got {steps!r}")

    def _run(self, x0, v0, steps, rng):
        positions = np.empty((steps + 1, *x0.shape))
        positions[0] = x0
        velocity = np.array(v0)
        for t in range(steps):
            if t > 0:
                velocity = velocity + self.sigma * rng.standard_normal(x0.shape)
            positions[t + 1] = positions[t] + velocity * self.dt
            velocity = (positions[t + 1] - positions[t]) / self.dt
        return positions

    def forward(self, initial, steps, rng):
        self._steps(steps)
        return flockkit.Motion(positions=self._run(initial.positions, initial.velocities, steps, rng), dt=self.dt)

    def backward(self, final, steps, rng):
        self._steps(steps)
        return flockkit.Motion(positions=self._run(final.positions, -final.velocities, steps, rng)[::-1], dt=self.dt)

    def log_plausibility(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        if not 0 <= start <= stop <= motion.n_frames:
            raise ValidationError(f"window {start}:{stop} outside 0..{motion.n_frames}")
        values = np.zeros(stop - start)
        velocities = np.diff(motion.positions, axis=0) / motion.dt
        for t in range(max(start, 1), min(stop, motion.n_frames - 1)):
            noise = (velocities[t] - velocities[t - 1]) / self.sigma
            values[t - start] = -0.5 * float(np.sum(noise**2)) - noise.size * 0.5 * math.log(2 * math.pi)
        return values


class MissingMethod:
    """Breaks check_interface: no backward at all."""

    forward = RandomVelocity.forward
    log_plausibility = RandomVelocity.log_plausibility


class OffByOneFrames(RandomVelocity):
    def forward(self, initial, steps, rng):
        return super().forward(initial, max(steps - 1, 0), rng)


class BackwardOffByOne(RandomVelocity):
    def backward(self, final, steps, rng):
        return super().backward(final, steps + 1, rng)


class ShiftedStart(RandomVelocity):
    def forward(self, initial, steps, rng):
        motion = super().forward(initial, steps, rng)
        return flockkit.Motion(positions=motion.positions + 1e-3, dt=motion.dt)


class BackwardEndsElsewhere(RandomVelocity):
    def backward(self, final, steps, rng):
        return super().forward(final, steps, rng)


class GlobalRandomness(RandomVelocity):
    """Ignores rng and draws from a fresh, unseeded generator."""

    def forward(self, initial, steps, rng):
        return super().forward(initial, steps, np.random.default_rng())


class MutatesInput(RandomVelocity):
    def forward(self, initial, steps, rng):
        initial.positions.setflags(write=True)
        initial.positions[0, 0] += 1.0
        return super().forward(initial, steps, rng)


class AcceptsNegativeSteps(RandomVelocity):
    def _steps(self, steps):
        pass

    def forward(self, initial, steps, rng):
        return super().forward(initial, max(steps, 0), rng)

    def backward(self, final, steps, rng):
        return super().backward(final, max(steps, 0), rng)


class NonFinitePlausibility(RandomVelocity):
    def log_plausibility(self, motion, start=0, stop=None):
        values = super().log_plausibility(motion, start, stop)
        return np.where(np.arange(start, start + len(values)) == 1, -np.inf, values)


class PrefersNoise(RandomVelocity):
    def log_plausibility(self, motion, start=0, stop=None):
        return -super().log_plausibility(motion, start, stop)


class WindowIgnored(RandomVelocity):
    """Returns the right length but always scores from frame 0."""

    def log_plausibility(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        if not 0 <= start <= stop <= motion.n_frames:
            raise ValidationError("bad window")
        return super().log_plausibility(motion)[: stop - start]


class WindowUnchecked(RandomVelocity):
    def log_plausibility(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        full = super().log_plausibility(motion)
        return np.resize(full[max(start, 0) : stop], max(stop - start, 0))


# check name -> a fake that breaks exactly that check
BROKEN = {
    "check_interface": MissingMethod,
    "check_forward_shape": OffByOneFrames,
    "check_backward_shape": BackwardOffByOne,
    "check_forward_starts_at_initial": ShiftedStart,
    "check_backward_ends_at_final": BackwardEndsElsewhere,
    "check_deterministic": GlobalRandomness,
    "check_inputs_unchanged": MutatesInput,
    "check_rejects_negative_steps": AcceptsNegativeSteps,
    "check_log_plausibility_finite": NonFinitePlausibility,
    "check_log_plausibility_prefers_forward": PrefersNoise,
    "check_log_plausibility_window": WindowIgnored,
    "check_rejects_bad_window": WindowUnchecked,
}
