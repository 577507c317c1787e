"""``flockkit demo``: the tour of the four parts, writing pictures, animations and a summary.

1. simulate a 20-agent flock turning inside an arena (a fence of round obstacles), 60 s;
2. build its motion graph, and draw the difference matrix with the chosen transitions marked,
   and the graph;
3. synthesize 2 minutes of motion kept inside a box by a region walk (a box a third of the
   arena's width, so that the walk has to steer: the group turns at its walls);
4. solve the come-from-behind scenario (paper 004, Figure 5) and draw its sampler trace;
5. fill a square with 12 flocks walked from that graph, each heading where the wind arrows point
   (east, turning north halfway), out of step with its neighbours (paper 002's scenes);
6. a crowd of 48 stick figures sharing two walking streams at their own offsets (paper 003):
   at 1 s half of them blend into a Stopped "cheer" stream, which starts, and time dilation
   spreads their offsets; at 3.5 s they walk again and the cheer stream stops;
7. with the shared captures present, build a graph from the five sticklebacks (pixels of a
   1280 x 720 video, read with y up) and walk it for a minute with the school's center kept one
   group radius inside the video frame;
8. with the shared data present, 2 000 Foxes driven by a 2 000-agent boids flock for 10 s: idle,
   or walking at the stream whose playback speed matches theirs, and at 4 s half of them run for
   3 s (a cue into a Stopped stream, dilated over 2 s); the 100 nearest the flock's centre drawn
   from above and written to USD as skinned Foxes (with usd-core);
9. with the shared data present, a scene of 8 Foxes walking out of step as a flow turns them
   from east to north (paper 002 with an animal), written to USD;
10. where a Python with Blender's bpy is found (FLOCKKIT_BPY_PYTHON, or this one), the
    synthesized flock, the Foxes' scene and the crowd of Foxes rendered in Blender (stills by
    Cycles, small and few samples; the Foxes turning as a short GIF by Workbench); otherwise the
    summary says the renders were skipped and why.

Every step is timed in summary.json's "seconds", drawing and rendering included.
"""

from __future__ import annotations

import contextlib
import json
import time
from pathlib import Path

import numpy as np

from flockkit import build_graph, simulate, synthesize, walk

from ..constrained.problem import ComConstraint, PointConstraint, Problem
from ..errors import FlockkitError, MissingDependencyError, ValidationError
from ..regions import Box
from ..regions import fence as arena
from ._options import add_quiet, shows_progress

STICKLEBACKS = Path("sticklebacks-5") / "ground_truth.csv"


def come_from_behind() -> tuple[Problem, dict]:
    """Paper 004, Figure 5, as examples/scenarios/come-from-behind.toml poses it (a test holds the
    two equal): agent 0 starts behind the flock, whose centre is constrained, and is in front of it
    14 s later, in a race long enough for the model's speeds. (Problem, ``solve``'s settings)."""
    rest = list(range(1, 20))
    problem = Problem(
        n_agents=20,
        duration=16.0,
        constraints=[
            PointConstraint(agent=0, time=1.0, position=[-1.5, 0.0], velocity=[1.1, 0.0]),
            PointConstraint(agent=0, time=15.0, position=[15.5, 0.0], velocity=[1.1, 0.0]),
            ComConstraint(agents=rest, time=1.0, position=[0.0, 0.0], velocity=[1.0, 0.0]),
            ComConstraint(agents=rest, time=15.0, position=[14.0, 0.0], velocity=[1.0, 0.0]),
        ],
    )
    return problem, {"iterations": 1000, "refine": 0, "seed": 2}


