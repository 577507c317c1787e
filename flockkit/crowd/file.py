"""Crowd scene files (TOML): what ``flockkit crowd`` reads.

::

    seconds = 20                 # how long to run
    fps = 24                     # the animation system's frame rate, 1 to 1000
    seed = 1
    record = 64                  # optional: agents kept for the USD file and the picture

    [trajectories]               # exactly one of simulate, motion, walk
    simulate = { agents = 300, seed = 1 }          # a 2D flock (behavior = "boids" unless named; dims = 2)
    # motion = "flock.npz"                         # a flockkit motion file (a solution, a walk)
    # walk = { graph = "graph.npz", flocks = 10, seed = 2 }   # flocks walked from one graph

    [character]                  # where the clips come from, and how they sit in the world
    clips = "../shared/data/fox-gltf/Fox.glb"      # glTF or BVH, relative to this file
    meters_per_unit = 0.01       # the clips' unit where the file's is wrong or missing (a number or
                                 # "cm", "in", ...): the Fox is modelled in centimetres, BVH states none
    up = "y"                     # optional: the character's up and forward axes (default the file's
    forward = "z"                # up axis, y for glTF and BVH, and glTF's forward, z)
    feet = ["b_LeftFoot02_018", "b_RightFoot02_022"]   # for states that match speeds (default: the legs' feet)
    legs = [["b_LeftLeg01_015", "b_LeftLeg02_016", "b_LeftFoot02_018"],   # optional: (upper, middle,
            ["b_RightLeg01_019", "b_RightLeg02_020", "b_RightFoot02_022"]]  # foot) joints per leg
    plant = ["Walk"]             # optional: clips whose feet to plant (flockkit.crowd.plant_feet; needs legs)

    [[streams]]                  # name, clip; optional rate (1), history (60), default ("Running"),
    name = "walk"                # controller (a name taking clip= and rate=; default "clip")
    clip = "Walk"

    [machine]                    # optional: on ("speed" or "climb"), hysteresis, blend_time
    hysteresis = 0.05

    [[states]]                   # name, streams (names); optional low, high, match (speeds from feet)
    name = "walk"
    streams = ["walk"]

    [[cues]]                     # name, time, stream; agents ("all", "half" or ids); duration,
    name = "goal"                # blend_time, time_to_dilate optional
    time = 10
    stream = "walk"
    agents = "half"
"""

from __future__ import annotations

import math
from pathlib import Path

import attrs
import numpy as np

from .. import _files, _tomlfile, validate
from ..errors import FlockkitError, ValidationError
from ..io import read_clips
from ..motion import Motion, random_flock
from ..registry import get, require, require_dims, resolve
from ..validate import allocation
from .drive import CLIP_CONTROLLER, Cue, Driver, Gait, StateMachine, character_axes
from .feet import ground_speed, plant_feet
from .pool import MAX_FPS, Stream, StreamPool
from .runtime import Crowd

__all__ = ["CrowdScene", "read_crowd_scene"]

# The behavior model of [trajectories] simulate unless the file names one: flockkit.simulate's.
DEFAULT_BEHAVIOR = "boids"

_KEYS = {"seconds", "fps", "seed", "record", "trajectories", "character", "streams", "machine", "states", "cues"}


@attrs.frozen(kw_only=True, eq=False)
class CrowdScene:
    """What a crowd scene file describes: trajectories, streams, a state machine and cues, ready
    to run (``driver()``) for `seconds`, keeping `record` agents for pictures and files. `up`,
    `forward` and `scale` (metres per character unit) place the characters (see ``Driver``)."""

    motion: Motion
    streams: tuple
    machine: StateMachine
    cues: tuple
    seconds: float
    fps: float
    seed: int
    record: int
    up: str
    forward: str
    scale: float

    def driver(self) -> Driver:
        """A fresh crowd on the streams, every agent on a trajectory, driven by the machine."""
        pool = StreamPool(self.streams, fps=self.fps)
        first = self.machine.states[0].streams[0]
        crowd = Crowd(pool, n_agents=self.motion.n_agents, clusters={"body": first}, seed=self.seed)
        return Driver(crowd, self.motion, self.machine, up=self.up, forward=self.forward, scale=self.scale,
                      cues=self.cues)  # fmt: skip


