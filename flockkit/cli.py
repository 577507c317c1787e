"""The ``flockkit`` command: a thin layer over the public API.

Every error becomes one line on stderr and a non-zero exit, never a traceback: 1 for errors, 2 for
usage, 3 when ``solve`` wrote a motion that does not meet its constraints, 70 for an error
flockkit did not foresee (a bug: ``FLOCKKIT_TRACEBACK=1`` shows it), 130 on Ctrl-C and 143 on
SIGTERM (temporary files removed, worker processes stopped). Output paths are checked before any
work. Warnings raised along the way are printed after the result, one line each, never before an
error line.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import time
import warnings
from pathlib import Path

import flockkit

from ._atomic import TERMINATED, check_writable
from .errors import FlockkitError, MissingDependencyError, ValidationError
from .registry import KINDS, describe

# per command, the keyword arguments its options set (and the option that sets each): a --param
# of one of these names would clash with them
_RESERVED = {
    "simulate": {"dt": "--dt", "n_agents": "--agents", "steps": "--steps", "seed": "--seed", "dims": "--dims",
                 "behavior": "--behavior", "progress": "--quiet", "initial": None,
                 "obstacles": "--obstacle or --arena"},
    "build": {"metric": "--metric", "builder": "--builder", "threshold": "--threshold", "n_jobs": "--jobs",
              "seed": "--seed", "progress": "--quiet", "metric_params": None, "motion": None,
              "segmentation": "--parts", "segmenter": None, "segmenter_params": None, "source": None},
    "segmenter": {"n_parts": "--parts"},
    "walk": {"duration": "--duration", "seed": "--seed", "strategy": "--strategy", "region": "--region",
             "graph": None},
}  # fmt: skip


def _parameters(pairs, command: str | None = None) -> dict:
    """``key=value`` strings to keyword arguments; values are read as JSON when they parse."""
    params = {}
    reserved = _RESERVED.get(command, {})
    for pair in pairs or ():
        key, sep, raw = pair.partition("=")
        if not sep or not key.isidentifier():
            raise ValidationError(f"--param expects key=value with key a Python identifier; got {pair!r}")
        if key in reserved:
            option = reserved[key]
            raise ValidationError(f"--param {key}: {f'set it with {option}' if option else 'not a parameter here'}")
        try:
            params[key] = json.loads(raw)
        except json.JSONDecodeError:
            params[key] = raw
    return params


def _require_suffix(path: str, suffixes: tuple[str, ...], option: str) -> Path:
    """The output `path`, checked before any work: a known suffix, and a file can be made there."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ValidationError(f"{option} {path}: unknown extension {path.suffix!r}; expected {' or '.join(suffixes)}")
    if not path.parent.is_dir():
        raise ValidationError(f"{option} {path}: folder {path.parent} does not exist")
    return check_writable(path)


def _cmd_plugins(args) -> int:
    rows = [(c.kind, c.name, c.plugin, c.distribution or "-", c.version or "-") for c in describe(args.kind)]
    header = ("kind", "name", "plugin", "distribution", "version")
    widths = [max(len(str(row[i])) for row in [header, *rows]) for i in range(len(header))]
    for row in [header, *rows]:
        print("  ".join(str(cell).ljust(width) for cell, width in zip(row, widths)).rstrip())
    return 0


def _cmd_simulate(args) -> int:
    output = _require_suffix(args.output, (".npz",), "-o")
    picture = None
    if args.picture:
        from .viz import PICTURE_SUFFIXES

        picture = _require_suffix(args.picture, PICTURE_SUFFIXES, "--picture")
    motion = flockkit.simulate(
        args.behavior,
        n_agents=args.agents,
        steps=args.steps,
        dims=args.dims,
        dt=args.dt,
        seed=args.seed,
        progress=not args.quiet and sys.stderr.isatty(),
        **_parameters(args.param, "simulate"),
        **_obstacles(args),
    )
    motion.save(output)
    print(f"wrote {output}: {motion!r}")
    if picture is not None:
        from .viz import plot_motion

        plot_motion(motion, picture)
        print(f"wrote {picture}")
    return 0


def _obstacles(args) -> dict:
    """The obstacles --arena and --obstacle ask for, as behavior parameters (none: no parameter)."""
    obstacles = [
        *(flockkit.fence(args.arena) if args.arena is not None else ()),
        *(_region(o, "--obstacle") for o in args.obstacle or ()),
    ]
    return {"obstacles": obstacles} if obstacles else {}


