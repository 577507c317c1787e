"""Render a flockkit export in Blender, headless, as the docs' picture of an imported flock.

Run it with a Python that has Blender's bpy module (``pip install bpy`` in its own environment):

    python render_flock.py flock.usdc picture.png [--frame F] [--samples N]

It imports the file as a user would (``bpy.ops.wm.usd_import``, or the glTF importer for .glb and
.gltf), with nothing rescaled or retimed, adds a ground, a sun and a camera framing the flock at
frame F (Blender frames, 24 per second), and renders with Cycles on the CPU.
"""

import argparse
import math
import sys

import bpy
from mathutils import Vector


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file")
    parser.add_argument("picture")
    parser.add_argument("--frame", type=int, default=48)
    parser.add_argument("--samples", type=int, default=32)
    args = parser.parse_args(argv)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if args.file.lower().endswith((".glb", ".gltf")):
        bpy.ops.import_scene.gltf(filepath=args.file)
    else:
        bpy.ops.wm.usd_import(filepath=args.file, relative_path=False)
    scene = bpy.context.scene
    scene.frame_set(args.frame)
    graph = bpy.context.evaluated_depsgraph_get()
    places = [i.matrix_world.translation.copy() for i in graph.object_instances if i.is_instance]
    places += [o.matrix_world.translation.copy() for o in bpy.data.objects if o.name.startswith("Agent ")]
    low = Vector([min(p[k] for p in places) for k in range(3)])
    high = Vector([max(p[k] for p in places) for k in range(3)])
    centre, size = (low + high) / 2, max((high - low).length, 4.0)
    print(f"agents between {tuple(round(v, 2) for v in low)} and {tuple(round(v, 2) for v in high)}")

    paint = bpy.data.materials.new("agents")
    paint.diffuse_color = (0.85, 0.35, 0.1, 1.0)
    paint.use_nodes = True
    paint.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.85, 0.35, 0.1, 1.0)
    for mesh in list(bpy.data.meshes):
        mesh.materials.clear()
        mesh.materials.append(paint)
    bpy.ops.mesh.primitive_plane_add(size=size * 6, location=(centre.x, centre.y, min(low.z, 0.0) - 0.3))
    ground = bpy.data.materials.new("ground")
    ground.use_nodes = True
    ground.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.18, 0.2, 0.22, 1.0)
    bpy.context.object.data.materials.append(ground)
    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(35), 0, math.radians(30)))
    bpy.context.object.data.energy = 3.0
    bpy.ops.object.camera_add(location=centre + Vector((0.0, -1.3 * size, 1.4 * size)))
    camera = bpy.context.object
    camera.rotation_euler = (centre - camera.location).to_track_quat("-Z", "Y").to_euler()
    scene.camera = camera
    world = bpy.data.worlds.new("sky")
    world.color = (0.8, 0.85, 0.9)
    scene.world = world
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = args.samples
    scene.render.resolution_x, scene.render.resolution_y = 960, 540
    scene.render.filepath = args.picture
    bpy.ops.render.render(write_still=True)
    print(
        f"rendered {len(places)} agents at frame {args.frame} ({args.frame / scene.render.fps:g} s) to {args.picture}"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