def _table(data, key: str, keys: set, required: set, where: str) -> dict:
    entry = data.get(key, {}) if key else data
    if not isinstance(entry, dict):
        raise ValidationError(f"{where} must be a table")
    unknown = sorted(set(entry) - keys)
    if unknown:
        raise ValidationError(f"{where}: unknown key {unknown[0]!r}; expected {', '.join(sorted(keys))}")
    missing = sorted(required - set(entry))
    if missing:
        raise ValidationError(f"{where}: missing {missing[0]!r}")
    return entry


def _trajectories(path: Path, entry: dict, fps: float, seconds: float, inside) -> Motion:
    from ..graphs import MotionGraph, synthesize_many, walk_graph

    sources = [k for k in ("simulate", "motion", "walk") if k in entry]
    if len(sources) != 1:
        raise ValidationError("[trajectories] needs exactly one of simulate, motion, walk")
    if "simulate" in entry:
        keys = {"agents", "seed", "dims", "behavior"}
        spec = _table(entry, "simulate", keys, {"agents"}, "[trajectories] simulate")
        steps = int(math.ceil(seconds * fps))
        # a flock from a random start, as flockkit.simulate makes one
        rng = np.random.default_rng(validate.seed(spec.get("seed", 0), "[trajectories] simulate seed"))
        n_agents = validate.integer(spec["agents"], "[trajectories] simulate agents", minimum=1)
        dims = validate.dims(spec.get("dims", 2), "[trajectories] simulate dims")
        allocation(2 * (steps + 1) * n_agents * dims, f"[trajectories] {steps + 1} frames of {n_agents} agents")
        initial = random_flock(n_agents=n_agents, dims=dims, rng=rng)
        model = get("behavior", spec.get("behavior", DEFAULT_BEHAVIOR), dt=1.0 / fps)
        require_dims("behavior", model, initial.dims, f"a {initial.dims}D flock")
        return model.forward(initial, steps, rng)
    if "motion" in entry:
        return Motion.load(inside(entry["motion"], "trajectories.motion"))
    spec = _table(entry, "walk", {"graph", "flocks", "seed"}, {"graph", "flocks"}, "[trajectories] walk")
    graph = MotionGraph.load(inside(spec["graph"], "trajectories.walk.graph"))
    seed = spec.get("seed", 0)
    return synthesize_many(graph, [walk_graph(graph, duration=seconds, seed=seed + k) for k in range(spec["flocks"])])


