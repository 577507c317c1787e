"""The script ``flockkit.viz.render_blender`` runs in a Python that has Blender's ``bpy`` module:

    python _in_blender.py JOB.json

It imports a USD or glTF file as a user would (``bpy.ops.wm.usd_import``, or the glTF importer),
nothing rescaled or retimed, sets the scene's frame range to the file's animation (Blender's glTF
importer leaves it at 1-250 whatever the keys span; its USD importer sets it), paints what it
imported, adds a ground under it, a sun and a sky, points a camera down at the action from the
south-west and fits it to the box the action fills over the frames asked, and renders each of
them to a PNG. It needs only bpy: flockkit is never imported here, so flockkit's own Python
keeps its numpy and Blender keeps its own.

JOB.json holds ``file``, ``times`` (seconds), ``duration`` (seconds: the file's animation, which
Blender lays over the scene's frame range: the importers read USD time codes as frames, whatever
the stage's rate, and glTF seconds at the scene's 24 fps), ``outputs`` (a PNG path per time),
``width``, ``height``, ``engine`` (a ``scene.render.engine`` name), ``samples`` (Cycles) and
``colour`` (RGB of what was imported).
"""

import json
import math
import sys

# The camera looks down this far below the horizon, from this bearing (degrees; 0 looks north).
PITCH, BEARING = 35.0, 30.0
# The ground's colour (linear RGBA): a dry meadow, darker than what stands on it.
GROUND = (0.16, 0.2, 0.1, 1.0)
# Frames sampled to find the box the action fills, at most (evenly among those rendered).
BOX_SAMPLES = 6


def main(argv):
    import time

    import bpy

    begin = time.perf_counter()

    with open(argv[0]) as file:
        job = json.load(file)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    if job["file"].lower().endswith((".glb", ".gltf")):
        bpy.ops.import_scene.gltf(filepath=job["file"])
        frame_range_from_actions(scene)
    else:
        bpy.ops.wm.usd_import(filepath=job["file"], relative_path=False)
    took = time.perf_counter() - begin
    print(f"imported {job['file']} in {took:.1f} s: frames {scene.frame_start} to {scene.frame_end}")
    paint(job["colour"])
    span = (scene.frame_end - scene.frame_start) / job["duration"] if job["duration"] > 0 else 0.0
    frames = [scene.frame_start + t * span for t in job["times"]]
    picks = {frames[round(k * (len(frames) - 1) / max(BOX_SAMPLES - 1, 1))] for k in range(BOX_SAMPLES)}
    low, high = action_box(scene, sorted(picks))
    stage(scene, low, high, job)
    begin = time.perf_counter()
    for frame, output in zip(frames, job["outputs"]):
        go(scene, frame)
        scene.render.filepath = output
        bpy.ops.render.render(write_still=True)
    print(f"rendered {len(frames)} frames ({frames[0]:g} to {frames[-1]:g}) of the box {fmt(low)} to {fmt(high)} in "
          f"{time.perf_counter() - begin:.1f} s")  # fmt: skip


