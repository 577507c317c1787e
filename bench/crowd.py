"""The crowd runtime at the paper's evaluation scale (paper 003, section 5), beside a direct
evaluation of every part's own clip.

    python bench/crowd.py [--agents 65000] [--streams 1024] [--frames 120] [--clips stream|skeleton]
                          [--running all|half]   # all: every stream Running (the acceptance case)
    python bench/crowd.py --quick      # 8 000 agents, 128 streams, 30 frames, 512 transitions
    python bench/crowd.py --device     # also the store in CuPy on a GPU, where CuPy finds one
    python bench/crowd.py --lod-parts 65000,260000   # the sizes of the level-of-detail section

65 000 agents x 4 part clusters (body: 82 joints; flag: 25; scarf and hat: 24), 1 024 streams
(half human, a quarter each flag and scarf; half of each Stopped by default) with histories of 20
to 120 frames, each playing its own random clip of 90 frames at a rate of 0.8 to 1.2 (the paper
has about 1 024 animations; ``--clips skeleton``: one clip per skeleton size for every stream).
After the crowd starts, 4 096 body parts transition at once into Stopped streams (a goal is
scored: celebrations), blending over 0.5 s with time dilation. It prints milliseconds per
`update` (mean and worst over the frames) and per `instance_buffer`, milliseconds to sample the
blended poses of the 4 096 transitioning parts (local, and world by forward kinematics), and the
pool's memory (everything it holds, its store against Equations 4-6).

The blend of the 4 096 transitioning parts is timed three ways in the same run: flockkit's
compiled read (``Crowd.poses(..., out=buffer)``: one pass per part into a buffer reused every
frame, as an engine's pose buffer is; and without ``out``, a new array each call), the same work
vectorized with numpy (the array API path ``Crowd._entries(..., compiled=False)``, what a store
on a GPU runs), and the memory-bandwidth limit: a numpy copy that moves as many bytes. Then
forward kinematics of those parts (world poses), compiled, against ``Skeleton.world`` (numpy,
one step per depth).

Level of detail (``Crowd.lod_from_camera``): crowds of about 65 000 and 260 000 agent parts
(`--lod-parts`) on a square, a camera at one corner and bands placing about a quarter of the agents
at each level 0-3 (refreshed every 1, 2, 4, 8 frames); a quarter of the body parts transition into
other streams with time dilation, and update + instance_buffer is timed per frame without and
with the levels (median of 60 frames, the same crowd run twice from the same seed).

Then, on sampled frames of the same run (best of 3 each), every agent part's local pose two
ways: flockkit's `update` + `poses()` (shared streams read at each part's offset, the
transitioning parts blended), and the strongest baseline we know without shared streams, a
vectorized numpy direct evaluation (`Direct`): every part samples its own clip at its own time,
all the parts of one skeleton size by one gather from a float32 table of their clips' keys
(slerped between frames as the clips define), and the parts in transition blend the two clips'
poses. The script checks the two equal (parts read between two stream frames while dilating
differ by the slerp between those frames against the clip at the exact time, and it prints by
how much). Targets (2 cores): update + instance_buffer <= 5 ms per frame; blended poses of
4 096 parts <= 3 ms; the pool's store equal to Equation 5. First it times read_clips on the
shared data's clips (the 2 752-frame BVH should take well under a second).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numba
import numpy as np
from timing import timed  # bench/timing.py: the scripts run from bench/

import flockkit
from flockkit.crowd import Crowd, Pose, Stream, StreamPool, equation_4, equation_5
from flockkit.crowd.runtime import STREAMED
from flockkit.testing import inputs

SKELETONS = {"body": 82, "flag": 25, "scarf": 24, "hat": 24}


def build(n_agents: int, n_streams: int, seed: int = 0, clips: str = "stream", running: str = "half"):
    """The crowd's pool and clusters. `clips`: "stream", every stream its own clip (the paper's
    evaluation has about 1 024 animations), or "skeleton", one clip per skeleton size that every
    stream of that size plays at its own rate (0.8 to 1.2)."""
    rng = np.random.default_rng(seed)
    shared = {j: inputs.random_clip(j, frames=90, seed=j) for j in sorted(set(SKELETONS.values()))}
    bones = np.concatenate(
        [np.full(n_streams // 2, 82), np.full(n_streams // 4, 25), np.full(n_streams - 3 * n_streams // 4, 24)]
    )
    histories = rng.integers(20, 121, size=n_streams)
    stopped = rng.random(n_streams) < 0.5
    if running == "all":  # the acceptance case: every stream Running from the start
        stopped[:] = False

    def clip_of(k: int, joints: int):
        if clips == "skeleton":
            return shared[joints]
        other = inputs.random_clip(joints, frames=90, seed=1000 + k)  # its motion on the shared skeleton
        return flockkit.SkeletalClip(skeleton=shared[joints].skeleton, fps=other.fps, rotations=other.rotations,
                                     translations=other.translations[:, 0], name=f"random{joints}-{k}")  # fmt: skip

    streams = [
        Stream(
            controller=flockkit.get("controller", "clip", clip=clip_of(k, int(b)), rate=float(rng.uniform(0.8, 1.2))),
            history=int(h),
            default="Stopped" if s else "Running",
        )
        for k, (b, h, s) in enumerate(zip(bones, histories, stopped))
    ]
    pool = StreamPool(streams, fps=30.0)
    clusters = {}
    shares = {"body": 1.0, "flag": 0.3, "scarf": 0.5, "hat": 0.4}
    for name, joints in SKELETONS.items():
        candidates = np.flatnonzero((bones == joints) & ~stopped)
        if running == "all":  # the celebration streams (the first 16 of 82 joints) start unused
            candidates = candidates[16:] if joints == 82 else candidates
        chosen = rng.choice(candidates, size=n_agents)
        clusters[name] = np.where(rng.random(n_agents) < shares[name], chosen, -1)
    return pool, clusters, bones, histories, stopped


# Parts the direct evaluation samples per call: its temporaries then stay in cache (1 024 parts a
# call took 0.70 of the time one call for all took, on 44 000 parts of 24 to 82 joints).
CHUNK = 1024


class KeyTable:
    """The frames clips of one skeleton size, every clip's keys in one float32 table (the store's
    precision), each interval's slerp angle and its far key turned to the near side worked out
    once: ``clip.sample`` (rotations slerped between frames, translations lerped) for parts of
    any of these clips at once, by one gather, with no search for the interval (frames are
    evenly spaced). Equal to ``clip.sample`` within float32."""

    def __init__(self, clips):
        rows = {name: [] for name in ("rotations", "far", "angle", "inverse_sine", "translations", "step")}
        self.base, self.last, self.fps, self.end = [], [], [], []
        for clip in clips:
            q, t = clip.rotations, clip.translations
            dot = np.sum(q[:-1] * q[1:], axis=-1, keepdims=True)
            angle = np.maximum(np.arccos(np.minimum(np.abs(dot), 1.0)), 1e-12)  # as the clip's own keys
            pad = lambda a: np.concatenate([a, a[-1:]])  # noqa: E731 - a row per frame, the last unused
            rows["rotations"].append(q)
            rows["far"].append(pad(np.where(dot < 0, -q[1:], q[1:])))
            rows["angle"].append(pad(angle))
            rows["inverse_sine"].append(pad(1 / np.sin(angle)))
            rows["translations"].append(t)
            rows["step"].append(pad(t[1:] - t[:-1]))
            self.base.append(sum(len(r) for r in rows["rotations"][:-1]))
            self.last.append(len(q) - 2)
            self.fps.append(clip.fps)
            self.end.append(clip.duration)
        for name, parts in rows.items():
            setattr(self, name, np.concatenate(parts).astype(np.float32))
        self.base, self.last = np.array(self.base), np.array(self.last)
        self.fps, self.end = np.array(self.fps), np.array(self.end)

    def sample(self, clip: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (n, J, 4) and translations (n, J, 3) float32 of clips `clip` (n,), indices
        into the clips given, at clip times `u` (n,)."""
        x = np.clip(u, 0, self.end[clip]) * self.fps[clip]
        k = np.minimum(np.floor(x).astype(np.int64), self.last[clip])
        t = (x - k).astype(np.float32)[:, None, None]
        row = self.base[clip] + k
        angle, inverse = self.angle[row], self.inverse_sine[row]
        rotations = np.sin((1 - t) * angle) * inverse * self.rotations[row]
        rotations += np.sin(t * angle) * inverse * self.far[row]
        return rotations, self.translations[row] + t * self.step[row]


