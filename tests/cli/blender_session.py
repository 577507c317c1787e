"""Drive the flockkit add-on in a fresh bpy, as a user would from its panels; run by
test_blender_addon.py with FLOCKKIT_BPY_PYTHON:

    python blender_session.py ADDON.zip FLOCKKIT_PYTHON FOLDER

It installs the extension, then simulates, authors constraints, checks speeds, solves (once through
the worker's progress, once more after an edit), analyses and scatters an animated mesh, and drives
an armature crowd; it prints one line RESULT{json} of what Blender holds afterwards."""

import json
import math
import sys
import time

import bpy

addon, python, folder = sys.argv[1:4]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.extensions.package_install_files(filepath=addon, repo="user_default", enable_on_install=True)
package = next(a.module for a in bpy.context.preferences.addons if a.module.endswith(".flockkit"))
bpy.context.preferences.addons[package].preferences.python = python
bridge, job = (__import__(f"{package}.{m}", fromlist=["_"]) for m in ("_bridge", "_job"))
scene, settings = bpy.context.scene, bpy.context.scene.flockkit
scene.render.fps, scene.frame_start, scene.frame_end = 24, 1, 49
settings.folder = folder
found = {"addon": package}


def keyed(obj):
    data = obj.animation_data
    return {f"{c.data_path}[{c.array_index}]": [list(p.co) for p in c.keyframe_points]
            for c in bridge.fcurves(data.action, getattr(data, "action_slot", None))}  # fmt: skip


def places(names, frames):
    out = {}
    for frame in frames:
        scene.frame_set(frame)
        out[frame] = {n: list(bpy.data.objects[n].matrix_world.translation) for n in names}
    return out


# the flock: behavior parameters, then a simulation onto a chosen mesh
bpy.ops.flockkit.behavior()
found["parameters"] = {p.name: p.value for p in settings.parameters}
bpy.ops.mesh.primitive_cube_add(size=0.3)
settings.agent_object, settings.agents = bpy.context.active_object, 6
bpy.ops.flockkit.simulate()
flock = bpy.data.collections["flockkit Flock"]
agents = sorted(flock.objects, key=lambda o: o["flockkit_agent"])
found["simulate"] = {
    "agents": [o.name for o in agents], "meshes": sorted({o.data.name for o in agents}),
    "keys": keyed(agents[2]), "range": [scene.frame_start, scene.frame_end], "motion": settings.motion_file,
    "places": places([o.name for o in agents], [1, 20, 49]),
}  # fmt: skip

# constraints: agent 0 through three keys, agent 3 once (its velocity its X axis), the centre of mass
scene.cursor.location = (0.0, 0.0, 0.0)
bpy.ops.flockkit.add(role="POINT")
point = bpy.context.active_object if bpy.context.active_object.flockkit.role == "POINT" else None
point = point or next(o for o in scene.objects if o.flockkit.role == "POINT")
for frame, where in ((1, (0.0, 0.0, 0.0)), (25, (1.0, 0.3, 0.0)), (49, (40.0, 1.0, 0.0))):
    point.location = where
    point.keyframe_insert("location", frame=frame)
lone = bpy.data.objects.new("Lone", None)
scene.collection.objects.link(lone)
lone.flockkit.role, lone.flockkit.agent, lone.flockkit.speed = "POINT", 3, 1.0
lone.location, lone.rotation_euler = (1.0, -1.0, 0.0), (0.0, 0.0, math.pi / 2)
lone.keyframe_insert("location", frame=37)
centre = bpy.data.objects.new("Centre", None)
scene.collection.objects.link(centre)
centre.flockkit.role, centre.location = "COM", (1.0, 0.0, 0.0)
centre.keyframe_insert("location", frame=13)
centre.location = (2.0, 0.5, 0.0)
centre.keyframe_insert("location", frame=37)

bpy.ops.flockkit.hints()
found["hints far"] = [[h.name, h.alert] for h in settings.hints]
point.location = (2.0, 0.5, 0.0)  # the edit: the last key within the model's reach
point.keyframe_insert("location", frame=49)
bpy.ops.flockkit.hints()
found["hints near"] = [[h.name, h.alert] for h in settings.hints]

# the solve a button starts: the worker polled as the modal timer polls it, its progress read
running = job.Job(python, "solve", {"problem": bridge.problem(bpy.context), "iterations": 60, "refine": 20,
                                    "seed": 1, "motion": f"{folder}/polled.npz"}, folder=folder)  # fmt: skip
seen = []
while not running.poll():
    seen.append(running.progress)
    time.sleep(0.02)
arrays, fields = running.result()
found["polled"] = {"progress": seen + [running.progress], "residual": fields["residual"]}

