"""Import a flockkit export into Blender and make the scene play all of it.

Run it inside Blender (Scripting workspace, or ``blender --python import_flockkit.py -- FILE``),
or in a Python with Blender's bpy module (``pip install bpy``) to save a .blend:

    python import_flockkit.py flock.glb [--save flock.blend]

USD (.usda, .usdc: flocks, scenes, crowds) goes through ``bpy.ops.wm.usd_import``, whose
``set_frame_range`` already makes the scene's range the stage's time codes. glTF (.glb, .gltf)
goes through Blender's glTF importer, which keys the animation at seconds x the scene's frame rate
(frames 0 to 480 for 20 s at 24 fps) but leaves the scene's range as it was (1 to 250 in a new
file): this script sets it to the span of the imported actions' keys, as ``flockkit render
--blender`` does before it renders.
"""

import argparse
import math
import sys

import bpy


def import_flockkit(path: str) -> tuple[int, int]:
    """Import `path` into the current scene; return the scene's frame range afterwards."""
    scene = bpy.context.scene
    if path.lower().endswith((".glb", ".gltf")):
        before = set(bpy.data.actions)
        bpy.ops.import_scene.gltf(filepath=path)
        spans = [action.frame_range for action in bpy.data.actions if action not in before]
        if spans:
            scene.frame_start = math.floor(min(s[0] for s in spans))
            scene.frame_end = math.ceil(max(s[1] for s in spans))
    else:
        bpy.ops.wm.usd_import(filepath=path, relative_path=False, set_frame_range=True)
    return scene.frame_start, scene.frame_end


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", help="a flockkit export: .usda, .usdc, .glb or .gltf")
    parser.add_argument("--save", help="save the result as this .blend")
    args = parser.parse_args(argv)
    start, end = import_flockkit(args.file)
    print(f"imported {args.file}: scene frames {start} to {end} at {bpy.context.scene.render.fps} fps")
    if args.save:
        bpy.ops.wm.save_as_mainfile(filepath=args.save)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:])