class Direct:
    """Every agent part evaluating its own clip at its own time, vectorized with numpy: the
    baseline for `Crowd.poses`. Each part is at a time on its clip (a direct system keeps one
    clock per part; here it is read from the crowd's instance buffer, so that both sides show
    the same poses); the parts of one skeleton size are sampled together, CHUNK at a time,
    between keys as their clips define (`KeyTable`: float32, as the crowd's store); parts in
    transition evaluate their second clip too and blend by α (Equation 2, nlerp, as Listing 3
    lerps). Streams must play ``clip`` controllers of frames clips."""

    def __init__(self, pool: StreamPool):
        controllers = [s.controller for s in pool.streams]
        clips, which = [], {}
        for c in controllers:
            if c.clip.channels or c.clip.n_frames < 2:
                raise SystemExit("the direct evaluation here samples clips of frames (two or more)")
            if id(c.clip) not in which:
                which[id(c.clip)] = len(clips)
                clips.append(c.clip)
        sizes = sorted({c.skeleton.n_joints for c in clips})
        self.tables = {j: KeyTable([c for c in clips if c.skeleton.n_joints == j]) for j in sizes}
        place, counts = {}, {}
        for c in clips:  # each clip's index in its size's table
            place[id(c)] = counts.get(c.skeleton.n_joints, 0)
            counts[c.skeleton.n_joints] = place[id(c)] + 1
        self.clip_of = np.array([place[id(c.clip)] for c in controllers])
        self.rate = np.array([c.rate for c in controllers])
        self.start = np.array([c.start for c in controllers])
        self.period = np.array([c.clip.duration if c.loop else 0.0 for c in controllers])
        self.fps = pool.fps

    def times(self, clock: np.ndarray, stream: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """Each part's time on its clip: the stream's frame (clock - 1 - offset) at its rate."""
        u = self.start[stream] + self.rate[stream] * (clock[stream] - 1 - offset) / self.fps
        period = self.period[stream]
        return np.where(period > 0, np.mod(u, np.where(period > 0, period, 1.0)), u)

    def sample(self, stream: np.ndarray, u: np.ndarray, joints: int) -> tuple[np.ndarray, np.ndarray]:
        """Each part's clip at its time `u`: rotations (n, joints, 4), translations (n, joints, 3)."""
        rotations = np.empty((len(u), joints, 4), np.float32)
        translations = np.empty((len(u), joints, 3), np.float32)
        table, clip = self.tables[joints], self.clip_of[stream]
        for begin in range(0, len(u), CHUNK):
            part = slice(begin, begin + CHUNK)
            rotations[part], translations[part] = table.sample(clip[part], u[part])
        return rotations, translations

    def poses(self, clock: np.ndarray, time: float, parts: dict, joints: int) -> Pose:
        """Local poses (n, joints) float32 of the parts described by `parts` (arrays: stream,
        offset, target, target_offset, blend_start, blend_time) at the crowd's `time`."""
        rotations, translations = self.sample(parts["stream"], self.times(clock, parts["stream"], parts["offset"]),
                                              joints)  # fmt: skip
        blending = np.flatnonzero(parts["blend_time"] > 0)
        if len(blending):
            target = parts["target"][blending]
            b, moved = self.sample(target, self.times(clock, target, parts["target_offset"][blending]), joints)
            alpha = np.clip((time - parts["blend_start"][blending]) / parts["blend_time"][blending], 0, 1)
            alpha = alpha.astype(np.float32)[:, None, None]
            a = rotations[blending]
            b *= np.where(np.vecdot(a, b)[..., None] < 0, -1, 1).astype(np.float32)  # the shorter way
            mixed = a + alpha * (b - a)
            rotations[blending] = mixed / np.sqrt(np.vecdot(mixed, mixed))[..., None]
            shift = translations[blending]
            translations[blending] = shift + alpha * (moved - shift)
        return Pose._adopt(rotations, translations)


def part_state(crowd: Crowd, agents: np.ndarray, cluster: str) -> dict:
    """What a direct evaluation keeps per part of `agents` in `cluster`, from the instance buffer."""
    record = crowd.instance_buffer()[agents, crowd.cluster_index(cluster)]
    if np.any(record["kind"] != STREAMED) or np.any((record["blend_time"] > 0) & (record["target_kind"] != STREAMED)):
        raise SystemExit("the direct evaluation covers parts on shared streams only")
    ints, floats = ("stream", "target"), ("offset", "target_offset", "blend_start", "blend_time")
    return {**{n: record[n].astype(np.int64) for n in ints}, **{n: record[n].astype(np.float64) for n in floats}}


class Gaps:
    """How far `Crowd.poses` is from the direct evaluation, per part (the largest joint rotation
    angle in radians and translation difference), kept apart for parts at whole stream frames
    (equal up to the float32 store), parts read between two frames (a slerp between the stream's
    frames against the clip at the exact time) and, of those, parts whose two frames straddle
    the loop seam of a clip whose end is not its start (the slerp crosses the jump)."""

    KINDS = ("whole", "between", "seam")

    def __init__(self):
        self.angles = {kind: [] for kind in self.KINDS}
        self.shifts = {kind: [] for kind in self.KINDS}

    def add(self, crowd: Pose, direct: Pose, between: np.ndarray, seam: np.ndarray) -> None:
        a, b = crowd.rotations.astype(np.float64), direct.rotations
        b = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -b, b)
        angle = 2 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1)).max(axis=1)
        shift = np.abs(crowd.translations - direct.translations).max(axis=(1, 2))
        for kind, chosen in zip(self.KINDS, (~between, between & ~seam, between & seam)):
            self.angles[kind].append(angle[chosen])
            self.shifts[kind].append(shift[chosen])

    def worst(self, kind: str) -> tuple:
        angles, shifts = np.concatenate(self.angles[kind]), np.concatenate(self.shifts[kind])
        if not len(angles):
            return 0, 0.0, 0.0, 0.0, 0.0
        return len(angles), angles.max(), shifts.max(), np.percentile(angles, 99), np.percentile(shifts, 99)

    def check(self) -> None:
        _, angle, shift, *_ = self.worst("whole")
        if angle > 1e-5 or shift > 1e-5:  # a float32 store against float64 sampling
            raise SystemExit(f"the direct evaluation and Crowd.poses differ: {angle:.3g} rad, {shift:.3g} units")

    def report(self, what: str) -> str:
        count, angle, shift, _, _ = self.worst("whole")
        lines = [f"  the same poses: {count} {what} at whole stream frames within {angle:.1e} rad and {shift:.1e} "
                 "units (the float32 store)"]  # fmt: skip
        count, angle, shift, angle99, shift99 = self.worst("between")
        lines.append(f"  {count} read between two frames (dilating): within {angle:.1e} rad and {shift:.1e} units, "
                     f"99% within {angle99:.1e} rad and {shift99:.1e} (a slerp between the stream's frames "
                     "against the clip at the exact time)")  # fmt: skip
        count, angle, shift, *_ = self.worst("seam")
        lines.append(f"  {count} between two frames that straddle a clip's loop seam: up to {angle:.2g} rad and "
                     f"{shift:.2g} units (where a clip's end is not its start, the slerp crosses the jump, which a "
                     "part at whole frames takes in one step)")  # fmt: skip
        return "\n".join(lines)


