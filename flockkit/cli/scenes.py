"""Commands of background scenes (paper 002): ``segment`` an animated mesh, fill a ``scene``."""

from __future__ import annotations

import flockkit

from ..scene.file import FEATURE_SOURCES
from ._options import (
    Component,
    add_allow_outside,
    add_components,
    add_mesh_options,
    add_output,
    add_quiet,
    add_scale_out,
    check_folder,
    component_params,
    joblib_backend,
    read_source,
    require_suffix,
    staged_folder,
)

# How --help states the segmenter chosen where none is named (flockkit.segment chooses it).
SEGMENTER_SHOWN = "skin-parts for a mesh read with a skin (a skinned glTF character), else ica-kmeans"

# Frames of the scene animation the CLI draws at most (frames are skipped evenly beyond): a
# minute-long scene stays a GIF of about a megabyte, drawn in seconds.
SCENE_GIF_FRAMES = 150


def _cmd_scene(args) -> int:
    from ..scene import read_scene

    folder = check_folder(args.output)
    scene = read_scene(args.scene, features=args.features, n_jobs=args.jobs, allow_outside=args.allow_outside)
    if not args.no_usd:  # fail before the walks, not after them, when usd-core is missing
        from ..io.usd import require_usd_core

        require_usd_core()
    with joblib_backend(args):
        animation = scene.synthesize(progress=not args.quiet)
    names = ["scene.npz"] + ([] if args.no_usd else ["scene.usda"]) + ([] if args.no_pictures else
                                                                        ["scene.png", "scene.gif"])  # fmt: skip
    with staged_folder(folder) as staging:  # every file, or none
        animation.save(staging / "scene.npz")
        if not args.no_usd:
            animation.export(staging / "scene.usda")
        if not args.no_pictures:
            from ..viz import animate_scene, plot_scene

            plot_scene(animation, staging / "scene.png")
            animate_scene(animation, staging / "scene.gif", max_frames=SCENE_GIF_FRAMES, progress=not args.quiet)
    report = animation.report
    print(
        f"wrote {', '.join(str(folder / name) for name in names)}: {animation.placement.n_objects} objects, "
        f"{animation.n_frames} frames; neighbours in step (within {report['in_step_frames']} frame) at most "
        f"{report['in_step_before']:.1%} of frames after the first walks ({report['first_rounds']} rounds), "
        f"{report['in_step_after']:.1%} after {report['walked_again']} objects were walked again; pairs in step "
        f"over 5% of frames {report['pairs_in_step_before']:.1%} after the first walks, "
        f"{report['pairs_in_step_after']:.1%} at the end"
    )
    return 0


def _cmd_segment(args) -> int:
    output = require_suffix(args.output, (".npz",), "-o")
    params = component_params(args, "segmenter")
    source = read_source(args.source, args.clip, args.fps, args.allow_outside, args.up, args.meters_per_unit)
    if args.parts is not None:
        params["n_parts"] = args.parts
    found = flockkit.segment(source, segmenter=args.segmenter, seed=args.seed, **params)
    found.save(output)
    sizes = ", ".join(str(len(p)) for p in found.parts())
    print(f"wrote {output}: {found.n_parts} parts of {sizes} points")
    return 0


def _segment_arguments(parser) -> None:
    parser.add_argument("source", help="animated mesh (.glb, .gltf, .usd*, OBJ folder or glob) or motion (.npz)")
    add_output(parser, "segmentation file to write (.npz)")
    parser.add_argument("--parts", type=int, help="number of parts (default: chosen by the segmenter)")
    parser.add_argument("--seed", type=int, default=None, help="random seed")
    add_mesh_options(parser)
    add_components(parser, "segment", Component("segmenter", shown=SEGMENTER_SHOWN))


def _scene_arguments(parser) -> None:
    parser.add_argument("scene", help="scene file (.toml; see docs/concepts.md, scenes)")
    parser.add_argument(
        "-o", "--output", required=True, help="folder to write scene.npz, scene.usda, scene.png, scene.gif"
    )
    parser.add_argument(
        "--features", choices=FEATURE_SOURCES,
        help="feature arrows for layers that carry none (build --layers makes none): keyframes, from each "
             "[[templates]] entry's features = [[time, [x, y]], ...] (which every such entry must then have); "
             "motion, the source's own heading and speed (animals, characters, flocks that travel); an entry's "
             "keyframes are used whichever is chosen. Default: none, and such layers are refused",
    )  # fmt: skip
    parser.add_argument("--no-usd", action="store_true", help="skip the USD export (needs flockkit[usd])")
    parser.add_argument(
        "--no-pictures", action="store_true", help="skip the top view and animation (need flockkit[viz])"
    )
    add_allow_outside(parser)
    add_scale_out(parser)
    add_quiet(parser)


# command -> (help, arguments, run)
COMMANDS = {
    "segment": (
        "split an animated mesh's vertices into parts that move independently",
        _segment_arguments,
        _cmd_segment,
    ),
    "scene": (
        "fill a region with duplicates of animated objects following arrows (.toml); write npz, USD, picture",
        _scene_arguments,
        _cmd_scene,
    ),
}
