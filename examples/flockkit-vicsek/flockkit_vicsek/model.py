"""Vicsek-style flocking: constant speed, heading = neighbors' mean heading plus noise.

At frame t >= 1 each agent takes the mean unit heading m of the agents within `radius` (itself
included, headings as they arrived at frame t), adds a Gaussian perturbation xi perpendicular to m
(standard deviation `noise` per direction), and moves at `speed` along unit(m + xi). Frame 0 drifts
with the initial velocity. Given positions, xi = d / (d . m) - m where d is the new heading, so the
plausibility is the Gaussian log density of the inferred xi.
"""

import math

import numpy as np
from scipy.spatial import cKDTree

import flockkit
from flockkit.errors import ValidationError


def _unit(vectors):
    norms = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.divide(vectors, norms, out=np.zeros_like(vectors), where=norms > 0)


class Vicsek:
    """Parameters: dt (seconds per frame), speed, radius (neighborhood), noise (heading noise)."""

    def __init__(self, dt=0.1, speed=1.0, radius=2.0, noise=0.2):
        for name, value in (("dt", dt), ("speed", speed), ("radius", radius), ("noise", noise)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValidationError(f"vicsek parameter {name} must be a finite number > 0; got {value!r}")
        self.dt, self.speed, self.radius, self.noise = float(dt), float(speed), float(radius), float(noise)

    def forward(self, initial, steps, rng):
        return flockkit.Motion(positions=self._run(initial.positions, initial.velocities, steps, rng), dt=self.dt)

    def backward(self, final, steps, rng):
        positions = self._run(final.positions, -final.velocities, steps, rng)
        return flockkit.Motion(positions=positions[::-1], dt=self.dt)

    def log_plausibility(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        if not (isinstance(start, int) and isinstance(stop, int) and 0 <= start <= stop <= motion.n_frames):
            raise ValidationError(f"vicsek: window start={start}, stop={stop} must lie in 0..{motion.n_frames}")
        x, values = motion.positions, np.zeros(stop - start)
        dims = motion.dims
        log_norm = 0.5 * (dims - 1) * math.log(2 * math.pi * self.noise**2)
        for t in range(max(start, 1), min(stop, motion.n_frames - 1)):
            mean = self._mean_heading(x[t], (x[t] - x[t - 1]) / motion.dt)
            heading = _unit((x[t + 1] - x[t]) / motion.dt)
            cosine = np.einsum("nd,nd->n", heading, mean)
            if np.any(cosine <= 0):
                values[t - start] = -np.inf  # a turn of 90 degrees or more: impossible for this model
                continue
            xi = heading / cosine[:, None] - mean
            values[t - start] = float(np.sum(-np.sum(xi**2, axis=1) / (2 * self.noise**2) - log_norm))
        return values

    def _run(self, x0, v0, steps, rng):
        if not isinstance(steps, int) or steps < 0:
            raise ValidationError(f"vicsek: steps must be an integer >= 0; got {steps!r}")
        positions = np.empty((steps + 1, *x0.shape))
        positions[0] = x0
        velocity = np.array(v0)
        for t in range(steps):
            if t > 0:
                mean = self._mean_heading(positions[t], velocity)
                xi = self.noise * rng.standard_normal(x0.shape)
                xi -= np.einsum("nd,nd->n", xi, mean)[:, None] * mean
                velocity = self.speed * _unit(mean + xi)
            positions[t + 1] = positions[t] + velocity * self.dt
            velocity = (positions[t + 1] - positions[t]) / self.dt
        return positions

    def _mean_heading(self, x, v):
        headings = _unit(v)
        headings[~headings.any(axis=1), 0] = 1.0  # an agent at rest counts as heading along +x
        total = headings.copy()
        pairs = cKDTree(x).query_pairs(self.radius, output_type="ndarray")
        for axis in range(x.shape[1]):
            total[:, axis] += np.bincount(pairs[:, 0], headings[pairs[:, 1], axis], minlength=len(x))
            total[:, axis] += np.bincount(pairs[:, 1], headings[pairs[:, 0], axis], minlength=len(x))
        mean = _unit(total)
        cancelled = ~mean.any(axis=1)
        mean[cancelled] = headings[cancelled]
        return mean
