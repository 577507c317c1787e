"""Commands on flocks' motions: ``simulate``, ``import``, ``info``, ``render``, ``export``."""

from __future__ import annotations

import json
import sys

import flockkit

from ..errors import ValidationError
from ._options import (
    Component,
    add_components,
    add_output,
    add_quiet,
    component_params,
    is_mesh_source,
    parse_region,
    pixel_size,
    read_source,
    require_capability,
    require_suffix,
    shows_progress,
)


def _cmd_simulate(args) -> int:
    output = require_suffix(args.output, (".npz",), "-o")
    picture = None
    if args.picture:
        from ..viz import PICTURE_SUFFIXES

        picture = require_suffix(args.picture, PICTURE_SUFFIXES, "--picture")
    require_capability(args, "behavior", "obstacles", what="obstacles",
                       needed_by={"--arena": args.arena is not None, "--obstacle": bool(args.obstacle)})  # fmt: skip
    params = component_params(args, "behavior")
    motion = flockkit.simulate(
        args.behavior,
        n_agents=args.agents,
        steps=args.steps,
        dims=args.dims,
        dt=args.dt,
        seed=args.seed,
        progress=not args.quiet and sys.stderr.isatty(),
        **params,
        **_obstacles(args),
    )
    motion.save(output)
    print(f"wrote {output}: {motion!r}")
    if picture is not None:
        from ..viz import plot_motion

        plot_motion(motion, picture)
        print(f"wrote {picture}")
    return 0


def _obstacles(args) -> dict:
    """The obstacles --arena and --obstacle ask for, as behavior parameters (none: no parameter)."""
    obstacles = [
        *(flockkit.fence(args.arena) if args.arena is not None else ()),
        *(parse_region(o, "--obstacle") for o in args.obstacle or ()),
    ]
    return {"obstacles": obstacles} if obstacles else {}


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
    from .._npzfile import kind_of
    from ..errors import FileFormatError

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


def _cmd_render(args) -> int:
    from ..viz import ANIMATION_SUFFIXES, PICTURE_SUFFIXES

    if args.blender:
        return _render_in_blender(args)
    output = require_suffix(args.output, PICTURE_SUFFIXES + ANIMATION_SUFFIXES, "-o")
    if is_mesh_source(args.motion):
        from .. import viz

        mesh = read_source(args.motion, args.clip)
        parts = flockkit.Segmentation.load(args.parts) if args.parts else None
        size = None if args.size is None else pixel_size(args.size)
        if output.suffix.lower() in ANIMATION_SUFFIXES:
            viz.animate_mesh(mesh, output, segmentation=parts, fps=args.fps, size=size, progress=shows_progress(args))
        else:
            viz.plot_mesh(mesh, output, segmentation=parts, size=size)
        print(f"wrote {output}")
        return 0
    motion = flockkit.Motion.load(args.motion)
    problem = None
    if args.scenario:
        from ..constrained import load_scenario

        problem = load_scenario(args.scenario)[0]
    from .. import viz

    regions = [parse_region(text) for text in args.region or ()]
    if output.suffix.lower() in ANIMATION_SUFFIXES:
        size = None if args.size is None else pixel_size(args.size)
        viz.animate(
            motion,
            output,
            problem=problem,
            regions=regions,
            fps=args.fps,
            size=size,
            trail=args.trail,
            progress=shows_progress(args),
            unit=args.unit,
        )
    else:
        viz.plot_motion(motion, output, problem=problem, regions=regions, unit=args.unit)
    print(f"wrote {output}")
    return 0


def _render_in_blender(args) -> int:
    from ..viz.render import SOURCE_SUFFIXES, render_blender

    output = require_suffix(args.output, (".png", ".gif"), "-o (with --blender)")
    source = args.motion
    if not source.lower().endswith(SOURCE_SUFFIXES):
        if is_mesh_source(source):
            kinds = ", ".join(SOURCE_SUFFIXES)
            raise ValidationError(f"render --blender {source}: expected a motion (.npz) or a file Blender imports "
                                  f"({kinds}), such as flockkit scene's scene.usda")  # fmt: skip
        source = flockkit.Motion.load(source)
    time = None
    if args.time is not None:
        try:
            time = tuple(float(t) for t in args.time.split(":")) if ":" in args.time else float(args.time)
        except ValueError:
            raise ValidationError(f"--time {args.time!r}: expected seconds T, or START:END for an animation") from None
    size = (640, 360) if args.size is None else pixel_size(args.size)
    render_blender(source, output, time=time, fps=args.fps, size=size, engine=args.engine, samples=args.samples)
    print(f"wrote {output}")
    return 0


def _cmd_export(args) -> int:
    from ..io import EXPORT_SUFFIXES, export

    output = require_suffix(args.output, EXPORT_SUFFIXES, "-o")
    motion = flockkit.Motion.load(args.motion)
    options = {k: v for k, v in (("fps", args.fps), ("meters_per_unit", args.units)) if v is not None}
    export(motion, output, **options)
    print(f"wrote {output}: {motion.n_frames} frames x {motion.n_agents} agents")
    return 0


