"""The ``flockkit`` command: a thin layer over the public API.

Every error becomes one line on stderr and a non-zero exit (1 for errors, 2 for usage), never a
traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import flockkit

from .errors import FlockkitError, ValidationError
from .registry import KINDS, describe


def _parameters(pairs) -> dict:
    """``key=value`` strings to keyword arguments; values are read as JSON when they parse."""
    params = {}
    for pair in pairs or ():
        key, sep, raw = pair.partition("=")
        if not sep or not key.isidentifier():
            raise ValidationError(f"--param expects key=value with key a Python identifier; got {pair!r}")
        try:
            params[key] = json.loads(raw)
        except json.JSONDecodeError:
            params[key] = raw
    return params


def _require_suffix(path: str, suffixes: tuple[str, ...], option: str) -> Path:
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ValidationError(f"{option} {path}: unknown extension {path.suffix!r}; expected {' or '.join(suffixes)}")
    if not path.parent.is_dir():
        raise ValidationError(f"{option} {path}: folder {path.parent} does not exist")
    return path


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
        **_parameters(args.param),
    )
    motion.save(output)
    print(f"wrote {output}: {motion!r}")
    if picture is not None:
        from .viz import plot_motion

        plot_motion(motion, picture)
        print(f"wrote {picture}")
    return 0


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
    motion = flockkit.Motion.load(args.motion)
    params = _parameters(args.param)
    if args.threshold is not None:
        params["threshold"] = args.threshold
    if args.jobs is not None:
        params["n_jobs"] = args.jobs
    graph = flockkit.build_graph(motion, builder=args.builder, metric=args.metric, progress=_progress(args), **params)
    graph.save(output)
    stats = graph.stats()
    print(
        f"wrote {output}: {stats['nodes']} nodes, {stats['transitions']} transitions, {stats['fraction_kept']:.0%} of "
        "frames kept"
    )
    return 0


def _region(text: str):
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
        f"--region {text!r}: expected box:x0,y0,x1,y1 (or 6 numbers in 3D), ball:cx,cy[,cz],r or "
        "polygon:x0,y0,x1,y1,x2,y2,..."
    )


def _cmd_walk(args) -> int:
    output = _require_suffix(args.output, (".npz",), "-o")
    graph = flockkit.MotionGraph.load(args.graph)
    params = _parameters(args.param)
    if args.region is not None:
        params["region"] = _region(args.region)
    path = flockkit.walk(graph, strategy=args.strategy, duration=args.duration, seed=args.seed, **params)
    motion = flockkit.synthesize(graph, path)
    motion.save(output)
    print(f"wrote {output}: {motion!r}")
    return 0


def _cmd_info(args) -> int:
    from .errors import FileFormatError

    try:
        graph = flockkit.MotionGraph.load(args.file)
    except FileFormatError as not_graph:
        try:
            motion = flockkit.Motion.load(args.file)
        except FileFormatError:
            raise not_graph from None
        print(
            json.dumps(
                {
                    "kind": "motion",
                    "frames": motion.n_frames,
                    "agents": motion.n_agents,
                    "dims": motion.dims,
                    "dt": motion.dt,
                    "seconds": motion.duration,
                    "channels": sorted(motion.channels),
                },
                indent=2,
            )
        )
        return 0
    print(
        json.dumps(
            {"kind": "graph", **graph.stats(), "params": graph.params, "provenance": graph.provenance},
            indent=2,
            default=str,
        )
    )
    return 0


def _cmd_solve(args) -> int:
    from .solve import load_scenario

    output = _require_suffix(args.output, (".npz",), "-o")
    problem, settings = load_scenario(args.scenario)
    for option in ("iterations", "chains", "seed"):
        if getattr(args, option) is not None:
            settings[option] = getattr(args, option)
    solution = flockkit.solve(problem, n_jobs=args.jobs, progress=_progress(args), **settings)
    solution.motion.save(output)
    rates = ", ".join(f"{name} {rate:.0%}" for name, rate in sorted(solution.acceptance.items())) or "none"
    print(f"wrote {output}: {solution.motion!r}")
    print(
        f"log g {solution.log_g[0]:.6g}; largest constraint residual {max(solution.residuals, default=0.0):.3g}; "
        f"accepted: {rates}"
    )
    return 0


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
    from .viz import ANIMATION_SUFFIXES, PICTURE_SUFFIXES

    output = _require_suffix(args.output, PICTURE_SUFFIXES + ANIMATION_SUFFIXES, "-o")
    motion = flockkit.Motion.load(args.motion)
    problem = None
    if args.scenario:
        from .solve import load_scenario

        problem = load_scenario(args.scenario)[0]
    from . import viz

    if output.suffix.lower() in ANIMATION_SUFFIXES:
        viz.animate(motion, output, problem=problem, progress=_progress(args))
    else:
        viz.plot_motion(motion, output, problem=problem)
    print(f"wrote {output}")
    return 0


def _cmd_export(args) -> int:
    from .io import EXPORT_SUFFIXES, export

    output = _require_suffix(args.output, EXPORT_SUFFIXES, "-o")
    motion = flockkit.Motion.load(args.motion)
    export(motion, output)
    print(f"wrote {output}: {motion.n_frames} frames x {motion.n_agents} agents")
    return 0


def _cmd_import(args) -> int:
    output = _require_suffix(args.output, (".npz",), "-o")
    reader = {"long": flockkit.io.read_long, "wide": flockkit.io.read_wide}[args.format]
    motion = reader(args.table, dt=args.dt, fps=args.fps, dims=args.dims, max_gap=args.max_gap)
    motion.save(output)
    print(f"wrote {output}: {motion!r}")
    return 0


def _output(parser, help: str) -> None:
    parser.add_argument("-o", "--output", required=True, help=help)


def _quiet(parser) -> None:
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _param(parser, what: str) -> None:
    parser.add_argument("--param", action="append", metavar="KEY=VALUE", help=f"{what} parameter, repeatable")


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
    _output(parser, "motion file to write (.npz)")
    parser.add_argument("--picture", help="also draw the trajectories (.png, .pdf or .svg; needs flockkit[viz])")
    _quiet(parser)


def _build_arguments(parser) -> None:
    parser.add_argument("motion", help="motion file (.npz, from simulate or import)")
    _output(parser, "graph file to write (.npz)")
    parser.add_argument("--metric", default="icp-hungarian", help="configuration metric (default icp-hungarian)")
    parser.add_argument("--builder", default="kovar", help="graph builder (default kovar)")
    parser.add_argument("--threshold", type=float, help="absolute transition threshold (default: adaptive)")
    parser.add_argument("--jobs", type=int, help="parallel workers (-1: all cores)")
    _param(parser, "builder")
    _quiet(parser)


def _walk_arguments(parser) -> None:
    parser.add_argument("graph", help="graph file (.npz, from build)")
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
    parser.add_argument("--chains", type=int, help="independent chains")
    parser.add_argument("--seed", type=int, help="random seed")
    parser.add_argument("--jobs", type=int, default=1, help="parallel workers for chains")
    _quiet(parser)


def _demo_arguments(parser) -> None:
    parser.add_argument("-o", "--output", default="flockkit-demo", help="folder to write into (./flockkit-demo)")
    parser.add_argument("--data", help="folder of the shared captures (default: ../shared/data when present)")
    _quiet(parser)


def _render_arguments(parser) -> None:
    parser.add_argument("motion", help="motion file (.npz)")
    _output(parser, "out.png | out.pdf | out.svg | out.gif | out.mp4 (needs flockkit[viz])")
    parser.add_argument("--scenario", help="also draw this scenario's constraints and obstacles (.toml)")
    _quiet(parser)


def _export_arguments(parser) -> None:
    parser.add_argument("motion", help="motion file (.npz)")
    _output(parser, "out.csv | out.json | out.usda | out.usdc")


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
    "walk": ("walk a motion graph and write the synthesized motion (.npz)", _walk_arguments, _cmd_walk),
    "info": ("describe a graph or motion file", _info_arguments, _cmd_info),
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
        "write a motion as CSV, JSON or USD (.usda/.usdc, needs flockkit[usd])",
        _export_arguments,
        _cmd_export,
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


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except (FlockkitError, OSError, AssertionError) as exc:
        message = " ".join(line.strip() for line in str(exc).splitlines() if line.strip())
        print(f"flockkit {args.command}: error: {message}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"flockkit {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