def read_crowd_scene(path, *, allow_outside: bool = False) -> CrowdScene:
    """The CrowdScene a TOML crowd scene file describes; errors name the file and the entry. The
    files it names (trajectories, clips) must lie in its folder (below it), unless
    `allow_outside` is True."""
    path = Path(path)
    data = _tomlfile.read(path, "crowd scene")

    def inside(reference, where):
        return _files.confined(path.parent, reference, source=path, where=where, allow_outside=allow_outside,
                               uri=False)  # fmt: skip

    try:
        _table(data, "", _KEYS, {"seconds", "trajectories", "character", "streams", "states"}, "the file")
        seconds = validate.number(data["seconds"], "seconds", minimum=0, strict=True)
        fps = validate.number(data.get("fps", 30.0), "fps", minimum=1, maximum=MAX_FPS)
        sources = _table(data, "trajectories", {"simulate", "motion", "walk"}, set(), "[trajectories]")
        motion = _trajectories(path, sources, fps, seconds, inside)
        keys = {"clips", "up", "forward", "scale", "meters_per_unit", "feet", "legs", "plant"}
        character = _table(data, "character", keys, {"clips"}, "[character]")
        if "scale" in character and "meters_per_unit" in character:
            raise ValidationError("[character] takes meters_per_unit (the clips' unit) or scale (an older name for "
                                  "it), not both")  # fmt: skip
        unit = character.get("meters_per_unit", character.get("scale"))
        clips = read_clips(inside(character["clips"], "character.clips"), up_axis=character.get("up"),
                           meters_per_unit=unit)  # fmt: skip
        skeleton = next(iter(clips.values())).skeleton
        up, forward, scale = character_axes(skeleton, up=character.get("up"), forward=character.get("forward"),
                                            owner="[character]")  # fmt: skip
        if "legs" in character and "feet" not in character:
            character["feet"] = [leg[-1] for leg in character["legs"]]
        for name in character.get("plant", []):
            if "legs" not in character:
                raise ValidationError("[character] plant needs legs")
            if name not in clips:
                raise ValidationError(
                    f"[character] plant: no clip {name!r}; the file has {', '.join(map(repr, clips))}"
                )
            clips[name] = plant_feet(clips[name], character["legs"], up=up, forward=forward)
        streams, names, rates = [], {}, []
        for k, spec in enumerate(data["streams"]):
            where = f"[[streams]] {k}"
            keys = {"name", "clip", "rate", "history", "default", "controller"}
            spec = _table(spec, "", keys, {"name", "clip"}, where)
            if spec["clip"] not in clips:
                raise ValidationError(f"{where}: no clip {spec['clip']!r}; the file has {', '.join(map(repr, clips))}")
            if spec["name"] in names:
                raise ValidationError(f"{where}: the name {spec['name']!r} is taken")
            controller_rate = float(spec.get("rate", 1.0))
            require("controller", spec.get("controller", CLIP_CONTROLLER), "clip_player", f"{where}: streams")
            controller = resolve("controller", spec.get("controller", CLIP_CONTROLLER), clip=clips[spec["clip"]],
                                 rate=controller_rate)  # fmt: skip
            names[spec["name"]] = len(streams)
            rates.append((spec["clip"], controller_rate))
            streams.append(Stream(controller=controller, history=spec.get("history", 60),
                                  default=spec.get("default", "Running"), name=spec["name"]))  # fmt: skip

        def stream_ids(listed, where):
            unknown = [s for s in listed if s not in names]
            if unknown:
                raise ValidationError(
                    f"{where}: no stream {unknown[0]!r}; the streams are {', '.join(map(repr, names))}"
                )
            return [names[s] for s in listed]

        states = []
        bottom = -math.inf if data.get("machine", {}).get("on") == "climb" else 0.0
        for k, spec in enumerate(data["states"]):
            where = f"[[states]] {k}"
            spec = _table(spec, "", {"name", "streams", "low", "high", "match"}, {"name", "streams"}, where)
            ids = stream_ids(spec["streams"], where)
            speeds = None
            if spec.get("match", False):
                if "feet" not in character:
                    raise ValidationError(f"{where}: match needs [character] feet")
                speeds = [ground_speed(clips[rates[i][0]], character["feet"], up=up, forward=forward, scale=scale)
                          * rates[i][1] for i in ids]  # fmt: skip
            low = spec.get("low", bottom)
            states.append(Gait(name=spec["name"], streams=ids, speeds=speeds, low=low, high=spec.get("high", math.inf)))
        machine = StateMachine(
            states, **_table(data, "machine", {"on", "hysteresis", "blend_time"}, set(), "[machine]")
        )
        cues = []
        n = motion.n_agents
        for k, spec in enumerate(data.get("cues", [])):
            where = f"[[cues]] {k}"
            keys = {"name", "time", "stream", "agents", "duration", "blend_time", "time_to_dilate"}
            spec = _table(spec, "", keys, {"name", "time", "stream"}, where)
            if not 0 <= spec["time"] <= seconds:
                raise ValidationError(f"{where}: time {spec['time']} is outside the run (0..{seconds:g} s)")
            chosen = spec.get("agents", "all")
            agents = (
                {"all": np.arange(n), "half": np.arange(0, n, 2)}.get(chosen) if isinstance(chosen, str) else chosen
            )
            if agents is None:
                raise ValidationError(f"{where}: agents must be 'all', 'half' or a list of agent ids; got {chosen!r}")
            (stream,) = stream_ids([spec["stream"]], where)
            cues.append(Cue(time=spec["time"], agents=agents, stream=stream, duration=spec.get("duration"),
                            blend_time=spec.get("blend_time", 0.3), time_to_dilate=spec.get("time_to_dilate"),
                            name=spec["name"]))  # fmt: skip
        record = int(data.get("record", 64))
        if record < 1:
            raise ValidationError(f"record must be at least 1; got {record}")
        return CrowdScene(motion=motion, streams=tuple(streams), machine=machine, cues=tuple(cues), seconds=seconds,
                          fps=fps, seed=int(data.get("seed", 0)), record=min(record, n), up=up, forward=forward,
                          scale=scale)  # fmt: skip
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"{path}: {exc}") from None
    except FlockkitError as exc:
        raise type(exc)(str(exc) if str(exc).startswith(str(path)) else f"{path}: {exc}") from None
    except (TypeError, KeyError, ValueError, OverflowError) as exc:  # a value of the wrong type or size
        raise ValidationError(f"{path}: {type(exc).__name__}: {exc}") from None