def _cmd_import(args) -> int:
    output = require_suffix(args.output, (".npz",), "-o")
    reader = {"long": flockkit.io.read_long, "wide": flockkit.io.read_wide}[args.format]
    motion = reader(
        args.table, dt=args.dt, fps=args.fps, dims=args.dims, max_gap=args.max_gap, image_height=args.image_height
    )
    motion.save(output)
    print(f"wrote {output}: {motion!r}")
    return 0


def _simulate_arguments(parser) -> None:
    parser.add_argument("--agents", type=int, required=True, help="number of agents (>= 1)")
    parser.add_argument("--steps", type=int, required=True, help="number of steps (>= 1)")
    parser.add_argument("--dims", type=int, default=2, choices=(2, 3), help="2 or 3 dimensions (default 2)")
    parser.add_argument("--dt", type=float, default=0.1, help="seconds per step (default 0.1)")
    parser.add_argument("--seed", type=int, default=None, help="random seed; the same seed gives the same motion")
    add_components(parser, "simulate", Component("behavior", "boids"))
    parser.add_argument("--arena", type=float, metavar="R", help="fence the flock in a ring of posts R from the origin")
    parser.add_argument(
        "--obstacle", action="append", metavar="SPEC", help="an obstacle (as --region of walk), repeatable"
    )
    add_output(parser, "motion file to write (.npz)")
    parser.add_argument("--picture", help="also draw the trajectories (.png, .pdf or .svg; needs flockkit[viz])")
    add_quiet(parser)


def _info_arguments(parser) -> None:
    parser.add_argument("file", help="a .npz written by flockkit")


def _render_arguments(parser) -> None:
    parser.add_argument(
        "motion", help="motion or animated-mesh file (.npz; or .glb, .gltf, .usd*, an OBJ folder or glob, as segment)"
    )
    parser.add_argument("--parts", help="colour an animated mesh's parts from this segmentation (.npz)")
    parser.add_argument("--clip", help="the clip of an animated-mesh file (default: its first), read at 30 fps")
    parser.add_argument(
        "--fps", type=float, help="animation frames per second (default: real time, at most 25; with --blender 12)"
    )
    parser.add_argument(
        "--size",
        help="animation size WIDTHxHEIGHT in pixels (default: 600 on the scene's longer side, in proportion; "
        "with --blender the image's, 640x360)",
    )
    parser.add_argument("--trail", type=float, default=1.0, help="seconds of path behind each agent (default 1)")
    parser.add_argument("--unit", default="m", help="the unit the axes name (default m; px for a capture in pixels)")
    add_output(parser, "out.png | out.pdf | out.svg | out.gif | out.mp4 (needs flockkit[viz])")
    parser.add_argument("--scenario", help="also draw this scenario's constraints and obstacles (.toml)")
    parser.add_argument(
        "--region",
        action="append",
        help="also draw this region (repeatable): box:x0,y0,x1,y1 | ball:cx,cy,r | polygon:x0,y0,x1,y1,...",
    )
    parser.add_argument(
        "--blender",
        action="store_true",
        help="render in Blender (a Python with bpy: $FLOCKKIT_BPY_PYTHON, or this one): a motion (.npz, exported to "
        "USD) or an export (.usd*, .glb, .gltf: a flock, scene.usda, a crowd) to -o .png or .gif",
    )
    parser.add_argument(
        "--time", help="with --blender: seconds of the still (default the middle), START:END of a .gif (default all)"
    )
    parser.add_argument(
        "--engine",
        choices=("cycles", "workbench", "eevee"),
        help="with --blender: cycles (default for a .png), workbench (default for a .gif), eevee",
    )
    parser.add_argument("--samples", type=int, default=8, help="with --blender, cycles: samples a pixel (8)")
    add_quiet(parser)


def _export_arguments(parser) -> None:
    parser.add_argument("motion", help="motion file (.npz)")
    add_output(parser, "out.csv | out.json | out.glb | out.gltf | out.usda | out.usdc")
    parser.add_argument("--fps", type=float, help="USD: frame rate of the file's time line (default 24)")
    parser.add_argument("--units", type=float, help="USD: meters per flockkit length unit (default 1)")


def _import_arguments(parser) -> None:
    parser.add_argument("table", help="long (frame, agent, x, y[, z]) or wide (frame, x1, y1, x2, y2, ...) table")
    add_output(parser, "motion file to write (.npz)")
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


# command -> (help, arguments, run)
COMMANDS = {
    "simulate": ("simulate a flock and write its motion (.npz)", _simulate_arguments, _cmd_simulate),
    "info": ("describe a flockkit file: motion, graph, layers, mesh or segmentation", _info_arguments, _cmd_info),
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
    "import": ("read a captured-motion table (CSV/TSV) into a motion (.npz)", _import_arguments, _cmd_import),
}