def _cmd_check(args) -> int:
    from .testing import check_plugin

    component = flockkit.get(args.kind, args.name, **_parameters(args.param))
    report = check_plugin(
        args.kind, component, name=args.name, partners=_partners(args.partner), progress=_progress(args)
    )
    print(f"{args.kind} {args.name!r}: {report.summary()}")
    return 0


def _partners(pairs) -> dict:
    """--partner metric=NAME, behavior=NAME (made with dt = 0.1 s, as the kit's motions) or
    graph=FILE.npz."""
    partners = {}
    for pair in pairs or ():
        key, sep, value = pair.partition("=")
        if not sep or key not in ("metric", "behavior", "graph"):
            raise ValidationError(f"--partner expects metric=NAME, behavior=NAME or graph=FILE.npz; got {pair!r}")
        if key == "graph":
            partners[key] = flockkit.MotionGraph.load(value)
        else:
            partners[key] = flockkit.get(key, value, **({"dt": 0.1} if key == "behavior" else {}))
    return partners


def _progress(args) -> bool:
    return not args.quiet and sys.stderr.isatty()


def _cmd_build(args) -> int:
    output = _require_suffix(args.output, (".npz",), "-o")
    source = _source(args.motion, args.clip, args.fps, args.allow_outside)
    params = _parameters(args.param, "build")
    if args.threshold is not None:
        params["threshold"] = args.threshold
    if args.layers or args.parts:
        segmentation = flockkit.Segmentation.load(args.parts) if args.parts else None
        layers = flockkit.build_layers(source, segmentation=segmentation, builder=args.builder or "windowed",
                                       seed=args.seed, **params)  # fmt: skip
        layers.save(output)
        counts = ", ".join(str(g.stats()["transitions"]) for g in layers.graphs)
        print(f"wrote {output}: {layers.n_parts} parts, each a graph (transitions: {counts})")
        return 0
    motion = source.motion if isinstance(source, flockkit.AnimatedMesh) else source
    if args.jobs is not None and args.backend is None:
        params["n_jobs"] = args.jobs
    with _backend(args):
        graph = flockkit.build_graph(
            motion, builder=args.builder or "kovar", metric=args.metric, seed=args.seed, progress=_progress(args),
            **params,
        )  # fmt: skip
    graph.save(output)
    stats = graph.stats()
    print(
        f"wrote {output}: {stats['nodes']} nodes, {stats['transitions']} transitions, {stats['fraction_kept']:.0%} of "
        "frames kept"
    )
    return 0


def _region(text: str, option: str = "--region"):
    """box:x0,y0,x1,y1 (or 3D: 6 numbers), ball:cx,cy[,cz],r, polygon:x0,y0,x1,y1,..."""
    kind, sep, numbers = text.partition(":")
    try:
        values = [float(v) for v in numbers.split(",")] if sep else []
    except ValueError:
        values = []
    if kind == "box" and len(values) in (4, 6):
        half = len(values) // 2
        return flockkit.Box(lower=values[:half], upper=values[half:])
    if kind == "ball" and len(values) in (3, 4):
        return flockkit.Ball(center=values[:-1], radius=values[-1])
    if kind == "polygon" and len(values) >= 6 and len(values) % 2 == 0:
        return flockkit.Polygon(vertices=[values[i : i + 2] for i in range(0, len(values), 2)])
    raise ValidationError(
        f"{option} {text!r}: expected box:x0,y0,x1,y1 (or 6 numbers in 3D), ball:cx,cy[,cz],r or "
        "polygon:x0,y0,x1,y1,x2,y2,..."
    )


def _cmd_walk(args) -> int:
    from ._npzfile import kind_of

    output = _require_suffix(args.output, (".npz",), "-o")
    layered = kind_of(args.graph) == "layers"
    graph = (flockkit.GraphLayers if layered else flockkit.MotionGraph).load(args.graph)
    params = _parameters(args.param, "walk")
    if args.region is not None:
        params["region"] = _region(args.region)
    path = flockkit.walk(graph, strategy=args.strategy, duration=args.duration, seed=args.seed, **params)
    motion = flockkit.synthesize(graph, path)
    if layered and graph.faces is not None:  # a mesh in, a mesh out: render draws its faces
        flockkit.AnimatedMesh(motion=motion, faces=graph.faces, name=Path(args.graph).stem).save(output)
    else:
        motion.save(output)
    print(f"wrote {output}: {motion!r}")
    return 0


MESH_SUFFIXES = (".glb", ".gltf", ".usda", ".usdc", ".usdz", ".usd", ".obj")


