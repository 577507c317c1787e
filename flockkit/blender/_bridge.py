"""Blender objects to flockkit jobs, and flockkit's results back to objects and keys.

Time: motions run at ``dt = 1 / fps`` (the scene's rate), motion frame k at Blender frame
``frame_start + k``; a key at frame f is a constraint at ``(f - frame_start) / fps`` seconds.
Space: Blender's world is flockkit's (z up, metres); a 2D flock lies in the plane z = 0 and reads
x and y of what the user placed."""

import bpy
import numpy as np
from mathutils import Vector

FLOCK = "flockkit Flock"
CROWD = "flockkit Crowd"
SCENE = "flockkit Scene"


# -- time and keys ------------------------------------------------------------------------------


def rate(scene) -> float:
    return scene.render.fps / scene.render.fps_base


def fcurves(action, slot=None) -> list:
    """The F-curves of `action` (of `slot` where given): a layered action's (Blender 4.4 and
    newer) or a legacy action's."""
    found = []
    for layer in getattr(action, "layers", ()):
        for strip in layer.strips:
            for bag in strip.channelbags:
                if slot is None or bag.slot == slot:
                    found.extend(bag.fcurves)
    return found or list(getattr(action, "fcurves", ()))


def key_frames(obj) -> list[int]:
    """The frames where `obj` has keys, in order."""
    data = obj.animation_data
    if data is None or data.action is None:
        return []
    frames = {round(p.co[0]) for fc in fcurves(data.action, getattr(data, "action_slot", None))
              for p in fc.keyframe_points}  # fmt: skip
    return sorted(frames)


def new_action(obj, name: str):
    obj.animation_data_create()
    action = bpy.data.actions.new(name)
    obj.animation_data.action = action
    return action


def new_fcurve(action, obj, path: str, index: int, group: str = ""):
    if hasattr(action, "fcurve_ensure_for_datablock"):  # Blender 4.4 and newer: layered actions
        return action.fcurve_ensure_for_datablock(obj, path, index=index, group_name=group)
    return action.fcurves.new(path, index=index, action_group=group)


def set_keys(fcurve, frames: np.ndarray, values: np.ndarray) -> None:
    """Keys at `frames` with `values`, linear in between (so that keys are what plays)."""
    points = fcurve.keyframe_points
    points.add(len(frames))
    points.foreach_set("co", np.column_stack([frames, values]).astype(np.float32).ravel())
    points.foreach_set("interpolation", np.full(len(frames), _LINEAR, dtype=np.int32))
    fcurve.update()


_LINEAR = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items["LINEAR"].value


def key_transform(obj, start: int, location: np.ndarray, rotation: np.ndarray | None = None) -> None:
    """Replace `obj`'s animation by keys of `location` (T, 3) and Euler `rotation` (T, 3) at
    frames start, start + 1, ..."""
    if obj.animation_data is not None and obj.animation_data.action is not None:
        old = obj.animation_data.action
        obj.animation_data.action = None
        if old.users == 0:
            bpy.data.actions.remove(old)
    action = new_action(obj, f"{obj.name} flockkit")
    frames = start + np.arange(len(location), dtype=float)
    obj.rotation_mode = "XYZ"
    for axis in range(3):
        set_keys(new_fcurve(action, obj, "location", axis, "Object Transforms"), frames, location[:, axis])
        if rotation is not None:
            set_keys(new_fcurve(action, obj, "rotation_euler", axis, "Object Transforms"), frames, rotation[:, axis])


# -- collections and objects --------------------------------------------------------------------


def collection(scene, name: str):
    found = bpy.data.collections.get(name)
    if found is None:
        found = bpy.data.collections.new(name)
    if found.name not in scene.collection.children:
        scene.collection.children.link(found)
    return found


def agent_mesh(settings):
    """The mesh every agent shares: the chosen object's, else a small cone along +x."""
    if settings.agent_object is not None:
        return settings.agent_object.data
    mesh = bpy.data.meshes.get("flockkit agent")
    if mesh is None:
        import bmesh

        mesh = bpy.data.meshes.new("flockkit agent")
        shape = bmesh.new()
        bmesh.ops.create_cone(shape, cap_ends=True, segments=8, radius1=0.15, radius2=0.0, depth=0.5)
        bmesh.ops.rotate(shape, verts=shape.verts, cent=(0, 0, 0),
                         matrix=__import__("mathutils").Matrix.Rotation(np.pi / 2, 3, "Y"))  # fmt: skip
        shape.to_mesh(mesh)
        shape.free()
    return mesh