def reading_between(direct: Direct, clock: np.ndarray, state: dict) -> tuple[np.ndarray, np.ndarray]:
    """Which parts read between two stream frames (source or blend target), and which of those
    have the two frames on either side of a clip's loop seam."""
    between, seam = np.zeros(len(state["stream"]), bool), np.zeros(len(state["stream"]), bool)
    for stream, offset, used in (("stream", "offset", True), ("target", "target_offset", state["blend_time"] > 0)):
        k, o = state[stream], state[offset]
        here = used & (o % 1 > 0)
        newer, older = direct.times(clock, k, np.floor(o)), direct.times(clock, k, np.floor(o) + 1)
        between |= here
        seam |= here & (newer < older)  # the older frame is later in the clip: the loop wrapped between
    return between, seam


def compare_poses(crowd: Crowd, direct: Direct, members: dict, joints: dict, gaps: Gaps) -> tuple[float, float]:
    """Time `Crowd.poses` and the direct evaluation (best of 3 each) for every part of every
    cluster (`members`: cluster -> agents having it) at the crowd's current frame, and add how
    far apart they are to `gaps`. Returns (crowd ms, direct ms)."""
    states = {name: part_state(crowd, agents, name) for name, agents in members.items()}
    clock, now = crowd.pool.clock.copy(), crowd.time
    ours = ms(lambda: [crowd.poses(agents, name) for name, agents in members.items()], repeat=3)
    theirs = ms(lambda: [direct.poses(clock, now, states[n], joints[n]) for n in members], repeat=3)
    for name, agents in members.items():
        state = states[name]
        between, seam = reading_between(direct, clock, state)
        gaps.add(crowd.poses(agents, name), direct.poses(clock, now, state, joints[name]), between, seam)
    gaps.check()
    return ours, theirs