def _source(path: str, clip=None, fps=None, allow_outside=False):
    """A Motion or an AnimatedMesh: a flockkit .npz of either, or an animated-mesh file (glTF,
    USD, an OBJ folder or glob) read at `fps` (default 30) for `clip`."""
    from ._npzfile import kind_of

    glob = not Path(path).exists() and any(c in path for c in "*?[")
    if Path(path).suffix.lower() in MESH_SUFFIXES or Path(path).is_dir() or glob:
        return flockkit.io.read_mesh_animation(path, clip=clip, fps=30.0 if fps is None else fps,
                                               allow_outside=allow_outside)  # fmt: skip
    if kind_of(path) == "mesh":
        return flockkit.AnimatedMesh.load(path)
    return flockkit.Motion.load(path)


# Frames of the scene animation the CLI draws at most (frames are skipped evenly beyond): a
# minute-long scene stays a GIF of about a megabyte, drawn in seconds.
SCENE_GIF_FRAMES = 150


def _cmd_scene(args) -> int:
    from .scene import read_scene

    folder = Path(args.output)
    if folder.exists() and not folder.is_dir():
        raise ValidationError(f"-o must be a folder; {folder} is a file")
    scene = read_scene(args.scene, n_jobs=args.jobs, allow_outside=args.allow_outside)
    with _backend(args):
        animation = scene.synthesize(progress=not args.quiet)
    folder.mkdir(parents=True, exist_ok=True)
    animation.save(folder / "scene.npz")
    written = [folder / "scene.npz"]
    if not args.no_usd:
        animation.export(folder / "scene.usda")
        written.append(folder / "scene.usda")
    if not args.no_pictures:
        from .viz import animate_scene, plot_scene

        plot_scene(animation, folder / "scene.png")
        animate_scene(animation, folder / "scene.gif", max_frames=SCENE_GIF_FRAMES, progress=not args.quiet)
        written += [folder / "scene.png", folder / "scene.gif"]
    report = animation.report
    print(
        f"wrote {', '.join(str(p) for p in written)}: {animation.placement.n_objects} objects, "
        f"{animation.n_frames} frames; neighbours in step {report['in_step_before']:.1%} of frames before "
        f"de-synchronisation, {report['in_step_after']:.1%} after"
    )
    return 0


def _cmd_crowd(args) -> int:
    from .crowd.file import read_crowd_scene
    from .crowd.record import record

    folder = Path(args.output)
    if folder.exists() and not folder.is_dir():
        raise ValidationError(f"-o must be a folder; {folder} is a file")
    scene = read_crowd_scene(args.scene, allow_outside=args.allow_outside)
    if not args.no_usd:  # fail before the run, not after it, when usd-core is missing
        from .io.usd import require_usd_core

        require_usd_core()
    driver = scene.driver()
    recording = record(driver, scene.seconds, agents=range(scene.record))
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    if not args.no_usd:
        recording.export_usd(folder / "crowd.usdc")
        written.append(folder / "crowd.usdc")
    if not args.no_pictures:
        from .viz import animate_recording

        animate_recording(recording, folder / "crowd.gif", progress=not args.quiet)
        written.append(folder / "crowd.gif")
    summary = {
        "agents": driver.crowd.n_agents,
        "recorded": scene.record,
        "frames": recording.n_frames,
        "streams": [s.name for s in scene.streams],
        "stream switches": driver.switches,
        "memory (bytes)": driver.crowd.pool.memory(),
    }
    (folder / "crowd.json").write_text(json.dumps(summary, indent=2))
    written.append(folder / "crowd.json")
    print(f"wrote {', '.join(str(p) for p in written)}: {summary['agents']} agents, {summary['frames']} frames, "
          f"{summary['stream switches']} stream switches")  # fmt: skip
    return 0


def _cmd_segment(args) -> int:
    output = _require_suffix(args.output, (".npz",), "-o")
    source = _source(args.source, args.clip, args.fps, args.allow_outside)
    params = _parameters(args.param, "segmenter")
    if args.parts is not None:
        params["n_parts"] = args.parts
    found = flockkit.segment(source, segmenter=args.segmenter, seed=args.seed, **params)
    found.save(output)
    sizes = ", ".join(str(len(p)) for p in found.parts())
    print(f"wrote {output}: {found.n_parts} parts of {sizes} points")
    return 0


def _motion_document(motion) -> dict:
    return {
        "frames": motion.n_frames,
        "agents": motion.n_agents,
        "dims": motion.dims,
        "dt": motion.dt,
        "seconds": motion.duration,
        "channels": sorted(motion.channels),
    }