def import_flock(context, arrays: dict, name: str = FLOCK) -> list:
    """Agents `Agent k` in the collection `name`, each an instance of the agent mesh (linked data),
    keyed at every frame from the scene's start; the scene's range covers the motion."""
    scene, settings = context.scene, context.scene.flockkit
    group = collection(scene, name)
    mesh = agent_mesh(settings)
    location, rotation = arrays["location"], arrays["rotation"]
    frames, agents = location.shape[:2]
    existing = sorted((o for o in group.objects if o.get("flockkit_agent") is not None),
                      key=lambda o: o["flockkit_agent"])  # fmt: skip
    for extra in existing[agents:]:
        bpy.data.objects.remove(extra)
    made = []
    for k in range(agents):
        obj = existing[k] if k < len(existing) else None
        if obj is None:
            obj = bpy.data.objects.new(f"Agent {k}", mesh)
            obj["flockkit_agent"] = k
            group.objects.link(obj)
        elif obj.data != mesh:
            obj.data = mesh
        key_transform(obj, scene.frame_start, location[:, k], rotation[:, k])
        made.append(obj)
    scene.frame_end = scene.frame_start + frames - 1
    return made


# -- what the user authored ---------------------------------------------------------------------


def world_positions(context, obj, frames) -> list:
    """`obj`'s world location at each of `frames` (the scene's current frame restored)."""
    scene, current = context.scene, context.scene.frame_current
    found = []
    for frame in frames:
        scene.frame_set(frame)
        found.append(np.array(obj.matrix_world.translation, dtype=float))
    scene.frame_set(current)
    return found


def agents_of(text: str):
    """'0-4,7' -> [0, 1, 2, 3, 4, 7]; '' -> None (all)."""
    if not text.strip():
        return None
    found = []
    for part in text.replace(" ", "").split(","):
        low, _, high = part.partition("-")
        found += list(range(int(low), int(high or low) + 1))
    return found


def heading(obj, speed: float, dims: int) -> list:
    """The object's world X axis times `speed`: the velocity a lone constraint or a shape gives."""
    axis = obj.matrix_world.to_3x3() @ Vector((1.0, 0.0, 0.0))
    axis = np.array(axis, dtype=float)[:dims]
    norm = np.linalg.norm(axis)
    return list(axis / norm * speed) if norm > 0 else [speed] + [0.0] * (dims - 1)


def world_vertices(context, obj) -> np.ndarray:
    graph = context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(graph)
    mesh = evaluated.to_mesh()
    points = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", points)
    points = points.reshape(-1, 3)
    matrix = np.array(evaluated.matrix_world, dtype=float)
    evaluated.to_mesh_clear()
    return points.astype(float) @ matrix[:3, :3].T + matrix[:3, 3]


def outline(context, obj) -> list:
    """The mesh's outline seen from above, counter-clockwise: its boundary loop where it has one
    (a flat shape), else the convex hull of its vertices in x, y."""
    graph = context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(graph)
    mesh = evaluated.to_mesh()
    matrix = np.array(evaluated.matrix_world, dtype=float)
    points = np.array([matrix[:3, :3] @ np.array(v.co) + matrix[:3, 3] for v in mesh.vertices])[:, :2]
    count = {}
    for polygon in mesh.polygons:
        for edge in polygon.edge_keys:
            count[edge] = count.get(edge, 0) + 1
    boundary = [edge for edge, n in count.items() if n == 1]
    evaluated.to_mesh_clear()
    loop = _loop(boundary)
    if loop is None:
        return _hull(points)
    vertices = points[loop]
    area = np.sum(vertices[:, 0] * np.roll(vertices[:, 1], -1) - np.roll(vertices[:, 0], -1) * vertices[:, 1])
    return (vertices if area > 0 else vertices[::-1]).tolist()


def _loop(edges):
    """The vertices of `edges` in order if they form one closed loop, else None."""
    if len(edges) < 3:
        return None
    neighbours = {}
    for a, b in edges:
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    if any(len(n) != 2 for n in neighbours.values()):
        return None
    start = edges[0][0]
    loop, previous, current = [start], None, start
    while True:
        nxt = neighbours[current][0] if neighbours[current][0] != previous else neighbours[current][1]
        if nxt == start:
            break
        loop.append(nxt)
        previous, current = current, nxt
    return loop if len(loop) == len(neighbours) else None


def _hull(points: np.ndarray) -> list:
    """Andrew's monotone chain: the convex hull of 2D points, counter-clockwise."""
    ordered = sorted(set(map(tuple, np.round(points, 9))))

    def half(sequence):
        chain = []
        for p in sequence:
            while len(chain) >= 2 and np.cross(np.subtract(chain[-1], chain[-2]), np.subtract(p, chain[-2])) <= 0:
                chain.pop()
            chain.append(p)
        return chain[:-1]

    return [list(p) for p in half(ordered) + half(ordered[::-1])]


