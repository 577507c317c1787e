"""Constrained flocks within the model's reach: the shipped scenarios over seeds, the keyframed
weight's trade-off, and the speed of a default solve end to end.

    python -W ignore bench/scenarios.py [--seeds 1-5] [--only NAME] [--skip-tradeoff] [--skip-speed]

1. Every scenario in examples/scenarios, a default solve (its own [solve] and [behavior]
   settings) per seed: whether every constraint is met (points to 1e-9, COMs within 3 sigma_com,
   shapes inside), the largest point constraint's error and COM constraint's miss in sigma_com,
   whether the reach check warned, log g_w per agent-step (the scenario's own
   behavior's log_plausibility summed over agents x interior frames, unweighted), the KS test of
   the free agents' impulse lengths (agents with no point constraint) against five forward
   simulations of the same model, flock size and length (a forward simulation's impulses are the
   model's draws exactly), the solve's seconds and its iterations per second end to end.
2. The keyframed weight (``Problem.keyframed_weight``): per weight, on the scenarios with point
   constraints and free agents, seeds as above: the median KS p of the free agents, how many seeds
   pass at 1%, the keyframed agents' own log g per agent-step (log N(|impulse|; 0, sigma)) and the
   whole flock's.
3. A default solve of 50 agents x 100 steps with a COM constraint at t = 0 and a point constraint
   at 5 s, 1 000 iterations: iterations per second end to end (setup, reach check, initial
   trajectories and refine included), and the sampler's alone; with the steering of 50 agents
   per frame, compiled (what boids runs) against the vectorized numpy N x N tables it replaced,
   in the same run.
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import attrs
import numpy as np
from scipy.stats import ks_2samp

import flockkit
from flockkit.constrained import load_scenario, solve
from flockkit.constrained.sampler import residuals, unmet
from flockkit.errors import FlockkitWarning

SCENARIOS = Path(__file__).resolve().parents[1] / "examples" / "scenarios"
WEIGHTS = (1.0, 0.5, 0.25, 0.1, 0.05)


def behavior_of(problem, settings):
    params = dict(settings.get("behavior_params", {}))
    if problem.obstacles:
        params["obstacles"] = problem.obstacles
    return flockkit.get("behavior", settings.get("behavior", "boids"), dt=problem.dt, **params)


def keyframed(problem) -> list[int]:
    return sorted({c.agent for c in problem.constraints if isinstance(c, flockkit.PointConstraint)})


def reference(model, problem, count=5) -> np.ndarray:
    """Impulse lengths of `count` forward simulations of the problem's flock size and length."""
    lengths = []
    for seed in range(count):
        motion = flockkit.simulate(model, n_agents=problem.n_agents, steps=problem.n_frames - 1, dims=problem.dims,
                                   seed=1000 + seed)  # fmt: skip
        lengths.append(np.linalg.norm(model.wander_impulses(motion)[1:-1], axis=-1).ravel())
    return np.concatenate(lengths)


def run(path, seed, weight=None) -> dict:
    problem, settings = load_scenario(path)
    if weight is not None:
        problem = attrs.evolve(problem, keyframed_weight=weight)
    model = behavior_of(problem, settings)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", FlockkitWarning)
        begin = time.perf_counter()
        solution = solve(problem, **dict(settings, seed=seed))
        seconds = time.perf_counter() - begin
    motion = solution.motion
    impulses = np.linalg.norm(model.wander_impulses(motion)[1:-1], axis=-1)  # (T - 2, N)
    pinned = keyframed(problem)
    free = [a for a in range(problem.n_agents) if a not in pinned]
    log_norm = math.log(model.wander_sigma) + 0.5 * math.log(2 * math.pi)
    own = -(impulses[:, pinned] ** 2) / (2 * model.wander_sigma**2) - log_norm
    found = residuals(problem, motion)
    points = [r for c, r in zip(problem.constraints, found) if isinstance(c, flockkit.PointConstraint)]
    coms = [r for c, r in zip(problem.constraints, found) if isinstance(c, flockkit.ComConstraint)]
    return {
        "met": not unmet(problem, motion),
        "point_error": max(points, default=float("nan")),
        "com_sigmas": max(coms, default=float("nan")) / problem.sigma_com,
        "warned": [str(w.message) for w in caught if issubclass(w.category, FlockkitWarning)],
        "log_g": float(np.sum(model.log_plausibility(motion)) / (problem.n_agents * (problem.n_frames - 2))),
        "keyframed": float(own.mean()) if pinned else float("nan"),
        "free": impulses[:, free].ravel() if free else None,
        "seconds": seconds,
        "rate": settings.get("iterations", 1000) / seconds,
        "model": model,
        "problem": problem,
    }


def scenarios(seeds, only) -> None:
    print(f"{'scenario':<18} {'seed':>4} {'met':>4} {'point err':>9} {'COM/sigma':>9} {'warns':>5} {'log g_w':>8} "
          f"{'KS p':>9} {'seconds':>8} {'it/s':>6}")  # fmt: skip
    for path in sorted(SCENARIOS.glob("*.toml")):
        if only and path.stem not in only:
            continue
        rows = [run(path, seed) for seed in seeds]
        simulated = reference(rows[0]["model"], rows[0]["problem"])
        ps = [ks_2samp(r["free"], simulated).pvalue if r["free"] is not None else float("nan") for r in rows]
        for seed, row, p in zip(seeds, rows, ps):
            print(f"{path.stem:<18} {seed:>4} {'yes' if row['met'] else 'NO':>4} {row['point_error']:>9.1e} "
                  f"{row['com_sigmas']:>9.2f} {len(row['warned']):>5} "
                  f"{row['log_g']:>8.2f} {p:>9.2g} {row['seconds']:>8.1f} {row['rate']:>6.0f}")  # fmt: skip
        passed = sum(p > 0.01 for p in ps)
        print(f"{path.stem:<18} median log g_w {np.median([r['log_g'] for r in rows]):.2f}, KS passes {passed} of "
              f"{len(rows)}, slowest {max(r['seconds'] for r in rows):.1f} s")  # fmt: skip
        for message in sorted({m for r in rows for m in r["warned"]}):
            print(f"{'':<18} warns: {message}")