def _cmd_info(args) -> int:
    from ._npzfile import kind_of
    from .errors import FileFormatError

    kind = kind_of(args.file)
    if kind == "motion":
        document = {"kind": "motion", **_motion_document(flockkit.Motion.load(args.file))}
    elif kind == "graph":
        graph = flockkit.MotionGraph.load(args.file)
        # params and provenance are read-only mappings: JSON objects, like every other field
        document = {"kind": "graph", **graph.stats(), "params": graph.params, "provenance": graph.provenance}
    elif kind == "layers":
        layers = flockkit.GraphLayers.load(args.file)
        document = {"kind": "layers", **layers.stats(), "faces": 0 if layers.faces is None else len(layers.faces)}
    elif kind == "mesh":
        mesh = flockkit.AnimatedMesh.load(args.file)
        document = {"kind": "mesh", "name": mesh.name, "faces": len(mesh.faces), **_motion_document(mesh.motion)}
    elif kind == "segmentation":
        found = flockkit.Segmentation.load(args.file)
        document = {"kind": "segmentation", "parts": found.n_parts, "points": found.n_points,
                    "points_per_part": [len(p) for p in found.parts()]}  # fmt: skip
    else:
        raise FileFormatError(f"{args.file}: a flockkit {kind!r} file, which info does not describe")
    print(json.dumps(document, indent=2, default=dict))
    return 0


def _cmd_solve(args) -> int:
    from .constrained import load_scenario

    output = _require_suffix(args.output, (".npz",), "-o")
    problem, settings = load_scenario(args.scenario)
    for option in ("iterations", "refine", "starts", "chains", "seed"):
        if getattr(args, option) is not None:
            settings[option] = getattr(args, option)
    from .constrained.sampler import unmet

    with _backend(args):
        solution = flockkit.solve(problem, n_jobs=args.jobs, progress=_progress(args), **settings)
    solution.motion.save(output)
    rates = ", ".join(f"{name} {rate:.0%}" for name, rate in sorted(solution.acceptance.items())) or "none"
    print(f"wrote {output}: {solution.motion!r}")
    print(
        f"log g {solution.log_g[0]:.6g}; largest constraint residual {max(solution.residuals, default=0.0):.3g}; "
        f"accepted: {rates}"
    )
    missed = unmet(problem, solution.motion)
    if missed:
        index, residual, limit = max(missed, key=lambda m: m[1] - m[2])
        kind = type(problem.constraints[index]).__name__
        raise _Unmet(
            f"{len(missed)} constraint(s) not met; the worst is constraints[{index}] ({kind} at "
            f"t={problem.constraints[index].time:g}), off by {residual:.3g} (tolerance {limit:.3g}); {output} holds "
            "the closest motion found: the scenario asks for more than the behavior model can do there"
        )
    return 0


class _Unmet(FlockkitError):
    """solve wrote its best motion, but it misses a constraint: exit status 3."""


@contextlib.contextmanager
def _backend(args):
    """Run the command's parallel work on the joblib backend `--backend` names (with `--jobs`
    workers, default all): dask (a LocalCluster, or the scheduler at `--scheduler`), ray (a local
    Ray, or the cluster at `--scheduler`), loky, threading. Without it, joblib's default."""
    import joblib

    if args.backend is None:
        yield
        return
    workers = -1 if args.jobs is None else args.jobs
    if args.backend == "dask":
        try:
            from distributed import Client
        except ImportError:
            raise MissingDependencyError(
                "--backend dask needs dask.distributed: pip install 'flockkit[scale]'"
            ) from None
        with Client(args.scheduler) if args.scheduler else Client(), joblib.parallel_config("dask", n_jobs=workers):
            yield
    elif args.backend == "ray":
        try:
            import ray
            from ray.util.joblib import register_ray
        except ImportError:
            raise MissingDependencyError("--backend ray needs ray: pip install 'flockkit[scale]'") from None
        register_ray()
        ray.init(address=args.scheduler, include_dashboard=False, log_to_driver=False)
        try:
            with joblib.parallel_config("ray", n_jobs=workers):
                yield
        finally:
            ray.shutdown()
    else:
        with joblib.parallel_config(args.backend, n_jobs=workers):
            yield


