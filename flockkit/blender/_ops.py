"""The operators (``bpy.ops.flockkit.*``). Each gathers what the user authored, runs one flockkit
job and imports its result. Run from a button, ``solve``, ``analyse`` and ``scatter`` keep Blender
responsive (a modal timer polls the worker and fills the progress bar; Esc cancels); run from a
script (``execute``), every operator waits for its result."""

import tempfile
from pathlib import Path

import bpy
import numpy as np
from bpy.props import EnumProperty

from . import _bridge, _job
from ._props import ROLES


def _python(context) -> str:
    return _job.find_python(context.preferences.addons[__package__].preferences.python)


def _folder(context) -> Path:
    """Where jobs and results go: the settings' folder, else one in Blender's temporary folder
    (removed when Blender quits)."""
    chosen = context.scene.flockkit.folder
    folder = Path(bpy.path.abspath(chosen)) if chosen else Path(bpy.app.tempdir or tempfile.gettempdir()) / "flockkit"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _params(settings) -> dict:
    return {p.name: round(p.value) if p.integer else p.value for p in settings.parameters}


def _flock_fields(context) -> dict:
    settings = context.scene.flockkit
    return {"behavior": settings.behavior, "params": _params(settings), "seed": settings.seed}


class _Worker:
    """What the long operators share: `start` makes the job; `finish` imports its result. Invoked
    from the interface they run modal with a timer; executed, they wait."""

    _jobs = {}  # operator class -> running Job (one each)

    def start(self, context):
        raise NotImplementedError

    def finish(self, context, arrays, fields):
        raise NotImplementedError

    def execute(self, context):
        try:
            job = self.start(context)
            arrays, fields = job.wait()
            return self._done(context, arrays, fields)
        except (_job.WorkerError, ValueError) as exc:
            return self._failed(context, exc)

    def invoke(self, context, event):
        settings = context.scene.flockkit
        if settings.running:
            self.report({"WARNING"}, "flockkit is already running a job")
            return {"CANCELLED"}
        try:
            self._job = self.start(context)
        except (_job.WorkerError, ValueError) as exc:
            return self._failed(context, exc)
        settings.running, settings.progress, settings.status = True, 0.0, f"{self._job.stage}..."
        self._timer = context.window_manager.event_timer_add(0.2, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        settings = context.scene.flockkit
        if event.type == "ESC":
            self._job.cancel()
            self._stop(context)
            settings.status = "cancelled"
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        settings.progress = self._job.progress
        settings.status = f"{self._job.stage}: {self._job.progress:.0%}"
        for area in context.screen.areas if context.screen else ():
            area.tag_redraw()
        if not self._job.poll():
            return {"PASS_THROUGH"}
        self._stop(context)
        try:
            arrays, fields = self._job.result()
        except _job.WorkerError as exc:
            return self._failed(context, exc)
        return self._done(context, arrays, fields)

    def _stop(self, context):
        context.window_manager.event_timer_remove(self._timer)
        context.scene.flockkit.running = False

    def _done(self, context, arrays, fields):
        settings = context.scene.flockkit
        settings.progress = 1.0
        message = self.finish(context, arrays, fields)
        settings.status = message
        self.report({"INFO"}, message)
        for warning in fields.get("warnings", ()):
            self.report({"WARNING"}, warning)
        return {"FINISHED"}

    def _failed(self, context, exc):
        context.scene.flockkit.status = f"error: {exc}"
        context.scene.flockkit.running = False
        self.report({"ERROR"}, str(exc))
        return {"CANCELLED"}


class FLOCKKIT_OT_behavior(bpy.types.Operator):
    """Load the behavior's parameters and their defaults into the panel"""

    bl_idname = "flockkit.behavior"
    bl_label = "Load parameters"

    def execute(self, context):
        settings = context.scene.flockkit
        try:
            _, found = _job.run(_python(context), "describe", {}, folder=_folder(context))
        except _job.WorkerError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        name = settings.behavior or found["default"]
        if name not in found["behaviors"]:
            self.report({"ERROR"}, f"no behavior {name!r}; installed: {', '.join(found['behaviors'])}")
            return {"CANCELLED"}
        settings.behavior = name
        settings.parameters.clear()
        for key, value in found["behaviors"][name].items():
            item = settings.parameters.add()
            item.name, item.value, item.integer = key, value, isinstance(value, int)
        settings.status = f"flockkit {found['version']}: {name}, {len(settings.parameters)} parameters"
        return {"FINISHED"}


class FLOCKKIT_OT_simulate(_Worker, bpy.types.Operator):
    """Simulate the flock over the scene's frame range into instanced agents"""

    bl_idname = "flockkit.simulate"
    bl_label = "Simulate flock"
    bl_options = {"REGISTER", "UNDO"}

    def start(self, context):
        scene, settings = context.scene, context.scene.flockkit
        folder = _folder(context)
        settings.motion_file = str(folder / "simulated.npz")
        fields = dict(_flock_fields(context), agents=settings.agents, dims=int(settings.dims),
                      dt=1.0 / _bridge.rate(scene), frames=scene.frame_end - scene.frame_start + 1,
                      obstacles=_bridge.obstacles(context), motion=settings.motion_file)  # fmt: skip
        return _job.Job(_python(context), "simulate", fields, folder=folder)

    def finish(self, context, arrays, fields):
        agents = _bridge.import_flock(context, arrays)
        return f"simulated {len(agents)} agents over {fields['frames']} frames"


class FLOCKKIT_OT_add(bpy.types.Operator):
    """Add a flockkit object at the 3D cursor: a keyed point or centre-of-mass empty, a shape or
    obstacle mesh, or a flow arrow"""

    bl_idname = "flockkit.add"
    bl_label = "Add flockkit object"
    bl_options = {"REGISTER", "UNDO"}

    role: EnumProperty(name="Role", items=[r for r in ROLES if r[0] != "NONE"])

    def execute(self, context):
        scene, cursor = context.scene, context.scene.cursor.location.copy()
        names = {"POINT": "Point", "COM": "Centre", "SHAPE": "Shape", "OBSTACLE": "Obstacle", "FLOW": "Flow"}
        if self.role in ("SHAPE", "OBSTACLE"):
            bpy.ops.mesh.primitive_plane_add(size=2.0, location=cursor)
            obj = context.active_object
            obj.name = names[self.role]
            obj.display_type = "WIRE"
        else:
            obj = bpy.data.objects.new(names[self.role], None)
            obj.empty_display_type = "SINGLE_ARROW" if self.role == "FLOW" else "ARROWS"
            obj.empty_display_size = 1.0 if self.role == "FLOW" else 0.5
            obj.location = cursor
            if self.role == "FLOW":  # an arrow empty points along its Z: lay it along X
                obj.rotation_euler = (0.0, np.pi / 2, 0.0)
            context.collection.objects.link(obj)
        obj.flockkit.role = self.role
        if self.role in ("POINT", "COM"):
            obj.keyframe_insert("location", frame=scene.frame_current)
        return {"FINISHED"}


class FLOCKKIT_OT_hints(bpy.types.Operator):
    """The speeds the constraints ask for, beside the speeds the behavior's agents move at
    unconstrained (the reach check, before solving)"""

    bl_idname = "flockkit.hints"
    bl_label = "Check speeds"

    def execute(self, context):
        settings = context.scene.flockkit
        try:
            fields = dict(_flock_fields(context), problem=_bridge.problem(context))
            _, found = _job.run(_python(context), "hints", fields, folder=_folder(context))
        except (_job.WorkerError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        model = found["model"]
        settings.hints.clear()
        head = settings.hints.add()
        head.name = (f"unconstrained: {model['p10']:.2f}-{model['p90']:.2f} m/s, "
                     f"99% below {model['p99']:.2f}")  # fmt: skip
        for leg in found["legs"]:
            hint = settings.hints.add()
            hint.name = f"{leg['name']}: {leg['speed']:.2f} m/s {leg['source']} ({leg['ratio']:.1f}x)"
            hint.alert = leg["beyond"]
        for text in found["warnings"]:
            hint = settings.hints.add()
            hint.name, hint.alert = text, True
        settings.status = f"{sum(h.alert for h in settings.hints)} constraints beyond the model"
        return {"FINISHED"}


class FLOCKKIT_OT_solve(_Worker, bpy.types.Operator):
    """Solve the constraints (point and centre-of-mass empties, shapes, obstacles) and import the
    flock; run again after edits to re-solve"""

    bl_idname = "flockkit.solve"
    bl_label = "Solve"
    bl_options = {"REGISTER", "UNDO"}

    def start(self, context):
        settings = context.scene.flockkit
        folder = _folder(context)
        settings.motion_file = str(folder / "solved.npz")
        fields = dict(_flock_fields(context), problem=_bridge.problem(context), iterations=settings.iterations,
                      refine=settings.refine, motion=settings.motion_file)  # fmt: skip
        return _job.Job(_python(context), "solve", fields, folder=folder)

    def finish(self, context, arrays, fields):
        agents = _bridge.import_flock(context, arrays)
        return f"solved {len(agents)} agents; largest constraint residual {fields['residual']:.2g}"


class FLOCKKIT_OT_analyse(_Worker, bpy.types.Operator):
    """Split the animated mesh into parts that move independently, a motion graph each (layers);
    each part becomes a vertex group"""

    bl_idname = "flockkit.analyse"
    bl_label = "Analyse into layers"
    bl_options = {"REGISTER", "UNDO"}

    def start(self, context):
        scene, settings = context.scene, context.scene.flockkit
        if settings.template is None:
            raise ValueError("choose the animated mesh first")
        folder = _folder(context)
        settings.layers_file = str(folder / f"{bpy.path.clean_name(settings.template.name)}-layers.npz")
        mesh = _bridge.mesh_animation(context, settings.template)
        np.savez(folder / "mesh.npz", **mesh)
        arrow = list(settings.arrow) if any(settings.arrow) else None
        fields = {"mesh": str(folder / "mesh.npz"), "dt": 1.0 / _bridge.rate(scene), "seed": settings.seed,
                  "arrow": arrow, "layers": settings.layers_file, "name": settings.template.name}  # fmt: skip
        return _job.Job(_python(context), "layers", fields, folder=folder)

    def finish(self, context, arrays, fields):
        settings, obj = context.scene.flockkit, context.scene.flockkit.template
        settings.parts = fields["parts"]
        labels = arrays["labels"]
        for group in [g for g in obj.vertex_groups if g.name.startswith("flockkit part ")]:
            obj.vertex_groups.remove(group)
        for part in range(fields["parts"]):
            group = obj.vertex_groups.new(name=f"flockkit part {part}")
            group.add([int(v) for v in np.flatnonzero(labels == part)], 1.0, "REPLACE")
        return f"{obj.name}: {fields['parts']} parts"


class FLOCKKIT_OT_scatter(_Worker, bpy.types.Operator):
    """Scatter copies of the analysed mesh over the ground, following the flow arrows out of step,
    and import them animated"""

    bl_idname = "flockkit.scatter"
    bl_label = "Scatter"
    bl_options = {"REGISTER", "UNDO"}

    def start(self, context):
        scene, settings = context.scene, context.scene.flockkit
        if not settings.layers_file or not Path(bpy.path.abspath(settings.layers_file)).is_file():
            raise ValueError("analyse the animated mesh into layers first")
        if settings.ground is None:
            raise ValueError("choose the ground object first")
        folder = _folder(context)
        self._usd = folder / "scene.usdc"
        fields = {"layers": bpy.path.abspath(settings.layers_file), "region": _bridge.outline(context, settings.ground),
                  "count": settings.count, "duration": (scene.frame_end - scene.frame_start) / _bridge.rate(scene),
                  "arrows": _bridge.flow_arrows(context), "seed": settings.seed, "fps": _bridge.rate(scene),
                  "usd": str(self._usd)}  # fmt: skip
        return _job.Job(_python(context), "scene", fields, folder=folder)

    def finish(self, context, arrays, fields):
        scene = context.scene
        group = _bridge.collection(scene, _bridge.SCENE)
        for obj in list(group.objects):
            bpy.data.objects.remove(obj)
        before = set(bpy.data.objects)
        start, end = scene.frame_start, scene.frame_end
        bpy.ops.wm.usd_import(filepath=str(self._usd), relative_path=False)
        scene.frame_start, scene.frame_end = start, end  # the importer sets the stage's range
        for obj in set(bpy.data.objects) - before:
            for owner in obj.users_collection:
                owner.objects.unlink(obj)
            group.objects.link(obj)
            for modifier in obj.modifiers:
                if modifier.type == "MESH_SEQUENCE_CACHE" and modifier.cache_file is not None:
                    modifier.cache_file.frame_offset = start  # time code 0 plays at the scene's start
        return f"scattered {fields['objects']} copies over {fields['frames']} frames"


class FLOCKKIT_OT_crowd(_Worker, bpy.types.Operator):
    """Drive the selected armatures (with their actions) along the flock's trajectories: a
    character per agent, each at its own offset into its action, played at its speed"""

    bl_idname = "flockkit.crowd"
    bl_label = "Crowd from flock"
    bl_options = {"REGISTER", "UNDO"}

    def start(self, context):
        settings = context.scene.flockkit
        self._characters = [o for o in context.selected_objects if o.type == "ARMATURE"
                            and o.animation_data is not None and o.animation_data.action is not None]  # fmt: skip
        if not self._characters:
            raise ValueError("select armatures that have actions")
        if not settings.motion_file or not Path(settings.motion_file).is_file():
            raise ValueError("simulate or solve a flock first")
        characters = []
        for obj in self._characters:
            first, last = obj.animation_data.action.frame_range
            characters.append({"ground_speed": obj.flockkit.ground_speed, "first": first, "last": last})
        fields = {"motion": settings.motion_file, "characters": characters, "fps": _bridge.rate(context.scene),
                  "seed": settings.seed}  # fmt: skip
        return _job.Job(_python(context), "crowd", fields, folder=_folder(context))

    def finish(self, context, arrays, fields):
        scene = context.scene
        group = _bridge.collection(scene, _bridge.CROWD)
        for obj in list(group.objects):
            bpy.data.objects.remove(obj)
        start = scene.frame_start
        location, heading, phase = arrays["location"], arrays["heading"], arrays["phase"]
        frames = start + np.arange(len(location), dtype=float)
        for k, which in enumerate(arrays["character"]):
            source = self._characters[int(which)]
            obj = bpy.data.objects.new(f"{source.name} {k}", source.data)  # the armature shared
            obj["flockkit_agent"] = k
            group.objects.link(obj)
            turn = np.zeros((len(location), 3))
            turn[:, 2] = heading[:, k]
            _bridge.key_transform(obj, start, location[:, k], turn)
            action = obj.animation_data.action
            data = source.animation_data
            for curve in _bridge.fcurves(data.action, getattr(data, "action_slot", None)):
                if not curve.data_path.startswith("pose.bones"):
                    continue
                values = np.array([curve.evaluate(float(f)) for f in phase[:, k]])
                target = _bridge.new_fcurve(action, obj, curve.data_path, curve.array_index, "Pose")
                _bridge.set_keys(target, frames, values)
        scene.frame_end = start + len(location) - 1
        return f"crowd of {len(arrays['character'])} characters over {len(location)} frames"


CLASSES = (FLOCKKIT_OT_behavior, FLOCKKIT_OT_simulate, FLOCKKIT_OT_add, FLOCKKIT_OT_hints, FLOCKKIT_OT_solve,
           FLOCKKIT_OT_analyse, FLOCKKIT_OT_scatter, FLOCKKIT_OT_crowd)  # fmt: skip

register, unregister = bpy.utils.register_classes_factory(CLASSES)
