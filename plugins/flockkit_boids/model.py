"""The boids behavior model of paper 004, section 3.1.

One step at frame t (1 <= t < T - 1), for every agent at once:

    wander[t]  = unit(wander[t - 1]) + impulse,   impulse = direction * length,
                 direction uniform on the unit circle/sphere, length ~ N(0, wander_sigma)
    request    = (sum over rules r of weight_r * rule_r(x[t], v[t - 1]) + wander_weight * wander[t]) / sum of weights
    v[t]       = v[t - 1] + acceleration * dt * request
    x[t + 1]   = x[t] + v[t] * dt

with v[t] = (x[t + 1] - x[t]) / dt, the Motion velocity convention. Frame 0 only drifts with the
initial velocity, so the first frame keeps the initial state exactly. Because the request is
affine in the wander contribution, the contribution (and so the impulse) of every step can be
recovered exactly from positions alone: that is `log_plausibility`.

The rules (each a dimensionless vector of order 1), over the neighbors an agent perceives (within
`perception_radius` and inside its field of view around its heading):

- separation: sum of unit vectors away from neighbors closer than `separation_radius`, each
  scaled by (1 - distance / separation_radius);
- cohesion: (neighbors' mean position - own position) / perception_radius;
- alignment: (neighbors' mean velocity - own velocity) / target_speed;
- speed: (target_speed - speed) / target_speed along the heading;
- avoidance: sum over obstacles of (outward surface normal + a sideways turn while approaching),
  scaled by clip(avoid_distance / distance - 1, 0, 19), which grows like 1 / distance near the surface.
"""

from __future__ import annotations

import math

import attrs
import numba
import numpy as np
from scipy.sparse import coo_matrix
from scipy.spatial import cKDTree

import flockkit
from flockkit import validate
from flockkit.errors import ValidationError

_WANDER = "wander"
# Seconds over which a guided group's wander is turned towards its path (group_guide). On 20 boids
# steered along a 14 s straight path the group ended 0.14-0.19 m from it with impulses like a free
# flock's (median 0.085-0.088 against 0.084); 8 s lagged by 0.8-1.9 m (bench/README.md).
GUIDE_TIME = 2.0


def _obstacles(value):
    try:
        obstacles = tuple(value)
    except TypeError:
        raise ValidationError(f"boids parameter obstacles must be a sequence of regions; got {value!r}") from None
    for index, obstacle in enumerate(obstacles):
        if not isinstance(obstacle, flockkit.Region):
            raise ValidationError(
                f"boids parameter obstacles[{index}] must be a flockkit region (Ball, Box or Polygon); "
                f"got {type(obstacle).__name__}"
            )
    return obstacles


def _positive(default):
    return validate.parameter("boids", default=default, minimum=0, strict=True)


def _non_negative(default):
    return validate.parameter("boids", default=default, minimum=0)


def _unit(vectors: np.ndarray) -> np.ndarray:
    norms = np.sqrt(np.einsum("...k,...k->...", vectors, vectors))[..., None]
    return np.divide(vectors, norms, out=np.zeros_like(vectors), where=norms > 0)