def go(scene, frame: float):
    """Show `frame`, which may fall between two."""
    whole = int(frame // 1)
    scene.frame_set(whole, subframe=frame - whole)


def frame_range_from_actions(scene):
    """The scene's frame range: the span of every imported action's keys."""
    import bpy

    spans = [action.frame_range for action in bpy.data.actions]
    if spans:
        scene.frame_start = math.floor(min(s[0] for s in spans))
        scene.frame_end = math.ceil(max(s[1] for s in spans))


def paint(colour):
    """One material, of `colour`, on every imported mesh."""
    import bpy

    material = bpy.data.materials.new("flockkit")
    material.diffuse_color = workbench(colour, 0.7)
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.6
    for mesh in bpy.data.meshes:
        mesh.materials.clear()
        mesh.materials.append(material)


def action_box(scene, frames):
    """(low, high) world corners of the box every drawn mesh (instances and deformed meshes
    included) fills over `frames`."""
    import bpy
    from mathutils import Vector

    low, high = Vector((math.inf,) * 3), Vector((-math.inf,) * 3)
    for frame in frames:
        go(scene, frame)
        graph = bpy.context.evaluated_depsgraph_get()
        for instance in graph.object_instances:
            shown = instance.object
            if shown.type != "MESH" or not (instance.is_instance or shown.original.visible_get()):
                continue
            for corner in shown.bound_box:
                point = instance.matrix_world @ Vector(corner)
                low = Vector(map(min, low, point))
                high = Vector(map(max, high, point))
    if not math.isfinite(low.x):
        raise SystemExit("nothing to render: the file holds no mesh")
    return low, high


def stage(scene, low, high, job):
    """A ground under the box, a sun, a sky and a camera that frames the box; render settings."""
    import bpy
    from mathutils import Euler, Vector

    centre, extent = (low + high) / 2, max((high - low).length, 1e-3)
    ground = bpy.data.meshes.new("ground")
    ground.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    floor = bpy.data.objects.new("ground", ground)
    floor.location = (centre.x, centre.y, low.z)
    floor.scale = (4 * extent,) * 3
    soil = bpy.data.materials.new("ground")
    soil.diffuse_color = workbench(GROUND[:3], 1 / 2.2)
    soil.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = GROUND
    ground.materials.append(soil)
    scene.collection.objects.link(floor)

    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.5, math.radians(8)
    sun.rotation_euler = Euler((math.radians(40), 0.0, math.radians(BEARING + 60)))
    scene.collection.objects.link(sun)
    sky = bpy.data.worlds.new("sky")
    background = sky.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.72, 0.8, 0.9, 1.0)
    background.inputs["Strength"].default_value = 0.8
    scene.world = sky

    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    camera.data.lens = 40
    camera.rotation_euler = Euler((math.radians(90 - PITCH), 0.0, math.radians(-BEARING)))
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = job["width"], job["height"]
    scene.render.resolution_percentage = 100
    corners = [Vector((x, y, z)) for x in (low.x, high.x) for y in (low.y, high.y) for z in (low.z, high.z)]
    graph = bpy.context.evaluated_depsgraph_get()
    place, _ = camera.camera_fit_coords(graph, [v for corner in corners for v in corner])
    back = camera.matrix_world.to_quaternion() @ Vector((0.0, 0.0, 1.0))
    camera.location = Vector(place) + back * 0.08 * extent  # a margin around the action
    camera.data.clip_start, camera.data.clip_end = 0.01 * extent, 20 * extent

    scene.render.engine = job["engine"]
    if job["engine"] == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = job["samples"]
        scene.cycles.use_denoising = True  # at a few samples, the denoiser's fast mode is what removes the grain
        scene.cycles.denoising_prefilter = scene.cycles.denoising_quality = "FAST"
    elif job["engine"] == "BLENDER_WORKBENCH":
        shading = scene.display.shading
        shading.light, shading.color_type = "STUDIO", "MATERIAL"
        shading.show_shadows, shading.shadow_intensity = True, 0.4
        shading.show_cavity = False
        scene.display.render_aa = "FXAA"  # its 8 default samples take 5 times as long on a CPU
    scene.view_settings.view_transform = "Standard"  # AgX greys a sunny ground and a fox's orange
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.compression = 90
    scene.render.film_transparent = False


def workbench(colour, lift: float):
    """The colour to give Workbench for linear RGB `colour`: its studio light, without the sky's
    light that Cycles adds, shows colours darker, the ground's most (it faces up, away from the
    studio's key light); raised to `lift`, they look about as Cycles shows them."""
    return (*(c**lift for c in colour), 1.0)


def fmt(vector):
    return "(" + ", ".join(f"{v:.2f}" for v in vector) + ")"


if __name__ == "__main__":
    main(sys.argv[1:])