def region(context, obj, dims: int) -> dict:
    """The job's region for a mesh object (its `region` setting)."""
    kind = obj.flockkit.region
    if kind == "AUTO":
        kind = "POLYGON" if dims == 2 else "BOX"
    if kind == "POLYGON":
        if dims != 2:
            raise ValueError(f"{obj.name}: a polygon is a 2D region; choose Box or Ball for a 3D flock")
        return {"kind": "polygon", "vertices": outline(context, obj)}
    points = world_vertices(context, obj)[:, :dims]
    low, high = points.min(axis=0), points.max(axis=0)
    if kind == "BOX":
        return {"kind": "box", "lower": low.tolist(), "upper": high.tolist()}
    return {"kind": "ball", "center": ((low + high) / 2).tolist(), "radius": float((high - low).max() / 2)}


def problem(context) -> dict:
    """The job's problem from the scene: agents, dims and the frame range from the settings, a
    constraint per key of every point and centre-of-mass empty, a shape per shape mesh (at its
    first key, else the current frame), an obstacle per obstacle mesh."""
    scene, settings = context.scene, context.scene.flockkit
    dims, fps, start = int(settings.dims), rate(scene), scene.frame_start
    constraints, obstacles = [], []
    for obj in sorted(scene.objects, key=lambda o: o.name):
        role = obj.flockkit.role
        if role in ("POINT", "COM"):
            frames = [f for f in key_frames(obj) if start <= f <= scene.frame_end] or [scene.frame_current]
            for frame, position in zip(frames, world_positions(context, obj, frames)):
                c = {"kind": role.lower(), "time": (frame - start) / fps, "position": position[:dims].tolist(),
                     "name": f"{obj.name} @ {frame}"}  # fmt: skip
                if role == "POINT":
                    c["agent"] = obj.flockkit.agent
                else:
                    c["agents"] = agents_of(obj.flockkit.agents)
                if len(frames) == 1:  # a lone constraint: its velocity is the user's
                    c["velocity"] = heading(obj, obj.flockkit.speed, dims)
                constraints.append(c)
        elif role == "SHAPE":
            frame = (key_frames(obj) or [scene.frame_current])[0]
            current = scene.frame_current
            scene.frame_set(frame)
            constraints.append({
                "kind": "shape", "time": (frame - start) / fps, "shape": region(context, obj, dims),
                "agents": agents_of(obj.flockkit.agents), "velocity": heading(obj, obj.flockkit.speed, dims),
                "name": f"{obj.name} @ {frame}",
            })  # fmt: skip
            scene.frame_set(current)
        elif role == "OBSTACLE":
            obstacles.append(region(context, obj, dims))
    return {
        "n_agents": settings.agents, "dims": dims, "dt": 1.0 / fps,
        "duration": (scene.frame_end - start) / fps, "constraints": constraints, "obstacles": obstacles,
    }  # fmt: skip


def obstacles(context) -> list:
    dims = int(context.scene.flockkit.dims)
    return [region(context, o, dims) for o in context.scene.objects if o.flockkit.role == "OBSTACLE"]


def flow_arrows(context) -> list:
    """Each flow-arrow empty as the scene's arrow: its position (x, y) and, at each of its keys (or
    once), its X axis seen from above times its speed (at most 1), at seconds from the start."""
    scene = context.scene
    fps, start, current = rate(scene), scene.frame_start, scene.frame_current
    arrows = []
    for obj in sorted(scene.objects, key=lambda o: o.name):
        if obj.flockkit.role != "FLOW":
            continue
        frames = [f for f in key_frames(obj) if start <= f <= scene.frame_end] or [start]
        keyframes = []
        for frame in frames:
            scene.frame_set(frame)
            vector = np.array(heading(obj, 1.0, 2))
            keyframes.append([(frame - start) / fps, (vector * min(obj.flockkit.speed, 1.0)).tolist()])
        arrows.append({"position": list(obj.matrix_world.translation)[:2], "keyframes": keyframes})
    scene.frame_set(current)
    return arrows


def mesh_animation(context, obj) -> dict:
    """The mesh's vertices in world space at every frame of the scene's range (T, V, 3), and its
    triangles."""
    scene, current = context.scene, context.scene.frame_current
    frames = []
    for frame in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(frame)
        frames.append(world_vertices(context, obj))
    scene.frame_set(current)
    graph = context.evaluated_depsgraph_get()
    mesh = obj.evaluated_get(graph).to_mesh()
    mesh.calc_loop_triangles()
    faces = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", faces)
    obj.evaluated_get(graph).to_mesh_clear()
    return {"positions": np.stack(frames), "faces": faces.reshape(-1, 3)}
