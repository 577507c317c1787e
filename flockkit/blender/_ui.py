"""The panels: the 3D view's sidebar, tab "flockkit" (press N): Flock, Constraints, Scene, Crowd,
and the active object's role."""

import bpy


class _Panel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "flockkit"


def _progress(layout, settings) -> None:
    if settings.running:
        layout.progress(factor=settings.progress, type="BAR", text=settings.status)
    elif settings.status:
        layout.label(text=settings.status)


class FLOCKKIT_PT_flock(_Panel, bpy.types.Panel):
    bl_label = "Flock"

    def draw(self, context):
        settings, layout = context.scene.flockkit, self.layout
        layout.prop(settings, "agents")
        layout.prop(settings, "dims", expand=True)
        layout.prop(settings, "agent_object")
        row = layout.row(align=True)
        row.prop(settings, "behavior")
        row.operator("flockkit.behavior", text="", icon="FILE_REFRESH")
        column = layout.column(align=True)
        for parameter in settings.parameters:
            column.prop(parameter, "value", text=parameter.name.replace("_", " "))
        layout.prop(settings, "seed")
        layout.prop(settings, "folder")
        layout.operator("flockkit.simulate", icon="PLAY")
        _progress(layout, settings)


class FLOCKKIT_PT_constraints(_Panel, bpy.types.Panel):
    bl_label = "Constraints"

    def draw(self, context):
        settings, layout = context.scene.flockkit, self.layout
        grid = layout.grid_flow(columns=2, align=True)
        for role, text in (("POINT", "Point"), ("COM", "Centre"), ("SHAPE", "Shape"), ("OBSTACLE", "Obstacle")):
            grid.operator("flockkit.add", text=text).role = role
        layout.operator("flockkit.hints", icon="INFO")
        box = layout.box()
        for hint in settings.hints:
            row = box.row()
            row.alert = hint.alert
            row.label(text=hint.name, icon="ERROR" if hint.alert else "NONE")
        layout.prop(settings, "iterations")
        layout.prop(settings, "refine")
        layout.operator("flockkit.solve", icon="CON_FOLLOWPATH")
        _progress(layout, settings)


class FLOCKKIT_PT_scene(_Panel, bpy.types.Panel):
    bl_label = "Scene"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings, layout = context.scene.flockkit, self.layout
        layout.prop(settings, "template")
        layout.prop(settings, "arrow")
        layout.operator("flockkit.analyse", icon="MOD_EXPLODE")
        if settings.parts:
            layout.label(text=f"{settings.parts} parts (vertex groups 'flockkit part k')")
        layout.prop(settings, "ground")
        layout.prop(settings, "count")
        layout.operator("flockkit.add", text="Flow arrow").role = "FLOW"
        layout.operator("flockkit.scatter", icon="PARTICLES")
        _progress(layout, settings)


class FLOCKKIT_PT_crowd(_Panel, bpy.types.Panel):
    bl_label = "Crowd"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.label(text="Select armatures with actions")
        obj = context.active_object
        if obj is not None and obj.type == "ARMATURE":
            layout.prop(obj.flockkit, "ground_speed")
        layout.operator("flockkit.crowd", icon="COMMUNITY")


class FLOCKKIT_PT_object(_Panel, bpy.types.Panel):
    bl_label = "Active object"

    @classmethod
    def poll(cls, context):
        return context.active_object is not None

    def draw(self, context):
        settings, layout = context.active_object.flockkit, self.layout
        layout.prop(settings, "role")
        if settings.role == "POINT":
            layout.prop(settings, "agent")
        if settings.role in ("COM", "SHAPE"):
            layout.prop(settings, "agents")
        if settings.role in ("POINT", "COM", "SHAPE", "FLOW"):
            layout.prop(settings, "speed")
        if settings.role in ("SHAPE", "OBSTACLE"):
            layout.prop(settings, "region")


CLASSES = (FLOCKKIT_PT_flock, FLOCKKIT_PT_constraints, FLOCKKIT_PT_scene, FLOCKKIT_PT_crowd, FLOCKKIT_PT_object)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