def _cmd_demo(args) -> int:
    from .demo import run_demo

    begin = time.perf_counter()
    summary = run_demo(args.output, data=args.data, progress=_progress(args))
    graph = summary["graph"]
    print(
        f"graph: {graph['nodes']} nodes, {graph['transitions']} transitions; come-from-behind: largest residual "
        f"{max(summary['come-from-behind']['residuals']):.3g}; sticklebacks: "
        f"{'built' if isinstance(summary['sticklebacks'], dict) else summary['sticklebacks']}"
    )
    print(f"done in {time.perf_counter() - begin:.0f} s; everything is in {Path(args.output).resolve()}")
    return 0


def _cmd_render(args) -> int:
    from ._npzfile import kind_of
    from .viz import ANIMATION_SUFFIXES, PICTURE_SUFFIXES

    output = _require_suffix(args.output, PICTURE_SUFFIXES + ANIMATION_SUFFIXES, "-o")
    if Path(args.motion).suffix.lower() in MESH_SUFFIXES or kind_of(args.motion) == "mesh":
        from . import viz

        mesh = _source(args.motion, args.clip)
        parts = flockkit.Segmentation.load(args.parts) if args.parts else None
        size = None if args.size is None else _size(args.size)
        if output.suffix.lower() in ANIMATION_SUFFIXES:
            viz.animate_mesh(mesh, output, segmentation=parts, fps=args.fps, size=size, progress=_progress(args))
        else:
            viz.plot_mesh(mesh, output, segmentation=parts, size=size)
        print(f"wrote {output}")
        return 0
    motion = flockkit.Motion.load(args.motion)
    problem = None
    if args.scenario:
        from .constrained import load_scenario

        problem = load_scenario(args.scenario)[0]
    from . import viz

    regions = [_region(text) for text in args.region or ()]
    if output.suffix.lower() in ANIMATION_SUFFIXES:
        size = None if args.size is None else _size(args.size)
        viz.animate(
            motion,
            output,
            problem=problem,
            regions=regions,
            fps=args.fps,
            size=size,
            trail=args.trail,
            progress=_progress(args),
        )
    else:
        viz.plot_motion(motion, output, problem=problem, regions=regions)
    print(f"wrote {output}")
    return 0


def _cmd_export(args) -> int:
    from .io import EXPORT_SUFFIXES, export

    output = _require_suffix(args.output, EXPORT_SUFFIXES, "-o")
    motion = flockkit.Motion.load(args.motion)
    options = {k: v for k, v in (("fps", args.fps), ("meters_per_unit", args.units)) if v is not None}
    export(motion, output, **options)
    print(f"wrote {output}: {motion.n_frames} frames x {motion.n_agents} agents")
    return 0


def _cmd_import(args) -> int:
    output = _require_suffix(args.output, (".npz",), "-o")
    reader = {"long": flockkit.io.read_long, "wide": flockkit.io.read_wide}[args.format]
    motion = reader(
        args.table, dt=args.dt, fps=args.fps, dims=args.dims, max_gap=args.max_gap, image_height=args.image_height
    )
    motion.save(output)
    print(f"wrote {output}: {motion!r}")
    return 0


def _output(parser, help: str) -> None:
    parser.add_argument("-o", "--output", required=True, help=help)


def _quiet(parser) -> None:
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _param(parser, what: str) -> None:
    parser.add_argument("--param", action="append", metavar="KEY=VALUE", help=f"{what} parameter, repeatable")


def _scale_out(parser) -> None:
    parser.add_argument("--jobs", type=int, help="parallel workers (-1: all; default 1, or all with --backend)")
    parser.add_argument(
        "--backend", choices=("loky", "threading", "dask", "ray"), help="joblib backend (dask, ray: flockkit[scale])"
    )
    parser.add_argument("--scheduler", metavar="ADDRESS", help="with --backend dask or ray: the cluster to use")


def _plugins_arguments(parser) -> None:
    parser.add_argument("--kind", choices=KINDS, help="only this kind")


def _simulate_arguments(parser) -> None:
    parser.add_argument("--agents", type=int, required=True, help="number of agents (>= 1)")
    parser.add_argument("--steps", type=int, required=True, help="number of steps (>= 1)")
    parser.add_argument("--dims", type=int, default=2, choices=(2, 3), help="2 or 3 dimensions (default 2)")
    parser.add_argument("--dt", type=float, default=0.1, help="seconds per step (default 0.1)")
    parser.add_argument("--seed", type=int, default=None, help="random seed; the same seed gives the same motion")
    parser.add_argument("--behavior", default="boids", help="behavior model (default boids)")
    _param(parser, "behavior")
    parser.add_argument("--arena", type=float, metavar="R", help="fence the flock in a ring of posts R from the origin")
    parser.add_argument(
        "--obstacle", action="append", metavar="SPEC", help="an obstacle (as --region of walk), repeatable"
    )
    _output(parser, "motion file to write (.npz)")
    parser.add_argument("--picture", help="also draw the trajectories (.png, .pdf or .svg; needs flockkit[viz])")
    _quiet(parser)


