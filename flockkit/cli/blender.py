"""``flockkit blender-addon``, and the worker the Blender add-on runs.

The add-on (``flockkit/blender``) never imports flockkit inside Blender: Blender's Python carries
its own numpy (1.x for Blender 4.2 to 5.0), and a solve would freeze Blender's interface. It writes
what the user authored (agents, keyframed empties, meshes, arrows) to a job file and runs

    PYTHON -m flockkit.cli.blender JOB.json

with the Python where flockkit is installed. This module reads the job, calls flockkit's public API,
prints ``PROGRESS done total stage`` lines while it works, and writes its result (arrays to an .npz,
everything else to JSON) atomically where the job says; an error is one line ``ERROR message`` on
stdout and exit status 1. The job format is the add-on's private business: both sides ship together.

Blender's frames and flockkit's agree by construction: the add-on asks for motions at ``dt = 1 /
fps`` (the scene's frame rate), so motion frame k is Blender frame ``frame_start + k``, and a
constraint keyed at Blender frame f lies at ``(f - frame_start) / fps`` seconds, on a frame.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np

import flockkit

from .._atomic import atomic_path
from ..errors import FlockkitError, ValidationError

# What the add-on runs where the user names no behavior: the default of `flockkit simulate`.
DEFAULT_BEHAVIOR = "boids"
# Agent facings leave an agent's last heading where it slows below this (length units per second).
STILL = 1e-6


def build_addon(path) -> list[str]:
    """Write the Blender extension to `path` (a .zip, atomically): the add-on's sources
    (``flockkit/blender``) and its ``blender_manifest.toml`` with this flockkit's version. Returns
    the names in the archive."""
    import zipfile
    from importlib.resources import files

    source = files("flockkit") / "blender"
    names = sorted(p.name for p in source.iterdir() if p.name.endswith((".py", ".toml")))
    with atomic_path(path) as temporary, zipfile.ZipFile(temporary, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in names:
            text = (source / name).read_text()
            if name == "blender_manifest.toml":
                text = text.replace("{version}", flockkit.__version__)
            archive.writestr(name, text)
    return names


def _cmd_blender_addon(args) -> int:
    output = Path(args.output)
    if output.suffix.lower() != ".zip":
        raise ValidationError(f"-o {output}: expected a .zip file, the form Blender installs extensions from")
    files = build_addon(output)
    print(f"wrote {output}: the flockkit extension for Blender 4.2 or newer ({len(files)} files); install it in "
          "Edit > Preferences > Extensions > Install from Disk")  # fmt: skip
    return 0


def _blender_addon_arguments(parser) -> None:
    parser.add_argument("-o", "--output", required=True, help="the extension to write (.zip)")


# command -> (help, arguments, run)
COMMANDS = {
    "blender-addon": (
        "write the Blender extension (.zip): flocks, constraints, solves, scenes and crowds inside Blender",
        _blender_addon_arguments,
        _cmd_blender_addon,
    ),
}


# -- the worker ---------------------------------------------------------------------------------


def region(spec: dict):
    """A flockkit region from the job's form: {"kind": "ball", "center", "radius"}, {"kind":
    "box", "lower", "upper"} or {"kind": "polygon", "vertices"}."""
    kind = spec.get("kind")
    if kind == "ball":
        return flockkit.Ball(center=spec["center"], radius=spec["radius"])
    if kind == "box":
        return flockkit.Box(lower=spec["lower"], upper=spec["upper"])
    if kind == "polygon":
        return flockkit.Polygon(vertices=spec["vertices"])
    raise ValidationError(f"region kind must be 'ball', 'box' or 'polygon'; got {kind!r}")


def problem(spec: dict) -> flockkit.Problem:
    """The Problem of the job's form: n_agents, dims, dt, duration, constraints (each with a "kind":
    point, com or shape, and "name", the Blender object it came from), obstacles."""
    made = []
    for c in spec["constraints"]:
        velocity = c.get("velocity")
        if c["kind"] == "point":
            made.append(flockkit.PointConstraint(agent=c["agent"], time=c["time"], position=c["position"],
                                                 velocity=velocity))  # fmt: skip
        elif c["kind"] == "com":
            made.append(flockkit.ComConstraint(agents=c.get("agents"), time=c["time"], position=c["position"],
                                               velocity=velocity))  # fmt: skip
        elif c["kind"] == "shape":
            made.append(flockkit.ShapeConstraint(agents=c.get("agents"), time=c["time"], shape=region(c["shape"]),
                                                 velocity=velocity))  # fmt: skip
        else:
            raise ValidationError(f"constraint kind must be 'point', 'com' or 'shape'; got {c['kind']!r}")
    return flockkit.Problem(
        n_agents=spec["n_agents"], dims=spec["dims"], dt=spec["dt"], duration=spec["duration"],
        constraints=made, obstacles=[region(o) for o in spec.get("obstacles", ())],
    )  # fmt: skip


def placements(motion: flockkit.Motion) -> dict:
    """What Blender keys: each frame's location (T, N, 3), the ground plane z = 0 for a 2D motion,
    and rotation (T, N, 3), XYZ Euler angles turning the agent's +x along its velocity with no roll
    (yaw unwrapped, so that keys interpolate the short way); a resting agent keeps its last facing."""
    location = np.zeros((motion.n_frames, motion.n_agents, 3))
    location[..., : motion.dims] = motion.positions
    velocity = np.zeros_like(location)
    velocity[..., : motion.dims] = motion.velocities()
    moving = np.linalg.norm(velocity, axis=-1) > STILL
    for k in range(1, motion.n_frames):  # hold the facing through rests
        velocity[k] = np.where(moving[k, :, None], velocity[k], velocity[k - 1])
    yaw = np.unwrap(np.arctan2(velocity[..., 1], velocity[..., 0]), axis=0)
    pitch = -np.arctan2(velocity[..., 2], np.linalg.norm(velocity[..., :2], axis=-1))
    rotation = np.stack([np.zeros_like(yaw), pitch, yaw], axis=-1)
    return {"location": location, "rotation": rotation}


def _model(job: dict, dt: float, obstacles=()):
    name = job.get("behavior") or DEFAULT_BEHAVIOR
    params = dict(job.get("params") or {})
    model = flockkit.get("behavior", name, dt=dt, **params)
    if obstacles and flockkit.capabilities(model).obstacles:
        model = flockkit.get("behavior", name, dt=dt, obstacles=tuple(obstacles), **params)
    return model


def _describe(job: dict, report) -> dict:
    """Every installed behavior and its numeric parameters with their defaults (the fields of an
    instance made with none), for the add-on's panel."""
    import attrs

    behaviors = {}
    for name in flockkit.available("behavior"):
        model = flockkit.get("behavior", name)
        fields = attrs.asdict(model, recurse=False) if attrs.has(type(model)) else {}
        behaviors[name] = {
            key: value for key, value in fields.items()
            if isinstance(value, int | float) and not isinstance(value, bool) and key != "dt"
        }  # fmt: skip
    return {"behaviors": behaviors, "default": DEFAULT_BEHAVIOR, "version": flockkit.__version__}