settings.iterations, settings.refine = 60, 20
bpy.ops.flockkit.solve()
constrained = {"Point": (0, [1, 25, 49]), "Lone": (3, [37])}


def solved():
    out = {}
    for name, (agent, frames) in constrained.items():
        for frame in frames:
            scene.frame_set(frame)
            out[f"{name} {frame}"] = [list(bpy.data.objects[name].matrix_world.translation),
                                      list(agents[agent].matrix_world.translation)]  # fmt: skip
    centres = {}
    for frame in (13, 37):
        scene.frame_set(frame)
        centres[frame] = [
            list(centre.matrix_world.translation),
            [sum(o.matrix_world.translation[k] for o in agents) / len(agents) for k in range(3)],
        ]
    return {"points": out, "centres": centres, "range": [scene.frame_start, scene.frame_end],
            "agents": len(flock.objects), "status": settings.status}  # fmt: skip


found["solve"] = solved()
scene.frame_set(25)
point.location = (1.0, 0.6, 0.0)  # edit a key and solve again
point.keyframe_insert("location", frame=25)
bpy.ops.flockkit.solve()
found["resolve"] = solved()

# a scene: a waving grid, analysed into layers, scattered over a ground with a flow arrow
bpy.ops.mesh.primitive_grid_add(x_subdivisions=5, y_subdivisions=5, size=2.0, location=(0, 0, 0))
wave = bpy.context.active_object
wave.name = "Wave"
wave.shape_key_add(name="Basis")
for k, phase in enumerate((0.0, math.pi / 2, math.pi, 3 * math.pi / 2)):
    key = wave.shape_key_add(name=f"wave {k}", from_mix=False)
    for v, point_ in zip(wave.data.vertices, key.data):
        point_.co.z = 0.2 * math.sin(phase + 2 * v.co.x)
    for frame in range(1, 50, 6):
        key.value = 1.0 if (frame // 6) % 4 == k else 0.0
        key.keyframe_insert("value", frame=frame)
settings.template, settings.arrow = wave, (0.6, 0.0, 0.0)
bpy.ops.flockkit.analyse()
found["analyse"] = {"parts": settings.parts, "groups": [g.name for g in wave.vertex_groups]}
bpy.ops.mesh.primitive_plane_add(size=20.0, location=(30.0, 0.0, 0.0))
settings.ground, settings.count = bpy.context.active_object, 3
bpy.ops.flockkit.add(role="FLOW")
arrow = next(o for o in scene.objects if o.flockkit.role == "FLOW")
arrow.location, arrow.flockkit.speed = (30.0, 0.0, 0.0), 0.6
bpy.ops.flockkit.scatter()
copies = list(bpy.data.collections["flockkit Scene"].all_objects)
meshes = [o for o in copies if o.type == "MESH"]
shapes = {}
for frame in (1, 20, 40):
    scene.frame_set(frame)
    graph = bpy.context.evaluated_depsgraph_get()
    shapes[frame] = [[list(o.evaluated_get(graph).matrix_world @ v.co) for v in o.evaluated_get(graph).data.vertices]
                     for o in meshes]  # fmt: skip
found["scatter"] = {"objects": [o.name for o in copies], "meshes": [o.name for o in meshes], "shapes": shapes,
                    "vertices": len(wave.data.vertices),
                    "range": [scene.frame_start, scene.frame_end], "status": settings.status}  # fmt: skip

# a crowd: an armature whose action swings a bone, driven along the flock
bpy.ops.object.select_all(action="DESELECT")
bpy.ops.object.armature_add(location=(0, 0, 0))
rig = bpy.context.active_object
rig.flockkit.ground_speed = 1.0
bpy.ops.object.mode_set(mode="POSE")
bone = rig.pose.bones[0]
bone.rotation_mode = "XYZ"
for frame, angle in ((1, 0.0), (13, 0.5), (25, 0.0)):
    bone.rotation_euler = (angle, 0.0, 0.0)
    bone.keyframe_insert("rotation_euler", frame=frame)
bpy.ops.object.mode_set(mode="OBJECT")
rig.select_set(True)
bpy.ops.flockkit.crowd()
crowd = sorted(bpy.data.collections["flockkit Crowd"].objects, key=lambda o: o["flockkit_agent"])
found["crowd"] = {
    "objects": [o.name for o in crowd], "armatures": sorted({o.data.name for o in crowd}),
    "keys": keyed(crowd[1]), "places": places([o.name for o in crowd], [1, 30]),
    "range": [scene.frame_start, scene.frame_end], "status": settings.status, "motion": settings.motion_file,
}  # fmt: skip
print("RESULT" + json.dumps(found))