def _mesh_options(parser) -> None:
    parser.add_argument("--clip", help="the clip of an animated-mesh file (default: its first)")
    parser.add_argument("--fps", type=float, help="frames per second to sample an animated-mesh file at (default 30)")
    _allow_outside(parser)


def _allow_outside(parser) -> None:
    parser.add_argument(
        "--allow-outside",
        action="store_true",
        help="let the input refer to files outside its folder (absolute paths, ..; see docs/security.md)",
    )


def _build_arguments(parser) -> None:
    parser.add_argument(
        "motion", help="motion or animated-mesh file (.npz from simulate, import or walk; .glb, .gltf, .usd*, OBJ)"
    )
    _output(parser, "graph file to write (.npz)")
    parser.add_argument("--metric", default="icp-hungarian", help="configuration metric (default icp-hungarian)")
    parser.add_argument("--builder", help="graph builder (default kovar; windowed for --layers)")
    parser.add_argument("--layers", action="store_true", help="split into parts and build one graph per part")
    parser.add_argument("--parts", help="the segmentation to use for --layers (.npz, from segment)")
    parser.add_argument("--seed", type=int, default=None, help="random seed (of the segmentation for --layers)")
    _mesh_options(parser)
    parser.add_argument("--threshold", type=float, help="absolute transition threshold (default: adaptive)")
    _scale_out(parser)
    _param(parser, "builder")
    _quiet(parser)


def _segment_arguments(parser) -> None:
    parser.add_argument("source", help="animated mesh (.glb, .gltf, .usd*, OBJ folder or glob) or motion (.npz)")
    _output(parser, "segmentation file to write (.npz)")
    parser.add_argument("--parts", type=int, help="number of parts (default: chosen by the segmenter)")
    parser.add_argument("--segmenter", default="ica-kmeans", help="segmenter (default ica-kmeans)")
    parser.add_argument("--seed", type=int, default=None, help="random seed")
    _mesh_options(parser)
    _param(parser, "segmenter")


def _walk_arguments(parser) -> None:
    parser.add_argument("graph", help="graph or layers file (.npz, from build)")
    parser.add_argument("--duration", type=float, required=True, help="seconds of motion to synthesize")
    parser.add_argument("--strategy", default="random", help="walk strategy (default random; region needs --region)")
    parser.add_argument(
        "--region", help="box:x0,y0,x1,y1 | ball:cx,cy,r | polygon:x0,y0,x1,y1,... (for --strategy region)"
    )
    parser.add_argument("--seed", type=int, default=None, help="random seed")
    _param(parser, "strategy")
    _output(parser, "motion file to write (.npz)")


def _info_arguments(parser) -> None:
    parser.add_argument("file", help="a .npz written by flockkit")


def _solve_arguments(parser) -> None:
    parser.add_argument("scenario", help="scenario file (.toml; see examples/scenarios)")
    _output(parser, "motion file to write (.npz)")
    parser.add_argument("--iterations", type=int, help="sampler iterations (default: the scenario's, else 1000)")
    parser.add_argument(
        "--refine", type=int, help="least-squares steps before sampling (default: the scenario's, else 40)"
    )
    parser.add_argument(
        "--starts",
        type=int,
        help="initial trajectories drawn per chain, the best kept (default: the scenario's, else 1)",
    )
    parser.add_argument("--chains", type=int, help="independent chains")
    parser.add_argument("--seed", type=int, help="random seed")
    _scale_out(parser)
    _quiet(parser)


def _demo_arguments(parser) -> None:
    parser.add_argument("-o", "--output", default="flockkit-demo", help="folder to write into (./flockkit-demo)")
    parser.add_argument("--data", help="folder of the shared captures (default: ../shared/data when present)")
    _quiet(parser)


def _size(text: str) -> tuple[int, int]:
    """--size WIDTHxHEIGHT in pixels."""
    width, sep, height = text.lower().partition("x")
    if not (sep and width.isdigit() and height.isdigit()):
        raise ValidationError(f"--size {text!r}: expected WIDTHxHEIGHT in pixels, e.g. 800x600")
    return int(width), int(height)