def _simulate(job: dict, report) -> dict:
    obstacles = [region(o) for o in job.get("obstacles", ())]
    model = _model(job, job["dt"], obstacles)
    if obstacles and not flockkit.capabilities(model).obstacles:
        raise ValidationError(f"behavior {job.get('behavior') or DEFAULT_BEHAVIOR!r} does not avoid obstacles")
    motion = flockkit.simulate(model, n_agents=job["agents"], steps=job["frames"] - 1, dims=job["dims"],
                               seed=job.get("seed"))  # fmt: skip
    motion.save(job["motion"])
    return {"arrays": placements(motion), "frames": motion.n_frames, "agents": motion.n_agents}


def _hints(job: dict, report) -> dict:
    """The reach check's numbers before solving: the model's speeds unconstrained (10th, 90th,
    99th percentiles), and per constraint the speed its track asks for from the constraint before
    (or its own velocity), with the check's warnings (``flockkit.constrained.reach``)."""
    from ..constrained import reach

    asked = problem(job["problem"])
    model = _model(job, asked.dt, asked.obstacles)
    free = reach.unconstrained(asked, model, job.get("seed"))
    low, high, fastest = (float(v) for v in np.percentile(reach.speeds(free), [10, 90, 99]))
    names = [c.get("name", "") for c in job["problem"]["constraints"]]
    index = {id(c): k for k, c in enumerate(asked.constraints)}
    legs = []
    for track in asked.tracks:
        for before, after in zip((None, *track[:-1]), track):
            if before is None and len(track) > 1:  # its velocity is the path's, judged by the leg after
                continue
            if before is None:
                speed = float(np.linalg.norm(after.velocity))
                source = "its velocity"
            else:
                gap = np.linalg.norm(np.asarray(after.position) - before.position)
                speed = float(gap / max(after.time - before.time, 1e-12))
                source = f"from {names[index[id(before)]] or 'the one before'} at {before.time:g} s"
            legs.append({
                "constraint": index[id(after)], "name": names[index[id(after)]], "time": after.time, "speed": speed,
                "source": source, "ratio": speed / fastest if fastest > 0 else float("inf"),
                "beyond": speed > reach.IMPLAUSIBLE * fastest,
            })  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        reach.warn_beyond(asked, free, fastest)
    return {
        "model": {"p10": low, "p90": high, "p99": fastest, "implausible": reach.IMPLAUSIBLE},
        "legs": sorted(legs, key=lambda leg: leg["time"]),
        "warnings": [str(w.message) for w in caught],
    }


