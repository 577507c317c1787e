"""Commands of data-driven groups (paper 000): ``build`` a motion graph (or layers), ``walk`` it."""

from __future__ import annotations

from pathlib import Path

import flockkit

from ..errors import ValidationError
from ._options import (
    Component,
    add_components,
    add_mesh_options,
    add_output,
    add_quiet,
    add_scale_out,
    component_params,
    joblib_backend,
    params_given,
    parse_region,
    read_source,
    require_parameter,
    require_suffix,
    shows_progress,
)


def _cmd_build(args) -> int:
    output = require_suffix(args.output, (".npz",), "-o")
    if params_given(args, "segmenter") and not (args.layers and not args.parts):
        raise ValidationError("--segmenter, --segmenter-param: the source is split into parts by a segmenter only "
                              "with --layers and no --parts")  # fmt: skip
    params = component_params(args, "builder")
    params["metric_params"] = component_params(args, "metric")
    if args.threshold is not None:
        params["threshold"] = args.threshold
    source = read_source(args.motion, args.clip, args.fps, args.allow_outside, args.up, args.meters_per_unit)
    if args.layers or args.parts:
        segmentation = flockkit.Segmentation.load(args.parts) if args.parts else None
        segmenter = {} if args.segmenter is None else {"segmenter": args.segmenter}
        layers = flockkit.build_layers(source, segmentation=segmentation, builder=args.builder or "windowed",
                                       segmenter_params=component_params(args, "segmenter"), **segmenter,
                                       metric=args.metric, seed=args.seed, **params)  # fmt: skip
        layers.save(output)
        counts = ", ".join(str(g.stats()["transitions"]) for g in layers.graphs)
        print(f"wrote {output}: {layers.n_parts} parts, each a graph (transitions: {counts})")
        return 0
    motion = source.motion if isinstance(source, flockkit.AnimatedMesh) else source
    if args.jobs is not None and args.backend is None:
        params["n_jobs"] = args.jobs
    with joblib_backend(args):
        graph = flockkit.build_graph(
            motion, builder=args.builder or "kovar", metric=args.metric, seed=args.seed, progress=shows_progress(args),
            **params,
        )  # fmt: skip
    graph.save(output)
    stats = graph.stats()
    print(
        f"wrote {output}: {stats['nodes']} nodes, {stats['transitions']} transitions, {stats['fraction_kept']:.0%} of "
        "frames kept"
    )
    return 0


def _cmd_walk(args) -> int:
    from .._npzfile import kind_of

    output = require_suffix(args.output, (".npz",), "-o")
    layered = kind_of(args.graph) == "layers"
    graph = (flockkit.GraphLayers if layered else flockkit.MotionGraph).load(args.graph)
    params = component_params(args, "strategy")
    if args.region is not None:
        require_parameter(args, "strategy", "region", "--region")
        params["region"] = parse_region(args.region)
    path = flockkit.walk(graph, strategy=args.strategy, duration=args.duration, seed=args.seed, **params)
    motion = flockkit.synthesize(graph, path)
    if layered and graph.faces is not None:  # a mesh in, a mesh out: render draws its faces
        flockkit.AnimatedMesh(motion=motion, faces=graph.faces, name=Path(args.graph).stem).save(output)
    else:
        motion.save(output)
    print(f"wrote {output}: {motion!r}")
    return 0


def _build_arguments(parser) -> None:
    parser.add_argument(
        "motion", help="motion or animated-mesh file (.npz from simulate, import or walk; .glb, .gltf, .usd*, OBJ)"
    )
    add_output(parser, "graph file to write (.npz)")
    parser.add_argument("--layers", action="store_true", help="split into parts and build one graph per part")
    parser.add_argument("--parts", help="the segmentation to use for --layers (.npz, from segment)")
    parser.add_argument("--seed", type=int, default=None, help="random seed (of the segmentation for --layers)")
    add_mesh_options(parser)
    parser.add_argument("--threshold", type=float, help="absolute transition threshold (default: adaptive)")
    add_scale_out(parser)
    add_components(
        parser, "build", Component("builder", shown="kovar; windowed with --layers"),
        Component("metric", "icp-hungarian"),
        Component("segmenter", shown="skin-parts for a skinned mesh, else ica-kmeans; it splits the source for "
                  "--layers without --parts"),
    )  # fmt: skip
    add_quiet(parser)


def _walk_arguments(parser) -> None:
    parser.add_argument("graph", help="graph or layers file (.npz, from build)")
    parser.add_argument("--duration", type=float, required=True, help="seconds of motion to synthesize")
    parser.add_argument(
        "--region",
        help="box:x0,y0,x1,y1 | ball:cx,cy,r | polygon:x0,y0,x1,y1,...: the strategy's region= (--strategy region)",
    )
    parser.add_argument("--seed", type=int, default=None, help="random seed")
    add_components(parser, "walk", Component("strategy", "random"))
    add_output(parser, "motion file to write (.npz)")


# command -> (help, arguments, run)
COMMANDS = {
    "build": ("build a motion graph from a motion (.npz)", _build_arguments, _cmd_build),
    "walk": ("walk a motion graph (or layers) and write the synthesized motion (.npz)", _walk_arguments, _cmd_walk),
}