def _render_arguments(parser) -> None:
    parser.add_argument("motion", help="motion or animated-mesh file (.npz; or .glb, .gltf, .usd*)")
    parser.add_argument("--parts", help="colour an animated mesh's parts from this segmentation (.npz)")
    parser.add_argument("--clip", help="the clip of an animated-mesh file (default: its first), read at 30 fps")
    parser.add_argument("--fps", type=float, help="animation frames per second (default: real time, at most 25)")
    parser.add_argument(
        "--size", help="animation size WIDTHxHEIGHT in pixels (default: 600 on the scene's longer side, in proportion)"
    )
    parser.add_argument("--trail", type=float, default=1.0, help="seconds of path behind each agent (default 1)")
    _output(parser, "out.png | out.pdf | out.svg | out.gif | out.mp4 (needs flockkit[viz])")
    parser.add_argument("--scenario", help="also draw this scenario's constraints and obstacles (.toml)")
    parser.add_argument(
        "--region",
        action="append",
        help="also draw this region (repeatable): box:x0,y0,x1,y1 | ball:cx,cy,r | polygon:x0,y0,x1,y1,...",
    )
    _quiet(parser)


def _export_arguments(parser) -> None:
    parser.add_argument("motion", help="motion file (.npz)")
    _output(parser, "out.csv | out.json | out.glb | out.gltf | out.usda | out.usdc")
    parser.add_argument("--fps", type=float, help="USD: frame rate of the file's time line (default 24)")
    parser.add_argument("--units", type=float, help="USD: meters per flockkit length unit (default 1)")


def _import_arguments(parser) -> None:
    parser.add_argument("table", help="long (frame, agent, x, y[, z]) or wide (frame, x1, y1, x2, y2, ...) table")
    _output(parser, "motion file to write (.npz)")
    parser.add_argument("--format", choices=("long", "wide"), default="long", help="table layout (default long)")
    rate = parser.add_mutually_exclusive_group(required=True)
    rate.add_argument("--fps", type=float, help="frames per second of the capture")
    rate.add_argument("--dt", type=float, help="seconds per frame of the capture")
    parser.add_argument("--dims", type=int, default=2, choices=(2, 3), help="2 or 3 coordinates per agent")
    parser.add_argument(
        "--max-gap", type=int, default=flockkit.io.DEFAULT_MAX_GAP, help="longest run of missing frames to fill"
    )
    parser.add_argument(
        "--image-height",
        type=float,
        help="pixel positions in an image this tall, y pointing down (video trackers): y becomes HEIGHT - y",
    )


def _scene_arguments(parser) -> None:
    parser.add_argument("scene", help="scene file (.toml; see docs/concepts.md, scenes)")
    parser.add_argument(
        "-o", "--output", required=True, help="folder to write scene.npz, scene.usda, scene.png, scene.gif"
    )
    parser.add_argument("--no-usd", action="store_true", help="skip the USD export (needs flockkit[usd])")
    parser.add_argument(
        "--no-pictures", action="store_true", help="skip the top view and animation (need flockkit[viz])"
    )
    _allow_outside(parser)
    _scale_out(parser)
    _quiet(parser)


def _crowd_arguments(parser) -> None:
    parser.add_argument("scene", help="crowd scene file (.toml; see docs/concepts.md, massive crowds)")
    parser.add_argument("-o", "--output", required=True, help="folder to write crowd.usdc, crowd.gif, crowd.json")
    parser.add_argument("--no-usd", action="store_true", help="skip the USD export (needs flockkit[usd])")
    parser.add_argument("--no-pictures", action="store_true", help="skip the animation (needs flockkit[viz])")
    _allow_outside(parser)
    _quiet(parser)


def _check_arguments(parser) -> None:
    parser.add_argument("kind", choices=KINDS)
    parser.add_argument("name")
    _param(parser, "factory")
    parser.add_argument(
        "--partner",
        action="append",
        metavar="KIND=NAME",
        help="partner component of the checks: metric=NAME (builders), behavior=NAME (proposals), "
        "graph=FILE.npz (walks); default: the built-in, or the kit's own graph",
    )
    _quiet(parser)