def _solve(job: dict, report) -> dict:
    asked = problem(job["problem"])
    iterations = int(job.get("iterations", 200))
    behavior = job.get("behavior") or DEFAULT_BEHAVIOR
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        report(0, iterations, "solving")
        solution = flockkit.solve(
            asked, behavior=behavior, behavior_params=job.get("params") or None, iterations=iterations,
            refine=int(job.get("refine", 40)), seed=job.get("seed"), n_jobs=1,
            callback=lambda chain, i, log_g, accepted: report(i + 1, iterations, "solving"),
        )  # fmt: skip
    solution.motion.save(job["motion"])
    return {
        "arrays": placements(solution.motion),
        "frames": solution.motion.n_frames,
        "residual": max(solution.residuals, default=0.0),
        "log_g": solution.log_g[0],
        "warnings": [str(w.message) for w in caught],
    }


def _layers(job: dict, report) -> dict:
    """Graph layers of an animated mesh sampled in Blender: its vertices' positions (T, V, 3) each
    frame and its faces, in Blender's axes (z up, metres, as flockkit's)."""
    from ..scene import Features

    with np.load(job["mesh"], allow_pickle=False) as data:
        positions, faces = data["positions"], data["faces"]
    motion = flockkit.Motion(positions=positions, dt=job["dt"])
    mesh = flockkit.AnimatedMesh(motion=motion, faces=faces, name=job.get("name", "mesh"))
    if job.get("arrow") is not None:
        features = Features.from_keyframes([(0.0, job["arrow"])], n_frames=motion.n_frames, dt=motion.dt)
    else:
        features = Features.from_motion(motion)
    report(0, 1, "layers")
    layers = flockkit.build_layers(mesh, features=features, seed=job.get("seed"))
    report(1, 1, "layers")
    layers.save(job["layers"])
    return {"arrays": {"labels": np.asarray(layers.segmentation.labels)}, "parts": layers.segmentation.n_parts}


def _scene(job: dict, report) -> dict:
    """A scene of copies of the layers in a ground polygon after keyframed flow arrows, written to
    USD on the Blender scene's time line."""
    from ..scene import Arrow, FlowField, GraphLayers, Scene

    layers = GraphLayers.load(job["layers"])
    arrows = [Arrow(position=a["position"], keyframes=[(t, v) for t, v in a["keyframes"]]) for a in job["arrows"]]
    scene = Scene(
        templates=[layers], region=flockkit.Polygon(vertices=job["region"]), counts=[job["count"]],
        duration=job["duration"], constraints=[FlowField(arrows=arrows)] if arrows else (), seed=job.get("seed") or 0,
        headings="aligned", n_jobs=1,
    )  # fmt: skip
    report(0, 1, "scene")
    animation = scene.synthesize()
    report(1, 1, "scene")
    animation.export(job["usd"], fps=job["fps"])
    return {"objects": animation.placement.n_objects, "frames": animation.n_frames, "report": animation.report}


