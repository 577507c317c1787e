"""The Vicsek model (Vicsek et al. 1995, "Novel type of phase transition in a system of
self-driven particles"): agents in the plane move at constant speed, and at every step each takes
the mean heading of the agents within `radius` (itself included), turned by Gaussian angular noise.

At frame t >= 1, with u_j the unit headings the agents arrived at frame t with,

    theta_i = arg(sum of u_j over the neighbors j of i) + xi_i,    xi_i ~ N(0, noise) radians,

and agent i moves at `speed` along theta_i. Frame 0 drifts with the initial velocity. Given
positions, xi_i is the (wrapped) angle between the heading taken and the neighbors' mean heading,
so the plausibility is the Gaussian log density of the inferred angles.

The model is planar: it declares ``flockkit.Capabilities(dims=(2,))``, so flockkit's conformance
kit checks it on 2D flocks only, and ``flockkit.simulate(..., dims=3)`` refuses it by name.
"""

import math

import attrs
import numpy as np
from scipy.spatial import cKDTree

import flockkit
from flockkit import validate


def _positive(default):
    return validate.parameter("vicsek", default=default, minimum=0, strict=True)


@attrs.frozen(kw_only=True)
class Vicsek:
    """Parameters: dt (seconds per frame), speed, radius (of the neighborhood), noise (standard
    deviation of the heading noise, in radians)."""

    dt: float = _positive(0.1)
    speed: float = _positive(1.0)
    radius: float = _positive(2.0)
    noise: float = _positive(0.2)

    # frame t of log_plausibility reads positions t - 1 .. t + 1 only
    capabilities = flockkit.Capabilities(dims=(2,), plausibility_reach=1)

    def forward(self, initial, steps, rng):
        return flockkit.Motion(positions=self._run(initial.positions, initial.velocities, steps, rng), dt=self.dt)

    def backward(self, final, steps, rng):
        positions = self._run(final.positions, -final.velocities, steps, rng)
        return flockkit.Motion(positions=positions[::-1], dt=self.dt)

    def log_plausibility(self, motion, start=0, stop=None):
        start, stop = validate.window(motion, start, stop, owner="vicsek")
        if not math.isclose(motion.dt, self.dt, rel_tol=1e-9):  # its steps are speed x dt long
            raise flockkit.errors.ValidationError(f"vicsek: motion.dt is {motion.dt} s; this model steps {self.dt} s")
        x, values = motion.positions, np.zeros(stop - start)
        log_norm = 0.5 * math.log(2 * math.pi * self.noise**2)
        for t in range(max(start, 1), min(stop, motion.n_frames - 1)):
            mean = self._mean_angle(x[t], x[t] - x[t - 1])
            step = x[t + 1] - x[t]
            xi = np.angle(np.exp(1j * (np.arctan2(step[:, 1], step[:, 0]) - mean)))  # wrapped to (-pi, pi]
            values[t - start] = float(np.sum(-(xi**2) / (2 * self.noise**2) - log_norm))
        return values

    def _run(self, x0, v0, steps, rng):
        steps = validate.integer(steps, "vicsek: steps", minimum=0)
        positions = np.empty((steps + 1, *x0.shape))
        positions[0] = x0
        velocity = np.array(v0)
        for t in range(steps):
            if t > 0:
                angle = self._mean_angle(positions[t], velocity) + self.noise * rng.standard_normal(len(x0))
                velocity = self.speed * np.stack([np.cos(angle), np.sin(angle)], axis=1)
            positions[t + 1] = positions[t] + velocity * self.dt
            velocity = (positions[t + 1] - positions[t]) / self.dt
        return positions

    def _mean_angle(self, x, v):
        """The angle of the mean unit heading over each agent's neighbors, itself included; an
        agent at rest counts as heading along +x."""
        angles = np.where(np.hypot(v[:, 0], v[:, 1]) > 0, np.arctan2(v[:, 1], v[:, 0]), 0.0)
        pairs = cKDTree(x).query_pairs(self.radius, output_type="ndarray")
        total = np.exp(1j * angles)
        heading = total.copy()
        total += np.bincount(pairs[:, 0], heading[pairs[:, 1]].real, minlength=len(x))
        total += 1j * np.bincount(pairs[:, 0], heading[pairs[:, 1]].imag, minlength=len(x))
        total += np.bincount(pairs[:, 1], heading[pairs[:, 0]].real, minlength=len(x))
        total += 1j * np.bincount(pairs[:, 1], heading[pairs[:, 0]].imag, minlength=len(x))
        # headings that cancel out exactly keep the agent's own
        return np.where(np.abs(total) > 1e-12, np.angle(total), angles)
