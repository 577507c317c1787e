"""Commands of data-driven groups (paper 000): ``build`` a motion graph (or layers), ``walk`` it."""

from __future__ import annotations

from pathlib import Path

import flockkit

from ..errors import ValidationError
from ._options import (
    add_component_params,
    add_mesh_options,
    add_output,
    add_quiet,
    add_scale_out,
    component_params,
    joblib_backend,
    parse_region,
    read_source,
    require_suffix,
    shows_progress,
)


def _cmd_build(args) -> int:
    output = require_suffix(args.output, (".npz",), "-o")
    source = read_source(args.motion, args.clip, args.fps, args.allow_outside)
    params = component_params(args, "builder", "build")
    metric_params = component_params(args, "metric", "build")
    if args.threshold is not None:
        params["threshold"] = args.threshold
    if (args.layers or args.parts) and metric_params:
        raise ValidationError("--metric-param: --layers builds each part with its builder's own comparison")
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
    with joblib_backend(args):
        graph = flockkit.build_graph(
            motion, builder=args.builder or "kovar", metric=args.metric, metric_params=metric_params, seed=args.seed,
            progress=shows_progress(args), **params,
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
    params = component_params(args, "strategy", "walk")
    if args.region is not None:
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
    parser.add_argument("--metric", default="icp-hungarian", help="configuration metric (default icp-hungarian)")
    parser.add_argument("--builder", help="graph builder (default kovar; windowed for --layers)")
    parser.add_argument("--layers", action="store_true", help="split into parts and build one graph per part")
    parser.add_argument("--parts", help="the segmentation to use for --layers (.npz, from segment)")
    parser.add_argument("--seed", type=int, default=None, help="random seed (of the segmentation for --layers)")
    add_mesh_options(parser)
    parser.add_argument("--threshold", type=float, help="absolute transition threshold (default: adaptive)")
    add_scale_out(parser)
    add_component_params(parser, "builder", "metric")
    add_quiet(parser)


def _walk_arguments(parser) -> None:
    parser.add_argument("graph", help="graph or layers file (.npz, from build)")
    parser.add_argument("--duration", type=float, required=True, help="seconds of motion to synthesize")
    parser.add_argument("--strategy", default="random",
                        help="walk strategy (default random; region needs --region; any installed)")  # fmt: skip
    parser.add_argument(
        "--region", help="box:x0,y0,x1,y1 | ball:cx,cy,r | polygon:x0,y0,x1,y1,... (for --strategy region)"
    )
    parser.add_argument("--seed", type=int, default=None, help="random seed")
    add_component_params(parser, "strategy")
    add_output(parser, "motion file to write (.npz)")


# command -> (help, arguments, run)
COMMANDS = {
    "build": ("build a motion graph from a motion (.npz)", _build_arguments, _cmd_build),
    "walk": ("walk a motion graph (or layers) and write the synthesized motion (.npz)", _walk_arguments, _cmd_walk),
}