def _crowd(job: dict, report) -> dict:
    """Characters on a flock's trajectories: per agent the character it is (dealt out in turn),
    the root each frame (the agent's position, its heading smoothed over `turn_time` seconds as
    ``flockkit.crowd.Driver`` turns roots), and the frame of its character's action it plays each
    frame: from a random offset (agents out of step), advancing at the agent's speed over the
    action's ground speed (time dilation: feet keep pace with the ground)."""
    motion = flockkit.Motion.load(job["motion"])
    characters = job["characters"]  # each: {"ground_speed": m/s, "first": frame, "last": frame}
    rng = np.random.default_rng(job.get("seed"))
    n, fps = motion.n_agents, job["fps"]
    place = placements(motion)
    location, velocity = place["location"], np.zeros_like(place["location"])
    velocity[..., : motion.dims] = motion.velocities()
    share = 1.0 if job.get("turn_time", 0.25) == 0 else 1 - np.exp(-motion.dt / job.get("turn_time", 0.25))
    heading = np.empty((motion.n_frames, n))
    heading[0] = place["rotation"][0, :, 2]
    for k in range(1, motion.n_frames):
        turn = (place["rotation"][k, :, 2] - heading[k - 1] + np.pi) % (2 * np.pi) - np.pi
        heading[k] = heading[k - 1] + share * turn
    which = np.arange(n) % len(characters)
    first = np.array([c["first"] for c in characters], dtype=float)[which]
    length = np.array([max(c["last"] - c["first"], 1) for c in characters], dtype=float)[which]
    ground = np.array([c["ground_speed"] for c in characters], dtype=float)[which]
    speed = np.linalg.norm(velocity[..., :2], axis=-1)
    rate = np.where(ground > 0, speed / np.where(ground > 0, ground, 1.0), 1.0) * (job.get("action_fps", fps) / fps)
    advance = np.concatenate([np.zeros((1, n)), np.cumsum(rate[:-1] * motion.dt * fps, axis=0)])
    phase = first + (rng.uniform(0, length) + advance) % length
    return {"arrays": {"location": location, "heading": heading, "phase": phase, "character": which}}


TASKS = {"describe": _describe, "simulate": _simulate, "hints": _hints, "solve": _solve, "layers": _layers,
         "scene": _scene, "crowd": _crowd}  # fmt: skip


def _report(done: int, total: int, stage: str) -> None:
    print(f"PROGRESS {done} {total} {stage}", flush=True)


def run(job_path) -> dict:
    """Run the job in `job_path` and write its result: arrays to ``job["output"] + ".npz"``, the
    rest to ``job["output"] + ".json"`` (both atomically). Returns the result."""
    job = json.loads(Path(job_path).read_text())
    task = TASKS.get(job.get("task"))
    if task is None:
        raise ValidationError(f"job task must be one of {', '.join(TASKS)}; got {job.get('task')!r}")
    result = task(job, _report)
    arrays = result.pop("arrays", {})
    output = Path(job["output"])
    with atomic_path(output.with_suffix(".npz")) as path:
        np.savez(path, **arrays)
    with atomic_path(output.with_suffix(".json")) as path:
        Path(path).write_text(json.dumps(result, default=float))
    return result


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("ERROR usage: python -m flockkit.cli.blender JOB.json", flush=True)
        return 2
    try:
        run(argv[0])
    except (FlockkitError, OSError, KeyError, TypeError, ValueError) as exc:
        message = " ".join(str(exc).split()) or type(exc).__name__
        print(f"ERROR {message}", flush=True)
        return 1
    print("DONE", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