# command -> (help, arguments, run), in the order `flockkit --help` lists them
COMMANDS = {
    "plugins": ("list installed plugin components", _plugins_arguments, _cmd_plugins),
    "simulate": ("simulate a flock and write its motion (.npz)", _simulate_arguments, _cmd_simulate),
    "build": ("build a motion graph from a motion (.npz)", _build_arguments, _cmd_build),
    "segment": (
        "split an animated mesh's vertices into parts that move independently",
        _segment_arguments,
        _cmd_segment,
    ),
    "walk": ("walk a motion graph (or layers) and write the synthesized motion (.npz)", _walk_arguments, _cmd_walk),
    "info": ("describe a flockkit file: motion, graph, layers, mesh or segmentation", _info_arguments, _cmd_info),
    "solve": ("solve a constrained-animation scenario (.toml) and write the motion", _solve_arguments, _cmd_solve),
    "demo": (
        "the tour: graph, synthesis, constrained flock, real fish; pictures and a summary",
        _demo_arguments,
        _cmd_demo,
    ),
    "render": (
        "draw a motion: a still (.png/.pdf/.svg) or an animation (.gif/.mp4)",
        _render_arguments,
        _cmd_render,
    ),
    "export": (
        "write a motion as CSV, JSON, glTF (.glb/.gltf) or USD (.usda/.usdc, needs flockkit[usd])",
        _export_arguments,
        _cmd_export,
    ),
    "scene": (
        "fill a region with duplicates of animated objects following arrows (.toml); write npz, USD, picture",
        _scene_arguments,
        _cmd_scene,
    ),
    "crowd": (
        "drive a crowd of skeletal characters along trajectories (.toml); write USD, animation, summary",
        _crowd_arguments,
        _cmd_crowd,
    ),
    "import": ("read a captured-motion table (CSV/TSV) into a motion (.npz)", _import_arguments, _cmd_import),
    "check": ("run the conformance kit on an installed plugin component", _check_arguments, _cmd_check),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="flockkit", description="Animate flocks, schools, herds and small crowds.")
    parser.add_argument("--version", action="version", version=f"flockkit {flockkit.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (help, arguments, run) in COMMANDS.items():
        command = commands.add_parser(name, help=help)
        arguments(command)
        command.set_defaults(run=run)
    return parser


class _Terminated(BaseException):
    """SIGTERM, raised where the command is so that every cleanup runs."""


_TERMINATION = []  # set when SIGTERM arrives: a library's cleanup may replace our exception with its own


def _terminate(signum, frame):
    _TERMINATION.append(signum)
    raise _Terminated


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    previous = signal.signal(signal.SIGTERM, _terminate)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = _run(args)
        finally:
            _stop_workers()
            signal.signal(signal.SIGTERM, previous)
    if code == 0:
        for message in dict.fromkeys(_line(w.message) for w in caught):
            print(f"flockkit {args.command}: warning: {message}", file=sys.stderr)
    return code


def _run(args) -> int:
    """Run the command; every exception becomes one line on stderr and an exit status."""
    _TERMINATION.clear()
    try:
        return args.run(args)
    except SystemExit:
        raise
    except BaseException as exc:  # noqa: BLE001 - each becomes its line and status below
        if _TERMINATION or isinstance(exc, _Terminated):
            print(f"flockkit {args.command}: terminated", file=sys.stderr)
            return TERMINATED
        if isinstance(exc, KeyboardInterrupt):
            print(f"flockkit {args.command}: interrupted", file=sys.stderr)
            return 130
        if isinstance(exc, _Unmet):
            return _fail(args, exc, 3)
        if isinstance(exc, FlockkitError | OSError | AssertionError | MemoryError):
            return _fail(args, exc, 1)
        if os.environ.get("FLOCKKIT_TRACEBACK") == "1" or not isinstance(exc, Exception):
            raise
        return _fail(args, exc, 70, prefix="internal error (please report; FLOCKKIT_TRACEBACK=1 shows where): ")


def _fail(args, exc: BaseException, code: int, prefix: str = "") -> int:
    kind = "" if isinstance(exc, FlockkitError | OSError | AssertionError) else f"{type(exc).__name__}: "
    print(f"flockkit {args.command}: error: {prefix}{kind}{_line(exc)}", file=sys.stderr)
    return code


def _line(message) -> str:
    return " ".join(line.strip() for line in str(message).splitlines() if line.strip())


def _stop_workers() -> None:
    """Stop the worker processes a command started (joblib's loky workers idle for minutes
    otherwise), however far their pool got: a SIGTERM may catch it half made."""
    import multiprocessing

    children = multiprocessing.active_children()
    for child in children:
        with contextlib.suppress(Exception):  # best effort: the command's result stands
            child.terminate()
    for child in children:
        with contextlib.suppress(Exception):
            child.join(timeout=10)


if __name__ == "__main__":
    sys.exit(main())