@attrs.frozen(kw_only=True)
class Boids:
    """Reynolds-style flocking with wander, as used by Anderson et al. (2003).

    Parameters
    ----------
    dt : float
        Seconds per frame (0.1: the paper samples at 10 Hz).
    perception_radius, separation_radius : float
        How far an agent sees its neighbors, and how close they must be to push it away.
    field_of_view : float
        Full angle of the perception cone in degrees, centered on the heading (360: all round).
        Backward simulation centers it on the opposite direction.
    target_speed : float
        The speed the speed rule steers to, in length units per second.
    acceleration : float
        Scale of the combined request, in length units per second squared.
    separation_weight, cohesion_weight, alignment_weight, avoidance_weight, speed_weight, wander_weight : float
        Weights of the weighted average; wander_weight must be > 0 so plausibility can be inferred.
    wander_sigma : float
        Standard deviation of the wander impulse length (sigma_w = 0.125 in the paper).
    avoid_distance : float
        Distance from an obstacle's surface at which avoidance starts.
    obstacles : sequence of flockkit.Ball, flockkit.Box or flockkit.Polygon
        Static obstacles, of the motion's dimension.
    kdtree_above : int
        Agent count above which neighbors are found with a cKDTree, frame by frame, instead of a
        compiled loop over every pair of agents (faster for small flocks).
    """

    dt: float = _positive(0.1)
    perception_radius: float = _positive(3.0)
    separation_radius: float = _positive(0.8)
    field_of_view: float = _positive(300.0)
    target_speed: float = _positive(1.0)
    acceleration: float = _positive(4.0)
    separation_weight: float = _non_negative(1.5)
    cohesion_weight: float = _non_negative(3.0)
    alignment_weight: float = _non_negative(3.0)
    avoidance_weight: float = _non_negative(3.0)
    speed_weight: float = _non_negative(6.0)
    wander_weight: float = _positive(1.0)
    wander_sigma: float = _positive(0.125)
    avoid_distance: float = _positive(1.5)
    obstacles: tuple = attrs.field(default=(), converter=_obstacles)
    kdtree_above: int = validate.parameter("boids", default=128, kind="integer", minimum=0)

    # A change at frame f alters the inferred impulses at frames f - 1 .. f + 2 (see
    # log_plausibility), so scores within 2 frames of a change.
    capabilities = flockkit.Capabilities(
        guide=True,
        group_guide=True,
        obstacles=True,
        plausibility_reach=2,
        residuals=True,
        coupling=True,
        progress=True,
    )

    def __attrs_post_init__(self):
        if self.field_of_view > 360:
            raise ValidationError(
                f"boids parameter field_of_view must be in (0, 360] degrees; got {self.field_of_view}"
            )

    # -- the three operations -------------------------------------------------------------

    def forward(
        self,
        initial: flockkit.State,
        steps: int,
        rng: np.random.Generator,
        *,
        progress=None,
        guide=None,
        group_guide=None,
    ) -> flockkit.Motion:
        """Simulate `steps` steps from `initial`; ``steps + 1`` frames, the first equal to `initial`.

        `guide` maps agent indices to (steps + 1, D) positions those agents take from frame 1 on
        (keyframed agents): the others see them there and react. `group_guide` is a sequence of
        (agents, path) pairs, path (steps + 1, D): each step adds to the group's wander impulses
        the turn that would bring its center of mass onto the path in about GUIDE_TIME seconds
        (critically damped), so the group drifts along the path by the model's own means."""
        self._check_state(initial, "initial")
        steps = _steps(steps)
        guide = self._guide(guide, steps, initial)
        group_guide = self._group_guide(group_guide, steps, initial)
        positions, wander = self._simulate(
            initial.positions,
            initial.velocities,
            self._wander_of(initial, rng),
            steps,
            rng,
            perception=1.0,
            progress=progress,
            guide=guide,
            group_guide=group_guide,
        )
        return flockkit.Motion(positions=positions, dt=self.dt, channels={_WANDER: wander})

    def backward(
        self, final: flockkit.State, steps: int, rng: np.random.Generator, *, progress=None, guide=None
    ) -> flockkit.Motion:
        """``steps + 1`` frames ending at `final`: simulate from `final` with velocities reversed and
        perception reversed (agents react to those behind them), then reverse time (004, 3.1).
        `guide` as for forward, its arrays in forward time (the last row at `final`)."""
        self._check_state(final, "final")
        steps = _steps(steps)
        guide = {agent: path[::-1] for agent, path in self._guide(guide, steps, final).items()}
        positions, wander = self._simulate(
            final.positions,
            -final.velocities,
            -self._wander_of(final, rng),
            steps,
            rng,
            perception=-1.0,
            progress=progress,
            guide=guide,
        )
        return flockkit.Motion(positions=positions[::-1], dt=self.dt, channels={_WANDER: -wander[::-1]})

    def log_plausibility(self, motion: flockkit.Motion, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Log density, summed over agents, of the wander impulses inferred at frames start..stop-1.

        Per agent, log N(|impulse|; 0, wander_sigma) as in paper 004 section 3.4.2. Frames 0 and
        T - 1 carry no impulse and contribute 0.
        """
        start, stop = self._window(motion, start, stop)
        impulses = self.wander_impulses(motion, start, stop)
        squared = np.einsum("tnd,tnd->t", impulses, impulses)
        agents = motion.n_agents
        log_norm = agents * (math.log(self.wander_sigma) + 0.5 * math.log(2 * math.pi))
        values = -squared / (2 * self.wander_sigma**2) - log_norm
        frames = np.arange(start, stop)
        return np.where((frames >= 1) & (frames <= motion.n_frames - 2), values, 0.0)

    def plausibility_residuals(self, motion: flockkit.Motion, start: int = 0, stop: int | None = None) -> np.ndarray:
        """The wander impulses over wander_sigma (stop - start, N, D): log_plausibility is minus
        half their summed squares, less the normalization."""
        return self.wander_impulses(motion, start, stop) / self.wander_sigma

    def plausibility_coupling(self, motion: flockkit.Motion) -> coo_matrix:
        """How each agent's residuals follow its neighbors' positions (Capabilities.coupling): a
        sparse (T N D, T N D) matrix, rows the residuals and columns the positions, both
        flattened (frame, agent, component).

        The contribution w_t of agent i (see log_plausibility) is (velocity change / gain - steering)
        / wander_weight, and the residual at t is (w_t - unit(w_{t-1})) / wander_sigma. Its
        steering at t reads each seen neighbor j's position at t (cohesion: + cohesion_weight /
        perception_radius / neighbors; separation: - separation_weight d g / d x_j, g(e) = (1/|e| -
        1/separation_radius) e within separation_radius) and velocity from t - 1 to t (alignment:
        alignment_weight / target_speed / neighbors). The residual at t + 1 takes the same through
        unit(w_t), whose derivative is (I - u u^T) / |w_t|. Which neighbors an agent sees and how
        many it sees are held fixed (they change only in jumps)."""
        self._window(motion, 0, None)
        x, dt = motion.positions, motion.dt
        frames, n, d = x.shape
        size = frames * n * d
        rows, columns, values = [], [], []
        wander = self._infer_wander(x, dt, 1, frames - 1) if frames > 2 else None  # frames 1 .. T - 2
        scale = 1.0 / (self.wander_weight * self.wander_sigma)
        cos_half = math.cos(math.radians(self.field_of_view) / 2)
        eye = np.eye(d)
        for t in range(1, frames - 1):
            pairs = _SparsePairs(x[t], self.perception_radius)  # who sees whom, as _steer finds it
            i, j, offset, distance = pairs.i, pairs.j, np.stack(pairs.offsets, axis=1), pairs.distances()
            if self.field_of_view < 360:  # a stationary agent sees all round
                step = x[t] - x[t - 1]
                length = np.linalg.norm(step, axis=1, keepdims=True)
                heading = np.divide(step, length, out=np.zeros_like(step), where=length > 0)
                seen = pairs.along(heading) >= distance * pairs.rows(cos_half * (length[:, 0] > 0))
                i, j, offset, distance = i[seen], j[seen], offset[seen], distance[seen]
            share = 1.0 / np.maximum(np.bincount(i, minlength=n), 1)
            if not len(i):
                continue
            pull = (
                self.cohesion_weight / self.perception_radius + self.alignment_weight / (self.target_speed * dt)
            ) * share[i]
            now = -pull[:, None, None] * eye
            near = distance < self.separation_radius
            g = (1 / distance[near] - 1 / self.separation_radius)[:, None, None] * eye
            g -= offset[near, :, None] * offset[near, None, :] / distance[near, None, None] ** 3
            now[near] += self.separation_weight * g
            before = (self.alignment_weight / (self.target_speed * dt) * share[i])[:, None, None] * eye
            blocks = [(t, t, now * scale), (t, t - 1, before * scale)]
            if t + 1 < frames - 1:  # the residual at t + 1 subtracts unit(w_t)
                w = wander[t - 1, i]
                length = np.maximum(np.linalg.norm(w, axis=1), 1e-12)
                unit = w / length[:, None]
                turn = (eye - unit[:, :, None] * unit[:, None, :]) / length[:, None, None]
                blocks += [(t + 1, t, -turn @ (now * scale)), (t + 1, t - 1, -turn @ (before * scale))]
            for frame, at, b in blocks:
                row = ((frame * n + i)[:, None] * d + np.arange(d))[:, :, None]  # (P, D, 1)
                column = ((at * n + j)[:, None] * d + np.arange(d))[:, None, :]  # (P, 1, D)
                rows.append(np.broadcast_to(row, b.shape).ravel())
                columns.append(np.broadcast_to(column, b.shape).ravel())
                values.append(b.ravel())
        if not rows:
            return coo_matrix((size, size))
        return coo_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))), shape=(size, size))

    def wander_impulses(self, motion: flockkit.Motion, start: int = 0, stop: int | None = None) -> np.ndarray:
        """The wander impulses (stop - start, N, D) a forward simulation would have drawn to produce
        `motion` at frames start..stop-1; zero at frames 0 and T - 1, which carry none.

        The contribution before frame 1 is read from the ``wander`` channel (zero if absent); every
        later one is inferred from positions, so proposals that move positions need not update it.
        """
        start, stop = self._window(motion, start, stop)
        x, dt = motion.positions, motion.dt
        impulses = np.zeros((stop - start, motion.n_agents, motion.dims))
        first, last = max(start, 1), min(stop, motion.n_frames - 1)  # frames with an impulse
        if first >= last:
            return impulses
        inferred = self._infer_wander(x, dt, first - 1 if first > 1 else first, last)  # frames .. last - 1
        if first == 1:
            channel = motion.channels.get(_WANDER)
            previous = channel[0] if channel is not None else np.zeros(x.shape[1:])
            inferred = np.concatenate([previous[None], inferred])
        impulses[first - start : last - start] = inferred[1:] - _unit(inferred[:-1])
        return impulses

    # -- internals -------------------------------------------------------------------------

    @property
    def _weight_sum(self) -> float:
        return (
            self.separation_weight
            + self.cohesion_weight
            + self.alignment_weight
            + self.avoidance_weight
            + self.speed_weight
            + self.wander_weight
        )

    def _check_state(self, state, name):
        if not isinstance(state, flockkit.State):
            raise ValidationError(f"boids: {name} must be a flockkit.State; got {type(state).__name__}")
        for index, obstacle in enumerate(self.obstacles):
            if obstacle.dims != state.dims:
                raise ValidationError(
                    f"boids: obstacles[{index}] is {obstacle.dims}D but the {name} state is {state.dims}D"
                )

    def _wander_of(self, state, rng) -> np.ndarray:
        """The state's wander contribution; a state without one starts from random unit vectors
        (a zero start would make the first impulse's direction ill-conditioned to infer)."""
        if _WANDER in state.extra:
            return np.array(state.extra[_WANDER])
        return _unit(rng.standard_normal(state.positions.shape))

    def _window(self, motion, start, stop) -> tuple[int, int]:
        start, stop = validate.window(motion, start, stop, owner="boids")
        if not math.isclose(motion.dt, self.dt, rel_tol=1e-9):
            raise ValidationError(f"boids: motion.dt is {motion.dt} s but this model steps dt = {self.dt} s")
        return start, stop

    def _guide(self, guide, steps, state) -> dict:
        if guide is None:
            return {}
        checked = {}
        for agent, path in dict(guide).items():
            if isinstance(agent, bool) or not isinstance(agent, (int, np.integer)) or not 0 <= agent < state.n_agents:
                raise ValidationError(f"boids: guide keys must be agent indices below {state.n_agents}; got {agent!r}")
            checked[int(agent)] = _checked_path(path, steps, state, f"guide[{agent}]")
        return checked

    def _group_guide(self, group_guide, steps, state) -> list:
        checked = []
        for index, pair in enumerate(group_guide or ()):
            try:
                agents, path = pair
                agents = np.asarray(agents)
            except (TypeError, ValueError):
                raise ValidationError(f"boids: group_guide[{index}] must be an (agents, path) pair") from None
            if (
                agents.ndim != 1
                or not len(agents)
                or not np.issubdtype(agents.dtype, np.integer)
                or agents.min() < 0
                or agents.max() >= state.n_agents
            ):
                raise ValidationError(
                    f"boids: group_guide[{index}] agents must be agent indices below {state.n_agents}; got {agents!r}"
                )
            checked.append((agents, _checked_path(path, steps, state, f"group_guide[{index}] path")))
        return checked

    def _check_memory(self, x) -> None:
        """Refuse, before simulating, a flock whose neighbor pairs would not fit in memory: pairs
        expected at the flock's mean density, about 20 numbers each (offsets, distances, weights)."""
        n, d = x.shape
        if n <= self.kdtree_above:
            return
        extent = np.maximum(np.ptp(x, axis=0), self.perception_radius)
        reach = (math.pi if d == 2 else 4 * math.pi / 3) * self.perception_radius**d
        pairs = n * min(n - 1, n * reach / float(np.prod(extent)))
        validate.allocation(20 * pairs, f"boids: finding the neighbors of {n} agents in {d}D")

    @np.errstate(over="ignore", invalid="ignore")  # overflow is reported as an error at the end
    def _simulate(self, x0, v0, wander0, steps, rng, *, perception, progress, guide=None, group_guide=None):
        n, d = x0.shape
        if steps > 1:
            self._check_memory(x0)
        positions = np.empty((steps + 1, n, d))
        wander = np.empty_like(positions)
        positions[0], wander[0] = x0, wander0
        gain = self.acceleration * self.dt / self._weight_sum
        velocity = np.array(v0)
        for t in range(steps):
            if t > 0:
                direction = _unit(rng.standard_normal((n, d)))
                impulse = direction * rng.normal(0.0, self.wander_sigma, (n, 1))
                for agents, path in group_guide or ():
                    impulse[agents] += self._towards(path, t, positions[t, agents], velocity[agents])
                wander[t] = _unit(wander[t - 1]) + impulse
                steer = self._steering(positions[t], velocity, perception)
                velocity = velocity + gain * (steer + self.wander_weight * wander[t])
            else:
                wander[t] = wander0
            positions[t + 1] = positions[t] + velocity * self.dt
            for agent, path in (guide or {}).items():
                positions[t + 1, agent] = path[t + 1]
            # Continue from the velocity the positions imply, exactly as inference will see it.
            velocity = (positions[t + 1] - positions[t]) / self.dt
            if progress is not None:
                progress(t + 1, steps, "simulating")
        if steps:
            wander[steps] = wander[steps - 1]
        if not np.all(np.isfinite(positions)):
            first = int(np.argmin(np.all(np.isfinite(positions), axis=(1, 2))))
            raise ValidationError(
                f"boids: the simulation overflowed at step {first} (dt = {self.dt:g} s, acceleration "
                f"{self.acceleration:g}); use a smaller dt"
            )
        return positions, wander

    def _towards(self, path, t, x, v) -> np.ndarray:
        """The impulse turning a group's wander towards its path at step t: the acceleration that
        brings its center of mass onto the path in about GUIDE_TIME (critically damped), as the
        wander that makes it, spread over GUIDE_TIME (a turn, not an offset: the wander is renormalized
        every step, so an offset would be paid again at every frame)."""
        miss = path[t] - x.mean(axis=0)
        late = (path[t + 1] - path[t]) / self.dt - v.mean(axis=0)
        wanted = miss / GUIDE_TIME**2 + 2 * late / GUIDE_TIME
        return wanted * self._weight_sum / (self.acceleration * self.wander_weight) * self.dt / GUIDE_TIME

    def _infer_wander(self, x, dt, first, last) -> np.ndarray:
        """The wander contributions at frames first..last-1 (1 <= t <= T - 2) implied by the
        frames around each, (last - first, N, D)."""
        before = (x[first:last] - x[first - 1 : last - 1]) / dt
        after = (x[first + 1 : last + 1] - x[first:last]) / dt
        gain = self.acceleration * dt / self._weight_sum
        return ((after - before) / gain - self._steering(x[first:last], before, 1.0)) / self.wander_weight

    def _steering(self, x, v, perception: float) -> np.ndarray:
        """Sum of weight * rule over every rule but wander, for positions x and headings v, (N, D)
        or (F, N, D) for F frames at once: small flocks by a compiled loop over every pair of each
        frame (``_steer_pairs``), large ones frame by frame (a cKDTree pair list, memory linear
        in N)."""
        n = x.shape[-2]
        if n > self.kdtree_above:
            if x.ndim == 2:
                return self._steer(x, v, perception)
            if not len(x):
                return np.zeros_like(x)
            return np.stack([self._steer(a, b, perception) for a, b in zip(x, v)])
        padded = np.zeros((2, math.prod(x.shape[:-1]) // n if n else 0, n, 3))
        padded[0, ..., : x.shape[-1]] = x.reshape(-1, n, x.shape[-1])
        padded[1, ..., : x.shape[-1]] = v.reshape(-1, n, x.shape[-1])
        steer = _steer_pairs(padded[0], padded[1], self._rule_constants(perception))
        steer = np.ascontiguousarray(steer[..., : x.shape[-1]]).reshape(x.shape)
        self._avoid(steer, x, v)
        return steer

    def _rule_constants(self, perception: float) -> np.ndarray:
        """The rules' constants as ``_steer_pairs`` reads them."""
        cos_half = math.cos(math.radians(self.field_of_view) / 2) if self.field_of_view < 360 else -2.0
        return np.array([
            self.perception_radius, self.separation_radius, cos_half, perception,
            self.cohesion_weight, self.separation_weight, self.alignment_weight, self.speed_weight,
            self.target_speed,
        ])  # fmt: skip

    def _avoid(self, steer, x, v) -> None:
        """Add the avoidance rule to `steer` in place (see ``_steer``)."""
        if not self.obstacles:
            return
        speed = np.sqrt(np.einsum("...k,...k->...", v, v))[..., None]
        heading = np.divide(v, speed, out=np.zeros_like(v), where=speed > 0)
        for obstacle in self.obstacles:
            distance = obstacle.signed_distance(x)
            # Grows like 1 / distance near the surface so that no other rule can push an agent in;
            # saturates at 1/20 of avoid_distance (19 = 20 - 1) so the push stays finite there.
            closeness = np.clip(self.avoid_distance / np.maximum(distance, 0.05 * self.avoid_distance) - 1.0, 0.0, 19.0)
            if closeness.any():
                normal = obstacle.surface_normal(x)
                along = np.sum(normal * heading, axis=-1)
                sideways = _unit(normal - along[..., None] * heading)  # steer round, not just brake
                away = normal + np.maximum(0.0, -along)[..., None] * sideways
                steer += self.avoidance_weight * closeness[..., None] * away

    def _steer(self, x, v, perception: float) -> np.ndarray:
        """The steering of one frame (N, D) of a large flock, from a cKDTree's pair list."""
        dims = x.shape[-1]
        speed = np.sqrt(np.einsum("...k,...k->...", v, v))[..., None]
        heading = np.divide(v, speed, out=np.zeros_like(v), where=speed > 0)
        pairs = _SparsePairs(x, self.perception_radius)
        distance = pairs.distances()
        seen = distance <= self.perception_radius
        if self.field_of_view < 360:  # a stationary agent sees all round
            cos_half = math.cos(math.radians(self.field_of_view) / 2) * (speed[..., 0] > 0)
            seen &= pairs.along(perception * heading) >= distance * pairs.rows(cos_half)
        seen = seen.astype(np.float64)
        # Per pair: cohesion pulls along the offset, separation pushes against it, alignment
        # averages neighbors' velocities. Cohesion and alignment weigh every seen neighbor alike,
        # so they need only the sums over seen neighbors of positions and velocities (one product):
        # steer_i = pull_i sum_j (x_j - x_i) - separation sum_j push_ij (x_j - x_i) + align_i sum_j v_j - ...
        push = 1.0 - distance * (1.0 / self.separation_radius)
        np.maximum(push, 0.0, out=push)  # 0 beyond the radius
        push /= np.maximum(distance, 1e-12)
        push *= seen
        count = pairs.total(seen)[..., None]
        share = np.divide(1.0, count, out=np.zeros(count.shape), where=count > 0)
        sums = pairs.weighted_sum(seen, np.concatenate([x, v], axis=-1))
        steer = (self.cohesion_weight / self.perception_radius * share) * (sums[..., :dims] - count * x)
        steer -= self.separation_weight * (pairs.weighted_sum(push, x) - pairs.total(push)[..., None] * x)
        steer += (self.alignment_weight / self.target_speed) * (share * sums[..., dims:] - (count > 0) * v)
        steer += (self.speed_weight / self.target_speed) * (self.target_speed - speed) * heading
        self._avoid(steer, x, v)
        return steer


@numba.njit(cache=True, nogil=True, inline="always")
def _add(sums, i, x, v, f, j, push):
    """Agent j, seen by agent i at frame f, into i's sums (see ``_steer_pairs``)."""
    sums[i, 0] += 1.0
    for k in range(3):
        sums[i, 1 + k] += x[f, j, k]
        sums[i, 4 + k] += v[f, j, k]
    if push > 0:
        sums[i, 7] += push
        for k in range(3):
            sums[i, 8 + k] += push * x[f, j, k]


@numba.njit(cache=True, nogil=True)
def _steer_pairs(x, v, constants):
    """``_steer``'s rules but avoidance for F frames of N agents, positions and velocities
    (F, N, 3) (2D ones padded with a zero z, which changes no sum), every pair of a frame in one
    compiled loop: N x N tables would cost a pass over memory per operation. At 50 agents a frame
    took 30 us with such tables and takes about 8 us here. `constants`: perception and
    separation radii, cos(field of view / 2) (-2: all round), the perception's sign (-1:
    backward), the cohesion, separation, alignment and speed weights, and the target speed."""
    radius, separation, cos_half, sign, cohesion, apart, alignment, speed_weight, target = constants
    frames, n = x.shape[0], x.shape[1]
    steer = np.zeros_like(x)
    reach = radius * radius
    fov = cos_half > -1.5
    heading = np.zeros((n, 3))
    speed = np.zeros(n)
    limit = np.zeros(n)
    sums = np.zeros((n, 11))  # per agent: count, positions, velocities, pushes, pushed positions
    for f in range(frames):
        for i in range(n):
            speed[i] = math.sqrt(v[f, i, 0] ** 2 + v[f, i, 1] ** 2 + v[f, i, 2] ** 2)
            limit[i] = cos_half if speed[i] > 0 else 0.0
            for k in range(3):
                heading[i, k] = sign * v[f, i, k] / speed[i] if speed[i] > 0 else 0.0
        sums[:] = 0.0
        # each pair once, for both of its agents; every agent still adds its neighbours in index order
        for i in range(n):
            xi, yi, zi = x[f, i, 0], x[f, i, 1], x[f, i, 2]
            for j in range(i + 1, n):
                ox, oy, oz = x[f, j, 0] - xi, x[f, j, 1] - yi, x[f, j, 2] - zi
                squared = ox * ox + oy * oy + oz * oz
                if squared > reach:
                    continue
                distance = math.sqrt(squared)
                push = (1.0 - distance * (1.0 / separation)) / max(distance, 1e-12) if distance < separation else 0.0
                if not fov or ox * heading[i, 0] + oy * heading[i, 1] + oz * heading[i, 2] >= distance * limit[i]:
                    _add(sums, i, x, v, f, j, push)
                if not fov or -(ox * heading[j, 0] + oy * heading[j, 1] + oz * heading[j, 2]) >= distance * limit[j]:
                    _add(sums, j, x, v, f, i, push)
        for i in range(n):
            count = sums[i, 0]
            share = 1.0 / count if count > 0 else 0.0
            seen = 1.0 if count > 0 else 0.0
            pull = cohesion / radius * share
            ahead = speed_weight / target * (target - speed[i]) * sign
            for k in range(3):
                own = x[f, i, k]
                steer[f, i, k] = (
                    pull * (sums[i, 1 + k] - count * own)
                    - apart * (sums[i, 8 + k] - sums[i, 7] * own)
                    + alignment / target * (share * sums[i, 4 + k] - seen * v[f, i, k])
                    + ahead * heading[i, k]
                )
    return steer


class _SparsePairs:
    """Directed pairs (i, j) closer than the radius, from a cKDTree; arrays are one value per pair."""

    def __init__(self, x, radius):
        pairs = cKDTree(x).query_pairs(radius, output_type="ndarray")
        self.i = np.concatenate([pairs[:, 0], pairs[:, 1]])
        self.j = np.concatenate([pairs[:, 1], pairs[:, 0]])
        self._x = x
        self.offsets = [c[self.j] - c[self.i] for c in x.T]

    def distances(self):
        return np.sqrt(sum(o * o for o in self.offsets))  # no pair of an agent and itself

    def along(self, direction):
        return sum(o * direction[self.i, k] for k, o in enumerate(self.offsets))

    def rows(self, values):
        return values[self.i]

    def total(self, values):
        return np.bincount(self.i, values, minlength=len(self._x))

    def weighted_sum(self, weights, y):
        return np.stack([self.total(weights * c[self.j]) for c in y.T], axis=1)


def _checked_path(path, steps, state, where) -> np.ndarray:
    """`path` as finite float positions (steps + 1, D) of a guide, else a ValidationError naming it."""
    try:
        path = np.asarray(path, dtype=np.float64)
    except (TypeError, ValueError):
        path = np.empty(0)
    if path.shape != (steps + 1, state.dims) or not np.all(np.isfinite(path)):
        raise ValidationError(
            f"boids: {where} must be finite positions of shape {(steps + 1, state.dims)}; got {path.shape}"
        )
    return path


def _steps(steps) -> int:
    return validate.integer(steps, "boids: steps", minimum=0)