def ms(function, repeat=5) -> float:
    """The best of `repeat` calls, in milliseconds."""
    return timed(function, repeat=repeat)[1] * 1000


def load() -> str:
    """The machine's load averages (1, 5, 15 minutes): other work sharing the cores."""
    return ", ".join(f"{x:.2f}" for x in os.getloadavg())


def bandwidth(crowd: Crowd, parts: np.ndarray, repeat: int = 5) -> tuple[float, int, float]:
    """The memory-bandwidth limit of blending `parts`' body poses: ms for a plain numpy copy
    that moves the bytes the blend must move (two store entries read per part and one written:
    a copy of 1.5 entries a part reads and writes as much), best of `repeat`; those bytes; and
    the copy's CPU ms, best of `repeat`. (A part read between two frames reads a third entry,
    which the limit does not count.)"""
    entries = crowd.entries(parts, "body")
    source = np.concatenate([entries, entries[: len(entries) // 2]])
    out = np.empty_like(source)
    wall = cpu = np.inf
    for _ in range(repeat):
        begin, begin_cpu = time.perf_counter(), time.thread_time()
        np.copyto(out, source)
        wall, cpu = min(wall, time.perf_counter() - begin), min(cpu, time.thread_time() - begin_cpu)
    return wall * 1000, 2 * source.nbytes, cpu * 1000


def measure_blend(crowd: Crowd, movers: np.ndarray, buffer: np.ndarray) -> dict:
    """The blend of `movers`' body parts, interleaved best of 7 (the machine's load hits each
    alike): compiled into `buffer` ("out") and into a new array ("new"), the array API path with
    numpy ("numpy"), the bandwidth limit ("limit", "bytes"); world poses compiled ("world") and by
    Skeleton.world ("numpy_world"); how far the two paths differ ("gap") and how many parts read
    their target between two frames ("between")."""
    c = crowd.cluster_index("body")
    threads = numba.get_num_threads()

    def one_thread():
        numba.set_num_threads(1)
        try:
            crowd.poses(movers, "body", out=buffer)
        finally:
            numba.set_num_threads(threads)

    rounds = {"out": lambda: crowd.poses(movers, "body", out=buffer), "out1": one_thread,
              "new": lambda: crowd.poses(movers, "body"),
              "numpy": lambda: crowd._entries(movers, c, compiled=False)}  # fmt: skip
    found = dict.fromkeys([*rounds, "limit", "out1_cpu", "limit_cpu"], np.inf)
    for _ in range(7):
        for name, call in rounds.items():
            begin = time.thread_time()
            found[name] = min(found[name], ms(call, repeat=1))
            if name == "out1":  # this thread's CPU time (numba runs one thread here): whatever else the machine runs
                found["out1_cpu"] = min(found["out1_cpu"], (time.thread_time() - begin) * 1000)
        copy_ms, found["bytes"], copy_cpu = bandwidth(crowd, movers, repeat=1)
        found["limit"], found["limit_cpu"] = min(found["limit"], copy_ms), min(found["limit_cpu"], copy_cpu)
    found["gap"] = np.abs(crowd._entries(movers, c) - crowd._entries(movers, c, compiled=False)).max()
    found["between"] = int(np.sum(crowd.instance_buffer()["target_offset"][movers, c] % 1 > 0))
    local, skeleton = crowd.poses(movers, "body"), crowd.skeletons[c]
    found["world"] = ms(lambda: crowd.poses(movers, "body", space="world"), repeat=3)
    numba.set_num_threads(1)
    found["world1"] = ms(lambda: crowd.poses(movers, "body", space="world"), repeat=3)
    numba.set_num_threads(threads)
    found["numpy_world"] = ms(lambda: skeleton.world(local, dtype=np.float32), repeat=3)
    return found


def gpu(args, movers, celebrations):
    """The same crowd with its store in CuPy, sampled and blended there through the same code
    (the array API), where CuPy and a GPU are present."""
    try:
        import cupy

        found = cupy.cuda.runtime.getDeviceCount()
    except Exception as exc:  # noqa: BLE001 - no CuPy, or CuPy without a driver or device
        print(f"--device: no GPU found (CuPy: {type(exc).__name__}: {exc}); the sampling and blending ran on "
              "the CPU only")  # fmt: skip
        return
    if not found:
        print("--device: CuPy finds no GPU; the sampling and blending ran on the CPU only")
        return
    try:
        pool, clusters, *_ = build(args.agents, args.streams, clips=args.clips, running=args.running)
        pool = StreamPool(pool.streams, fps=pool.fps, xp=cupy)
        crowd = Crowd(pool, n_agents=args.agents, clusters=clusters, seed=1)
        for k, group in enumerate(np.array_split(movers, 16)):
            crowd.transition_to_streamed(group, "body", int(celebrations[k]), blend_time=0.5, time_to_dilate=2.0)
        for _ in range(5):
            crowd.update()

        def sample():
            crowd.poses(movers, "body")
            cupy.cuda.Device().synchronize()

        print(f"GPU ({cupy.cuda.runtime.getDeviceProperties(0)['name'].decode()}): blended poses of "
              f"{len(movers)} parts {ms(sample):.2f} ms")  # fmt: skip
    except Exception as exc:  # noqa: BLE001 - report what a device run met, and go on
        print(f"GPU: the CuPy run failed: {type(exc).__name__}: {exc}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=65_000)
    parser.add_argument("--streams", type=int, default=1024)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--transitions", type=int, default=4096)
    parser.add_argument("--samples", type=int, default=8, help="frames on which every part's pose is timed both ways")
    parser.add_argument("--quick", action="store_true", help="8 000 agents, 128 streams, 30 frames, 512 transitions")
    parser.add_argument("--running", choices=("all", "half"), default="all",
                        help="all streams Running (the acceptance case) or half Stopped by default")  # fmt: skip
    parser.add_argument("--clips", choices=("stream", "skeleton"), default="stream",
                        help="a clip per stream, or one per skeleton size at each stream's rate")  # fmt: skip
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    parser.add_argument("--device", action="store_true", help="also sample and blend a store in CuPy on a GPU")
    parser.add_argument("--lod-parts", default="65000,260000", help="agent parts of the level-of-detail crowds "
                        "(comma-separated; empty: skip)")  # fmt: skip
    args = parser.parse_args()
    if args.quick:
        args.agents, args.streams, args.frames, args.transitions = 8000, 128, 30, 512
    for name in ("cmu-mocap-bvh/01_01.bvh", "fox-gltf/Fox.glb", "robot-expressive-gltf/RobotExpressive.glb"):
        path = Path(args.data) / name
        if path.is_file():
            begin = time.perf_counter()
            clips = flockkit.io.read_clips(path)
            frames = sum(c.n_frames for c in clips.values())
            print(f"read_clips({name}): {len(clips)} clips, {frames} frames in {time.perf_counter() - begin:.3f} s")
    start = time.perf_counter()
    pool, clusters, bones, histories, stopped = build(args.agents, args.streams, clips=args.clips,
                                                      running=args.running)  # fmt: skip
    crowd = Crowd(pool, n_agents=args.agents, clusters=clusters, seed=1)
    setup = time.perf_counter() - start
    members = {name: np.flatnonzero(streams >= 0) for name, streams in clusters.items()}
    parts = sum(len(m) for m in members.values())
    distinct = len({id(s.controller.clip) for s in pool.streams})
    print(f"{args.agents} agents, {parts} agent parts in {len(SKELETONS)} clusters, {args.streams} streams "
          f"({int(stopped.sum())} Stopped by default) playing {distinct} clips of 90 frames, histories 20..120; "
          f"set up in {setup:.1f} s")  # fmt: skip
    for _ in range(40):  # past the streams' first refills
        crowd.update()
    rng = np.random.default_rng(2)
    movers = rng.choice(args.agents, size=args.transitions, replace=False)
    celebrations = np.flatnonzero((bones == 82) & stopped) if args.running == "half" else np.flatnonzero(bones == 82)
    begin = time.perf_counter()
    for k, group in enumerate(np.array_split(movers, 16)):  # 16 celebration streams start at once
        crowd.transition_to_streamed(group, "body", int(celebrations[k]), blend_time=0.5, time_to_dilate=2.0)
    transition = (time.perf_counter() - begin) * 1000
    direct = Direct(pool)
    compare_poses(crowd, direct, members, SKELETONS, Gaps())  # warm-up, not counted: the allocator's first blocks
    sampled = set(np.linspace(1, args.frames - 1, min(args.samples, args.frames)).astype(int).tolist())
    updates, ours, theirs, rows, gaps = [], [], [], [], Gaps()
    advances, buffers = [], []
    advance = pool.advance

    def timed_advance():  # the pool's share of each update
        begin = time.perf_counter()
        found = advance()
        advances.append((time.perf_counter() - begin) * 1000)
        return found

    pool.advance = timed_advance
    pose_buffer = np.empty((len(movers), SKELETONS["body"], 12), np.float32)
    for frame in range(args.frames):
        begin = time.perf_counter()
        crowd.update()
        updates.append((time.perf_counter() - begin) * 1000)
        begin = time.perf_counter()
        crowd.instance_buffer()
        buffers.append((time.perf_counter() - begin) * 1000)
        if frame == 4:  # mid-blend: sample the transitioning parts
            blend = measure_blend(crowd, movers, pose_buffer)
            blended, limit, moved_bytes = blend["out"], blend["limit"], blend["bytes"]
            assert np.all(crowd.alphas("body")[movers] > 0)
        if frame in sampled:
            mine, other = compare_poses(crowd, direct, members, SKELETONS, gaps)
            ours.append(mine)
            theirs.append(other)
            record = crowd.instance_buffer()
            blending = int(np.sum(record["blend_time"] > 0))
            fractional = (record["offset"] % 1 > 0) | ((record["blend_time"] > 0) & (record["target_offset"] % 1 > 0))
            dilating = int(np.sum(fractional))
            rows.append(f"  frame {frame:>4}: {blending:>5} parts blending, {dilating:>5} between two frames; "
                        f"poses() {mine:7.1f} ms, direct {other:7.1f} ms")  # fmt: skip
    buffer = ms(lambda: crowd.instance_buffer())
    copied = ms(lambda: crowd.instance_buffer().copy())
    updates = np.array(updates)
    print(f"{args.transitions} body parts transition at once: {transition:.1f} ms for the 16 calls")
    print(f"update: mean {updates.mean():.2f} ms, median {np.median(updates):.2f} ms, worst {updates.max():.2f} ms "
          f"(frame {int(np.argmax(updates))}; the 5 worst {', '.join(f'{u:.1f}' for u in np.sort(updates)[-5:])}) "
          f"over {args.frames} frames (target: update + instance_buffer <= 5 ms)")  # fmt: skip
    print(f"instance_buffer: {buffer:.3f} ms (a read-only view; copying it: {copied:.2f} ms, "
          f"{crowd.instance_buffer().nbytes / 2**20:.1f} MB)")  # fmt: skip
    print(f"blended poses of {args.transitions} parts ({blend['between']} reading their target between two frames), "
          f"interleaved best of 7: compiled into a reused buffer {blended:.2f} ms on {numba.get_num_threads()} threads "
          f"({blend['out1']:.2f} ms on 1), compiled into a new array "
          f"{blend['new']:.2f} ms, the same work vectorized with numpy (the array API path) "
          f"{blend['numpy']:.2f} ms; the two paths differ by at most {blend['gap']:.1e}")  # fmt: skip
    print(f"world poses (forward kinematics) of those parts: compiled {blend['world']:.2f} ms on "
          f"{numba.get_num_threads()} threads ({blend['world1']:.2f} ms on 1; blend included), "
          f"numpy Skeleton.world of the local poses {blend['numpy_world']:.2f} ms")  # fmt: skip
    advances, buffers = np.array(advances), np.array(buffers)
    frame = np.median(updates) + np.median(buffers)
    print(f"budget per frame (median of {args.frames} frames; {'all' if args.running == 'all' else 'half the'} "
          f"streams Running, {args.transitions} transitions started at frame 0; load {load()}):")  # fmt: skip
    print(f"  pool.advance (every Running stream's head)   {np.median(advances):7.2f} ms")
    print(f"  the rest of update (dilation, blends, roots) {np.median(updates) - np.median(advances):7.2f} ms")
    print(f"  instance_buffer                              {np.median(buffers):7.3f} ms")
    print(f"  update + instance_buffer                     {frame:7.2f} ms (target <= 5 ms: "
          f"{'met' if frame <= 5 else 'NOT met'})")  # fmt: skip
    print(f"  blended local poses of {args.transitions} parts       {blended:7.2f} ms; memory-bandwidth limit "
          f"(numpy copy of the {moved_bytes / 2**20:.1f} MiB they read and write) {limit:.2f} ms: "
          f"{blended / limit:.1f}x the limit (target <= 2x: {'met' if blended <= 2 * limit else 'NOT met'}; "
          f"on 1 thread {blend['out1'] / limit:.1f}x); "
          f"numpy (array API path) {blend['numpy']:.2f} ms, {blend['numpy'] / limit:.1f}x")  # fmt: skip
    print(f"    in CPU time (free of waits for the machine's other work): the blend on 1 thread "
          f"{blend['out1_cpu']:.2f} ms, the copy {blend['limit_cpu']:.2f} ms: "
          f"{blend['out1_cpu'] / blend['limit_cpu']:.1f}x")  # fmt: skip
    world = min(blend["world"], blend["world1"])
    print(f"  world poses of those parts                  {world:7.2f} ms (numpy FK alone "
          f"{blend['numpy_world']:.2f} ms)")  # fmt: skip
    memory = pool.memory_parts()
    total_new = equation_5(bones, histories)
    total_prev = equation_4(bones, histories, transitions=args.transitions)
    print(f"memory: pool {pool.memory() / 2**20:.1f} MiB = store {memory['store'] / 2**20:.1f} + prefetch "
          f"{memory['prefetch'] / 2**20:.1f} (+{memory['prefetch'] / memory['store']:.0%}) + batch tables "
          f"{memory['batch'] / 2**20:.1f} + bookkeeping "
          f"{memory['bookkeeping'] / 2**20:.1f}; Equation 5 {total_new / 2**20:.1f} MiB "
          f"({'equal to the store' if memory['store'] == total_new else 'NOT the store'}); Equation 4 (every stream "
          f"padded to 82 joints and 120 frames, {args.transitions} transition slots) {total_prev / 2**20:.1f} MiB; "
          f"difference (Equation 6) {(total_prev - total_new) / 2**20:.1f} MiB")  # fmt: skip
    if args.device:
        gpu(args, movers, celebrations)
    ours, theirs = np.array(ours), np.array(theirs)
    produced = ours.mean() + updates.mean()
    print(f"every agent part's local pose, per frame ({parts} parts; best of 3 on each of {len(ours)} frames):")
    print("\n".join(rows))
    print("  mean over those frames:")
    print(f"  flockkit update (mean of every frame) + poses(): {updates.mean():.2f} + {ours.mean():.1f} = "
          f"{produced:.1f} ms (poses() worst {ours.max():.1f} ms)")  # fmt: skip
    print(f"  direct numpy evaluation of each part's own clip: {theirs.mean():.1f} ms (worst {theirs.max():.1f} ms); "
          f"direct / flockkit = {theirs.mean() / produced:.2f}")  # fmt: skip
    print(gaps.report("part-frames"))
    print(f"  flockkit update alone (the instance buffer a skinning shader reads, no per-part pose): "
          f"{updates.mean():.2f} ms")  # fmt: skip
    sizes = [int(p) for p in args.lod_parts.split(",") if p.strip()]
    if sizes:
        print(
            f"level of detail: update + instance_buffer per frame (median of 60 frames; a quarter of the body "
            f"parts transitioning with time dilation; levels 0-3 by distance bands from a camera; load {load()}):"
        )
    for parts_wanted in sizes:
        lod_section(parts_wanted, args)


def lod_section(parts_wanted: int, args) -> None:
    """update + instance_buffer per frame for a crowd of about `parts_wanted` agent parts, without
    and with levels of detail from a camera: the same crowd run twice from the same seed."""
    per_agent = 2.2  # parts an agent has on average (build's shares: 1 + 0.3 + 0.5 + 0.4)
    n_agents = int(round(parts_wanted / per_agent))
    side = int(np.ceil(np.sqrt(n_agents)))
    times, shares = {}, None
    for with_lod in (False, True):
        pool, clusters, bones, _, _ = build(n_agents, args.streams, clips=args.clips, running=args.running)
        crowd = Crowd(pool, n_agents=n_agents, clusters=clusters, seed=1)
        parts = sum(int(np.sum(s >= 0)) for s in clusters.values())
        grid = np.arange(n_agents)
        crowd.placement[:, 0, 3], crowd.placement[:, 1, 3] = grid % side, grid // side  # 1 m apart
        for _ in range(10):
            crowd.update()
        if with_lod:  # a camera at a corner; bands that put about a quarter of the agents at each level
            distance = np.linalg.norm(crowd.placement[:, :3, 3], axis=1)
            levels = crowd.lod_from_camera((0.0, 0.0, 0.0), bands=np.quantile(distance, [0.25, 0.5, 0.75]))
            shares = np.bincount(levels, minlength=4) / n_agents
        movers = np.random.default_rng(2).choice(n_agents, size=n_agents // 4, replace=False)
        targets = np.flatnonzero(bones == 82)
        for k, group in enumerate(np.array_split(movers, 16)):
            crowd.transition_to_streamed(group, "body", int(targets[k]), blend_time=0.5, time_to_dilate=2.0)
        frame = []
        for _ in range(60):
            begin = time.perf_counter()
            crowd.update()
            crowd.instance_buffer()
            frame.append((time.perf_counter() - begin) * 1000)
        times[with_lod] = np.median(frame)
        del crowd, pool
    refreshed = float(np.sum(shares / 2.0 ** np.arange(4)))
    print(f"  {parts} parts ({n_agents} agents, {len(movers)} transitioning): all at level 0 {times[False]:6.2f} ms; "
          f"with levels ({', '.join(f'{s:.0%}' for s in shares)} at 0-3, {refreshed:.0%} of agents refreshed a "
          f"frame) {times[True]:6.2f} ms")  # fmt: skip


if __name__ == "__main__":
    main()
