"""Commands of background scenes (paper 002): ``segment`` an animated mesh, fill a ``scene``."""

from __future__ import annotations

from pathlib import Path

import flockkit

from ..errors import ValidationError
from ._options import (
    Component,
    add_allow_outside,
    add_components,
    add_mesh_options,
    add_output,
    add_quiet,
    add_scale_out,
    component_params,
    joblib_backend,
    read_source,
    require_suffix,
)

# Frames of the scene animation the CLI draws at most (frames are skipped evenly beyond): a
# minute-long scene stays a GIF of about a megabyte, drawn in seconds.
SCENE_GIF_FRAMES = 150


def _cmd_scene(args) -> int:
    from ..scene import read_scene

    folder = Path(args.output)
    if folder.exists() and not folder.is_dir():
        raise ValidationError(f"-o must be a folder; {folder} is a file")
    scene = read_scene(args.scene, n_jobs=args.jobs, allow_outside=args.allow_outside)
    with joblib_backend(args):
        animation = scene.synthesize(progress=not args.quiet)
    folder.mkdir(parents=True, exist_ok=True)
    animation.save(folder / "scene.npz")
    written = [folder / "scene.npz"]
    if not args.no_usd:
        animation.export(folder / "scene.usda")
        written.append(folder / "scene.usda")
    if not args.no_pictures:
        from ..viz import animate_scene, plot_scene

        plot_scene(animation, folder / "scene.png")
        animate_scene(animation, folder / "scene.gif", max_frames=SCENE_GIF_FRAMES, progress=not args.quiet)
        written += [folder / "scene.png", folder / "scene.gif"]
    report = animation.report
    print(
        f"wrote {', '.join(str(p) for p in written)}: {animation.placement.n_objects} objects, "
        f"{animation.n_frames} frames; neighbours in step (within {report['in_step_frames']} frame) at most "
        f"{report['in_step_before']:.1%} of frames before de-synchronisation, {report['in_step_after']:.1%} after; "
        f"pairs in step over 5% of frames {report['pairs_in_step_before']:.1%} before, "
        f"{report['pairs_in_step_after']:.1%} after"
    )
    return 0


def _cmd_segment(args) -> int:
    output = require_suffix(args.output, (".npz",), "-o")
    params = component_params(args, "segmenter")
    source = read_source(args.source, args.clip, args.fps, args.allow_outside)
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
    add_components(parser, "segment", Component("segmenter", "ica-kmeans"))


def _scene_arguments(parser) -> None:
    parser.add_argument("scene", help="scene file (.toml; see docs/concepts.md, scenes)")
    parser.add_argument(
        "-o", "--output", required=True, help="folder to write scene.npz, scene.usda, scene.png, scene.gif"
    )
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