def tradeoff(seeds, only) -> None:
    print(f"{'scenario':<18} {'weight':>6} {'median KS p':>11} {'passes':>6} {'keyframed log g':>15} {'log g_w':>8}")
    for path in sorted(SCENARIOS.glob("*.toml")):
        problem, _ = load_scenario(path)
        pinned = keyframed(problem)
        if (only and path.stem not in only) or not pinned or len(pinned) == problem.n_agents:
            continue
        simulated = None
        for weight in WEIGHTS:
            rows = [run(path, seed, weight) for seed in seeds]
            if simulated is None:
                simulated = reference(rows[0]["model"], rows[0]["problem"])
            ps = [ks_2samp(r["free"], simulated).pvalue for r in rows]
            own, whole = np.median([r["keyframed"] for r in rows]), np.median([r["log_g"] for r in rows])
            print(f"{path.stem:<18} {weight:>6g} {np.median(ps):>11.2g} {sum(p > 0.01 for p in ps):>6} "
                  f"{own:>15.2f} {whole:>8.2f}")  # fmt: skip


def numpy_steering(model, x, v):
    """The boids rules but avoidance on N x N tables per frame (F, N, D): the vectorized numpy
    version of what the compiled loop computes."""
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    heading = np.divide(v, speed, out=np.zeros_like(v), where=speed > 0)
    offset = x[:, None, :, :] - x[:, :, None, :]  # [f, i, j] = x_j - x_i
    distance = np.linalg.norm(offset, axis=-1)
    n = x.shape[1]
    distance[:, np.arange(n), np.arange(n)] = np.inf
    seen = distance <= model.perception_radius
    cos_half = math.cos(math.radians(model.field_of_view) / 2) * (speed[..., 0] > 0)
    finite = np.where(np.isinf(distance), 0, distance)
    seen &= np.einsum("fijk,fik->fij", offset, heading) >= finite * cos_half[..., None]
    seen = seen.astype(float)
    push = np.maximum(1 - distance / model.separation_radius, 0) / np.maximum(distance, 1e-12) * seen
    count = seen.sum(axis=-1, keepdims=True)
    share = np.divide(1.0, count, out=np.zeros_like(count), where=count > 0)
    steer = model.cohesion_weight / model.perception_radius * share * (seen @ x - count * x)
    steer -= model.separation_weight * (push @ x - push.sum(axis=-1, keepdims=True) * x)
    steer += model.alignment_weight / model.target_speed * (share * (seen @ v) - (count > 0) * v)
    steer += model.speed_weight / model.target_speed * (model.target_speed - speed) * heading
    return steer


def speed() -> None:
    problem = flockkit.Problem(n_agents=50, duration=10.0, constraints=[
        flockkit.ComConstraint(time=0.0, position=[0.0, 0.0], velocity=[1.0, 0.0]),
        flockkit.PointConstraint(agent=0, time=5.0, position=[5.0, 1.0], velocity=[1.0, 0.0])])  # fmt: skip
    solve(problem, iterations=10, seed=99)  # compiled kernels loaded, as in any later solve
    for seed in (1, 2, 3):
        begin = time.perf_counter()
        solve(problem, iterations=0, seed=seed)
        setup = time.perf_counter() - begin
        begin = time.perf_counter()
        solution = solve(problem, iterations=1000, seed=seed)
        total = time.perf_counter() - begin
        assert not unmet(problem, solution.motion)
        print(f"50 x 100, COM + point, seed {seed}: {total:5.2f} s, {1000 / total:5.0f} it/s end to end "
              f"(setup {setup:.2f} s; sampler alone {1000 / max(total - setup, 1e-9):.0f} it/s)")  # fmt: skip
    model = flockkit.get("behavior", "boids")
    motion = flockkit.simulate(n_agents=50, steps=100, seed=1)
    x, v = motion.positions[1:], np.diff(motion.positions, axis=0) / motion.dt
    error = np.abs(numpy_steering(model, x, v) - model._steering(x, v, 1.0)).max()
    for name, steer in (("compiled pair loop", lambda: model._steering(x, v, 1.0)),
                        ("numpy N x N tables", lambda: numpy_steering(model, x, v))):  # fmt: skip
        begin = time.perf_counter()
        for _ in range(50):
            steer()
        print(f"steering 100 frames of 50 agents, {name}: {(time.perf_counter() - begin) / 50 * 1e3:.2f} ms")
    print(f"(largest difference between the two: {error:.1e})")


def seed_range(text: str) -> list[int]:
    first, _, last = text.partition("-")
    return list(range(int(first), int(last or first) + 1))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1-5", type=seed_range)
    parser.add_argument("--only", nargs="*", default=None)
    parser.add_argument("--skip-tradeoff", action="store_true")
    parser.add_argument("--skip-speed", action="store_true")
    parser.add_argument("--skip-scenarios", action="store_true")
    args = parser.parse_args()
    if not args.skip_scenarios:
        print("shipped scenarios, default solve per seed")
        scenarios(args.seeds, args.only)
    if not args.skip_tradeoff:
        print("\nthe keyframed weight: free agents' KS p against the keyframed agents' own log g (medians over seeds)")
        tradeoff(args.seeds, args.only)
    if not args.skip_speed:
        print("\nspeed")
        speed()


if __name__ == "__main__":
    main()