def difference_matrix(motion, *, interval: float, metric="icp-hungarian"):
    """E between frames `interval` seconds apart, (K, K), and the frame stride used; `metric` a
    name or an instance (its declared `pairwise` is used where it has one)."""
    from scipy.spatial.distance import squareform

    from ..interfaces import capabilities
    from ..registry import resolve

    measure = resolve("metric", metric)
    stride = max(1, round(interval / motion.dt))
    configurations = [motion.configuration(t) for t in range(0, motion.n_frames, stride)]
    if capabilities(measure).pairwise:
        return squareform(measure.pairwise(configurations)), stride
    i, j = np.triu_indices(len(configurations), 1)
    distances = [measure.compare(configurations[a], configurations[b]).distance for a, b in zip(i, j)]
    return squareform(np.array(distances)), stride


def shared_data_folder(given=None) -> Path | None:
    """`given`, else ../shared/data beside the working folder or beside this checkout."""
    candidates = (
        [Path(given)]
        if given
        else [Path.cwd().parent / "shared" / "data", Path(__file__).resolve().parents[2] / "shared" / "data"]
    )
    for folder in candidates:
        if (folder / STICKLEBACKS).is_file():
            return folder
    if given:
        raise ValidationError(f"--data {given}: no {STICKLEBACKS} there")
    return None


class _Tour:
    """Where the demo writes, what it wrote, and how long each step took."""

    def __init__(self, out: Path, progress: bool):
        self.out, self.progress = out, progress
        self.timings: dict[str, float] = {}
        self.written: list[str] = []

    @contextlib.contextmanager
    def step(self, name: str):
        begin = time.perf_counter()
        try:
            yield
        finally:  # a step that fails (a render the summary reports as failed) is timed too
            self.timings[name] = round(time.perf_counter() - begin, 2)

    def path(self, name: str) -> Path:
        self.written.append(str(self.out / name))
        return self.out / name


def run_demo(out, *, data=None, progress=False, report=print) -> dict:
    """Run the demo into folder `out` (created if needed); return the summary it writes."""
    begin = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tour = _Tour(out, progress)
    data_driven, graph, synthesized = _data_driven(tour)
    summary = {
        **data_driven,
        "come-from-behind": _constrained(tour),
        "scene": _scene(tour, graph),
        "crowd": _crowd(tour),
    }
    folder = shared_data_folder(data)
    if folder is None:
        summary["sticklebacks"] = "skipped: ../shared/data/sticklebacks-5 not found (use --data)"
        summary["foxes"] = "skipped: ../shared/data/fox-gltf not found (use --data)"
        summary["fox scene"] = "skipped: ../shared/data/fox-gltf not found (use --data)"
    else:
        summary["sticklebacks"] = _sticklebacks(tour, folder)
        summary["foxes"] = _foxes(tour, folder)
        summary["fox scene"] = _fox_scene(tour, folder)
    summary["renders"] = _renders(tour, synthesized, summary)
    summary["seconds"] = {**tour.timings, "the whole demo": round(time.perf_counter() - begin, 2)}
    tour.path("summary.json").write_text(json.dumps(summary, indent=2, default=float))
    for path in tour.written:
        report(f"wrote {path}")
    return summary


def _data_driven(tour: _Tour) -> tuple[dict, object, object]:
    """Paper 000: a recording in an arena, its graph, and 2 minutes synthesized inside a box;
    the summary, the graph and the synthesized motion."""
    from .. import viz

    fence = arena(15.0, posts=24)
    with tour.step("simulate 60 s of 20 boids"):
        recording = simulate(n_agents=20, steps=600, seed=1, obstacles=fence)
    with tour.step("build the motion graph"):
        graph = build_graph(recording, seed=1, n_jobs=-1, progress=tour.progress)
    with tour.step("draw the recording, its differences and its graph"):
        viz.plot_motion(recording, tour.path("recording.png"), obstacles=fence, title="the recording: 20 boids, 60 s")
        values, stride = difference_matrix(recording, interval=0.5)
        marked = [(t.start // stride, t.end // stride) for t in graph.transitions if not t.is_turn]
        viz.plot_difference_matrix(
            values,
            tour.path("difference-matrix.png"),
            marked=marked,
            title="E, frames 0.5 s apart (circles: transitions)",
        )
        viz.plot_graph(graph, tour.path("graph.png"))

    box = Box(lower=[-10.0, -10.0], upper=[10.0, 10.0])  # the arena is 30 units across
    with tour.step("synthesize 2 min in a box"):
        synthesized = synthesize(graph, walk(graph, strategy="region", region=box, duration=120, seed=2))
    title = "2 minutes synthesized, its center of mass kept in the box"
    shown = {"region for the center of mass": box}
    with tour.step("draw the synthesized flock (png, gif)"):
        viz.plot_motion(synthesized, tour.path("synthesized.png"), regions=shown, title=title)
        viz.animate(synthesized, tour.path("synthesized.gif"), regions=shown, progress=tour.progress)
    com = synthesized.center_of_mass()
    inside = bool(box.contains(com).all())
    crossed = (com.max(axis=0) - com.min(axis=0)) / (box.upper - box.lower)
    return (
        {
            "graph": graph.stats(),
            "synthesized": {
                "seconds": synthesized.duration,
                "agents": synthesized.n_agents,
                "center of mass in the box": inside,
                "share of the box crossed": [round(float(c), 3) for c in crossed],
            },
        },
        graph,
        synthesized,
    )


def _scene(tour: _Tour, graph) -> dict:
    """Paper 002: a scene of flocks following arrows that turn halfway."""
    from .. import viz
    from ..regions import Polygon
    from ..scene import Arrow, FlowField, Scene

    wind = FlowField(arrows=[Arrow(position=[0.0, 0.0], keyframes=[(0.0, [0.7, 0.0]), (19.0, [0.7, 0.0]),
                                                                  (21.0, [0.0, 0.7])])])  # fmt: skip
    square = Polygon(vertices=[[-60.0, -60.0], [60.0, -60.0], [60.0, 60.0], [-60.0, 60.0]])
    with tour.step("a scene of 12 flocks for 40 s"):
        # the arrows weigh three times the default against transitions: a boids recording wobbles
        scene = Scene(templates=[graph], region=square, counts=[12], duration=40.0, constraints=[wind], seed=2,
                      walk_params={"alpha": 30.0})  # fmt: skip
        animation = scene.synthesize(progress=tour.progress)
    with tour.step("draw the scene (png, gif)"):
        viz.plot_scene(animation, tour.path("scene.png"))
        viz.animate_scene(animation, tour.path("scene.gif"), progress=tour.progress)
    targets = scene.targets(animation.placement)
    within = []
    for motion, target in zip(animation.motions, targets):
        heading = np.gradient(motion.center_of_mass(), motion.dt, axis=0)
        cosine = np.sum(heading * target[:, :2], axis=1) / np.maximum(
            np.linalg.norm(heading, axis=1) * np.linalg.norm(target[:, :2], axis=1), 1e-12
        )
        within.append(float(np.mean(cosine >= np.cos(np.radians(30)))))
    return {
        "flocks": animation.placement.n_objects,
        "seconds": animation.n_frames * animation.dt,
        "share of frames heading within 30 degrees of the arrow (least, median)": [
            round(min(within), 3),
            round(float(np.median(within)), 3),
        ],
        "neighbours in step (first walks, end)": [
            animation.report["in_step_before"],
            animation.report["in_step_after"],
        ],
    }


def _crowd(tour: _Tour) -> dict:
    """Paper 003: a crowd of stick figures on shared streams; half cheer, then walk again."""
    from .. import viz
    from ..crowd import Crowd, Stream, StreamPool, equation_5, record
    from ..registry import get
    from ..testing.inputs import walker

    clip = walker()
    cheer = get("controller", "blend", a=get("controller", "clip", clip=clip, rate=2.6),
                b=get("controller", "clip", clip=walker(swing=70.0), rate=0.8), weight=0.6)  # fmt: skip
    streams = [
        Stream(controller=get("controller", "clip", clip=clip), history=60, name="walk"),
        Stream(controller=get("controller", "clip", clip=clip, rate=1.3), history=45, name="walk x1.3"),
        Stream(controller=cheer, history=60, default="Stopped", name="cheer"),
    ]
    pool = StreamPool(streams, fps=30.0)
    crowd = Crowd(pool, n_agents=48, clusters={"body": np.arange(48) % 2}, seed=3)
    cheering, offsets, running = np.arange(0, 48, 2), [], {}

    def script(crowd, frame):
        if frame == 30:
            crowd.transition_to_streamed(cheering, "body", 2, blend_time=0.4, time_to_dilate=3.0)
            running["at the cheer"] = crowd.pool.is_running(2)
        if frame == 105:
            crowd.transition_to_streamed(cheering, "body", 0, blend_time=0.4)
        if 30 <= frame < 105:
            offsets.append(crowd.offsets("body")[cheering])

    with tour.step("a crowd of 48 for 5 s"):
        recording = record(crowd, 5.0, agents=range(48), on_frame=script)
    offsets = np.array(offsets)
    with tour.step("draw the crowd (gif) and its offsets"):
        viz.animate_recording(recording, tour.path("crowd.gif"), layout="grid", axes="yz", pool=pool,
                              progress=tour.progress)  # fmt: skip
        viz.plot_offsets((30 + np.arange(len(offsets))) / 30.0, offsets, tour.path("crowd-offsets.png"),
                         title="offsets of the cheering half after the cheer stream starts")  # fmt: skip
    return {
        "agents": crowd.n_agents,
        "streams": len(streams),
        "memory (bytes, Equation 5)": [pool.memory_parts()["store"], equation_5(pool.bones, pool.history)],
        "memory (bytes, all the pool holds)": pool.memory(),
        "cheer stream running (at the cheer, at the end)": [running["at the cheer"], pool.is_running(2)],
        "distinct offsets among the cheering half (at the start, at 3.5 s)": [
            int(len(np.unique(offsets[0]))),
            int(len(np.unique(np.rint(offsets[-1])))),
        ],
    }


FOX = Path("fox-gltf") / "Fox.glb"
# the Fox's legs as (upper, middle, foot) joints, for planting its feet (flockkit.crowd.plant_feet)
FOX_LEGS = [("b_LeftLeg01_015", "b_LeftLeg02_016", "b_LeftFoot02_018"),
            ("b_RightLeg01_019", "b_RightLeg02_020", "b_RightFoot02_022"),
            ("b_RightUpperArm_06", "b_RightForeArm_07", "b_RightHand_08"),
            ("b_LeftUpperArm_09", "b_LeftForeArm_010", "b_LeftHand_011")]  # fmt: skip
FOX_FEET = [foot for _, _, foot in FOX_LEGS]
# The Foxes the demo keeps of its crowd (drawn, written to USD, rendered): a group near the flock's
# centre, each big enough to see in a 640-pixel GIF, and few enough that Blender imports them in
# seconds (the whole 2 000 take it a minute).
FOX_GROUP = 100


def _foxes(tour: _Tour, folder: Path) -> dict:
    """Paper 003 driven by paper 004's model: a few thousand Foxes follow a boids flock; the
    FOX_GROUP nearest the flock's centre at the start are kept, drawn and written to USD."""
    from .. import viz
    from ..crowd import Crowd, Cue, Driver, Gait, StateMachine, Stream, StreamPool, ground_speed, plant_feet, record
    from ..io import read_clips
    from ..io.skin import read_skin
    from ..registry import get

    fps, seconds, n = 24.0, 10.0, 2000
    with tour.step("read the Fox's clips and simulate a 2 000-boid flock"):
        clips = read_clips(folder / FOX)
        clips["Walk"] = plant_feet(clips["Walk"], FOX_LEGS)  # its paws otherwise slide at any rate
        scale = 0.01  # the Fox is modelled in centimetres; the flock moves in metres
        natural = ground_speed(clips["Walk"], FOX_FEET, scale=scale)
        rates = (0.8, 1.0, 1.25)
        streams = [Stream(controller=get("controller", "clip", clip=clips["Survey"]), history=60, name="idle")]
        streams += [Stream(controller=get("controller", "clip", clip=clips["Walk"], rate=r), history=40,
                           name=f"walk x{r}") for r in rates]  # fmt: skip
        streams.append(Stream(controller=get("controller", "clip", clip=clips["Run"]), history=48, default="Stopped",
                              name="run"))  # fmt: skip
        walking = Gait(name="walk", streams=[1, 2, 3], speeds=[natural * r for r in rates], low=0.2)
        machine = StateMachine([Gait(name="idle", streams=0, high=0.2), walking])
        runners = np.arange(0, n, 2)
        cue = Cue(time=4.0, agents=runners, stream=4, duration=3.0, time_to_dilate=2.0, name="run")
        flock = simulate(n_agents=n, steps=int(seconds * fps), dt=1 / fps, seed=3)
        start = flock.positions[0]
        group = np.sort(np.argsort(np.linalg.norm(start - start.mean(axis=0), axis=1))[:FOX_GROUP])

    with tour.step("2 000 Foxes driven by a boids flock for 10 s"):
        pool = StreamPool(streams, fps=fps)
        driver = Driver(Crowd(pool, n_agents=n, clusters={"body": 1}, seed=4), flock, machine, scale=scale,
                        cues=[cue])  # fmt: skip
        synchrony = {}

        def watch(crowd, frame):
            if frame in (int(4.0 * fps) + 1, int(6.0 * fps) + 1):
                synchrony[frame / fps] = crowd.synchrony("body", runners)

        shown = record(driver, seconds, agents=group, on_frame=watch)
    usd = "skipped: usd-core is not installed (pip install 'flockkit[usd]')"
    try:
        with tour.step(f"{FOX_GROUP} of the Foxes written to USD, skinned"):
            shown.export_usd(tour.path("foxes.usdc"), mesh=read_skin(folder / FOX))
        usd = "foxes.usdc"
    except MissingDependencyError:
        tour.written.pop()
    title = f"{FOX_GROUP} of {n:,} Foxes, those nearest the flock's centre"
    with tour.step(f"draw {FOX_GROUP} of the Foxes (gif)"):
        viz.animate_recording(shown, tour.path("foxes.gif"), pool=pool, fps=12, size=(600, 640), title=title,
                              progress=tour.progress)  # fmt: skip
    root = driver.roots[:, :2, 3]
    return {
        "agents": n,
        "shown and written": FOX_GROUP,
        "frames": shown.n_frames,
        "streams": [s.name for s in streams],
        "stream switches": driver.switches,
        "runners in step with another (just after the cue, 2 s later)": [round(v, 3) for v in synchrony.values()],
        "roots on their trajectories": bool(np.allclose(root, flock.positions[shown.n_frames - 1, :, :2], atol=1e-9)),
        "usd": usd,
        "memory (bytes)": pool.memory(),
    }


def _fox_scene(tour: _Tour, folder: Path) -> dict:
    """Paper 002 with an animal: Foxes walking out of step across a meadow, moved and turned by a
    flow that turns from east to north, their paws planted (the Fox's walk played in place at
    the rate that matches the speed asked)."""
    from .. import build_layers
    from ..io import read_mesh_animation
    from ..regions import Polygon
    from ..scene import Arrow, Features, FlowField, Scene

    with tour.step("a scene of 8 walking Foxes for 8 s"):
        fox = read_mesh_animation(folder / FOX, clip="Walk", fps=24).to_flockkit_axes(meters_per_unit="cm")
        stride = Features.from_stride(fox.motion, forward=[0, -1])  # the Fox faces -y in flockkit's axes
        layers = build_layers(fox, features=stride, seed=0)
        turning = FlowField(arrows=[Arrow(position=[6.0, 6.0], keyframes=[(0.0, [0.7, 0.0]), (3.0, [0.7, 0.0]),
                                                                          (6.0, [0.0, 0.7])])])  # fmt: skip
        meadow = Polygon(vertices=[[0.0, 0.0], [12.0, 0.0], [12.0, 12.0], [0.0, 12.0]])  # metres
        scene = Scene(templates=[layers], region=meadow, counts=[8], duration=8.0, constraints=[turning], seed=2,
                      headings="aligned", max_turn=np.radians(60))  # fmt: skip
        animation = scene.synthesize(progress=tour.progress)
    usd = "skipped: usd-core is not installed (pip install 'flockkit[usd]')"
    try:
        with tour.step("the Foxes' scene written to USD"):
            animation.export(tour.path("fox-scene.usdc"))
        usd = "fox-scene.usdc"
    except MissingDependencyError:
        tour.written.pop()
    speeds = np.linalg.norm(np.diff(animation.paths.positions, axis=1), axis=2) / animation.dt
    return {
        "foxes": animation.placement.n_objects,
        "seconds": animation.n_frames * animation.dt,
        "speed (m/s, least and most)": [round(float(speeds.min()), 3), round(float(speeds.max()), 3)],
        "neighbours in step (first walks, end)": [
            animation.report["in_step_before"],
            animation.report["in_step_after"],
        ],
        "usd": usd,
    }


# Renders: small and few samples, so that each takes seconds on two cores; the video (Workbench)
# smaller still, at 8 frames a second, over the seconds the Foxes' flow turns them.
RENDER_SIZE, RENDER_SAMPLES = (480, 270), 8
VIDEO_SIZE, VIDEO_FPS, VIDEO_TIME = (320, 180), 8.0, (2.0, 6.0)


def _renders(tour: _Tour, synthesized, summary: dict) -> dict | str:
    """The flock, the scene of Foxes (a still and a short video) and the crowd of Foxes rendered
    in Blender, where a Python with bpy is found (FLOCKKIT_BPY_PYTHON); what was skipped and why,
    otherwise."""
    from ..viz.render import blender_python, render_blender

    try:
        blender_python()
    except MissingDependencyError as exc:
        return f"skipped: {exc}"
    still = {"size": RENDER_SIZE, "samples": RENDER_SAMPLES}
    jobs = [("the flock", synthesized, "render-flock.png", {"time": 60.0, **still})]
    scene, crowd = summary.get("fox scene"), summary.get("foxes")
    if isinstance(scene, dict) and scene["usd"] == "fox-scene.usdc":
        jobs.append(("the Foxes' scene", tour.out / "fox-scene.usdc", "render-fox-scene.png", {"time": 6.0, **still}))
        video = {"time": VIDEO_TIME, "fps": VIDEO_FPS, "size": VIDEO_SIZE}
        jobs.append(("the Foxes' scene as they turn", tour.out / "fox-scene.usdc", "render-fox-scene.gif", video))
    if isinstance(crowd, dict) and crowd["usd"] == "foxes.usdc":
        jobs.append(("the crowd of Foxes", tour.out / "foxes.usdc", "render-foxes.png", {"time": 6.0, **still}))
    done = {}
    for name, source, picture, options in jobs:
        try:
            with tour.step(f"render {name} in Blender"):
                render_blender(source, tour.path(picture), **options)
        except MissingDependencyError as exc:  # a flock is exported to USD first
            tour.written.pop()
            done[name] = f"skipped: {exc}"
            continue
        except FlockkitError as exc:  # Blender failed: the rest of the tour stands, and says so
            tour.written.pop()
            done[name] = f"failed: {exc}"
            continue
        when = options["time"]
        done[name] = f"{picture} ({f'{when[0]:g} to {when[1]:g} s' if isinstance(when, tuple) else f'at {when:g} s'})"
    return done


def _constrained(tour: _Tour) -> dict:
    """Paper 004: the come-from-behind scenario and its sampler trace."""
    from .. import viz
    from ..constrained import solve

    problem, settings = come_from_behind()
    with tour.step("solve come-from-behind"):
        solution = solve(problem, **settings, progress=tour.progress)
    title = "come from behind to win (paper 004, Fig. 5)"
    with tour.step("draw come-from-behind and its trace"):
        viz.plot_motion(solution.motion, tour.path("come-from-behind.png"), problem=problem, title=title)
        viz.animate(solution.motion, tour.path("come-from-behind.gif"), problem=problem, progress=tour.progress)
        viz.plot_trace(solution, tour.path("trace.png"))
    return {"log g": solution.log_g[0], "residuals": list(solution.residuals), "acceptance": solution.acceptance}


def _sticklebacks(tour: _Tour, folder: Path) -> dict:
    """Real fish: a graph of five sticklebacks and a minute walked from it."""
    from .. import viz
    from ..io import read_wide

    with tour.step("sticklebacks: read, graph and a 60 s walk"):
        fish = read_wide(folder / STICKLEBACKS, fps=15, image_height=720)  # pixels, y down in the video
        com = fish.center_of_mass()
        radius = float(np.sqrt(np.mean(np.sum((fish.positions - com[:, None]) ** 2, axis=-1))))
        frame = Box(lower=[0.0, 0.0], upper=[1280.0, 720.0])
        inner = Box(lower=[radius, radius], upper=[1280.0 - radius, 720.0 - radius])
        # fish swim 200 px/s and turn fast: short blends and 30 degree turns every second keep them in the frame
        fish_graph = build_graph(fish, seed=0, blend_time=1.0, turn_angle=30.0, turn_interval=1.0)
        fish_walk = synthesize(fish_graph, walk(fish_graph, strategy="region", region=inner, duration=60, seed=3))
    title = "60 s synthesized from 20 s of five sticklebacks, kept in the video frame"
    shown = {"video frame (1280 x 720 px)": frame, "where the school's center is kept": inner}
    with tour.step("draw the sticklebacks (png, gif)"):
        viz.plot_motion(fish_walk, tour.path("sticklebacks.png"), regions=shown, title=title, unit="px")
        viz.animate(fish_walk, tour.path("sticklebacks.gif"), regions=shown, unit="px", progress=tour.progress)
    return {
        **fish_graph.stats(),
        "center kept in the video frame": bool(inner.contains(fish_walk.center_of_mass()).all()),
    }


def _cmd_demo(args) -> int:
    begin = time.perf_counter()
    summary = run_demo(args.output, data=args.data, progress=shows_progress(args))
    graph = summary["graph"]
    print(
        f"graph: {graph['nodes']} nodes, {graph['transitions']} transitions ({graph['turns']} of them turns); "
        f"come-from-behind: largest residual "
        f"{max(summary['come-from-behind']['residuals']):.3g}; sticklebacks: "
        f"{'built' if isinstance(summary['sticklebacks'], dict) else summary['sticklebacks']}"
    )
    renders = summary["renders"]
    print(f"renders in Blender: {', '.join(renders.values()) if isinstance(renders, dict) else renders}")
    print(f"done in {time.perf_counter() - begin:.0f} s; everything is in {Path(args.output).resolve()}")
    return 0


def _demo_arguments(parser) -> None:
    parser.add_argument("-o", "--output", default="flockkit-demo", help="folder to write into (./flockkit-demo)")
    parser.add_argument("--data", help="folder of the shared captures (default: ../shared/data when present)")
    add_quiet(parser)


# command -> (help, arguments, run)
COMMANDS = {
    "demo": (
        "the tour: graph, synthesis, constrained flock, real fish; pictures and a summary",
        _demo_arguments,
        _cmd_demo,
    ),
}
