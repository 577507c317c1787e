"""The add-on's settings: ``scene.flockkit`` (flock, solve, scene and crowd settings and what the
last run reported), ``object.flockkit`` (what an object is to flockkit: a point or centre-of-mass
constraint, a shape, an obstacle, a flow arrow, a character), and the preference naming the
Python where flockkit is installed."""

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

ROLES = [
    ("NONE", "None", "Not used by flockkit"),
    ("POINT", "Point constraint", "An empty keyframed where its agent must be at each key"),
    ("COM", "Centre of mass", "An empty keyframed where the group's centre must be at each key"),
    ("SHAPE", "Shape", "A mesh the agents must lie inside at its frame"),
    ("OBSTACLE", "Obstacle", "A mesh the agents avoid"),
    ("FLOW", "Flow arrow", "An empty whose X axis is a scene's flow arrow (keyframe its rotation)"),
]
REGIONS = [
    ("AUTO", "Automatic", "A polygon (its outline seen from above) in 2D, its bounding box in 3D"),
    ("BOX", "Box", "Its world bounding box"),
    ("BALL", "Ball", "The ball around its bounding box's centre, to its largest half-extent"),
    ("POLYGON", "Polygon", "Its outline seen from above (2D flocks only)"),
]


class FlockkitPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    python: StringProperty(
        name="flockkit's Python", subtype="FILE_PATH",
        description="The Python where flockkit is installed (empty: FLOCKKIT_PYTHON, else the flockkit command's)",
    )  # fmt: skip

    def draw(self, context):
        self.layout.prop(self, "python")


class FlockkitParameter(bpy.types.PropertyGroup):
    value: FloatProperty(name="Value")
    integer: BoolProperty(name="Whole number", description="The behavior takes a whole number")


class FlockkitHint(bpy.types.PropertyGroup):
    alert: BoolProperty(name="Beyond the model")


class FlockkitObject(bpy.types.PropertyGroup):
    role: EnumProperty(name="Role", items=ROLES, default="NONE")
    agent: IntProperty(name="Agent", min=0, description="The agent a point constraint holds")
    agents: StringProperty(name="Agents", description="The agents held, as 0-4,7 (empty: all)")
    speed: FloatProperty(
        name="Speed", default=1.0, min=0.0,
        description="A lone constraint's or a shape's speed along the object's X axis; a flow arrow's length (0-1)",
    )  # fmt: skip
    region: EnumProperty(name="Region", items=REGIONS, default="AUTO")
    ground_speed: FloatProperty(
        name="Ground speed", default=1.0, min=0.0, unit="VELOCITY",
        description="How fast a character's action carries it over the ground at the action's own rate",
    )  # fmt: skip


class FlockkitSettings(bpy.types.PropertyGroup):
    agents: IntProperty(name="Agents", default=20, min=1, max=100000)
    dims: EnumProperty(name="Space", items=[("2", "2D", "On the ground, z = 0"), ("3", "3D", "In the air")],
                       default="2")  # fmt: skip
    behavior: StringProperty(name="Behavior", description="An installed behavior model (empty: flockkit's default)")
    parameters: CollectionProperty(type=FlockkitParameter)
    agent_object: PointerProperty(
        name="Agent", type=bpy.types.Object, description="The mesh every agent shows (empty: a small cone)",
        poll=lambda self, obj: obj.type == "MESH",
    )  # fmt: skip
    seed: IntProperty(name="Seed", default=1, min=0)
    iterations: IntProperty(name="Iterations", default=200, min=0)
    refine: IntProperty(name="Refine steps", default=40, min=0)
    progress: FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0, subtype="FACTOR")
    status: StringProperty(name="Status")
    running: BoolProperty(name="Running")
    hints: CollectionProperty(type=FlockkitHint)
    folder: StringProperty(
        name="Folder", subtype="DIR_PATH",
        description="Where flockkit's jobs, motions and layers go (empty: Blender's temporary folder)",
    )  # fmt: skip
    motion_file: StringProperty(name="Motion file", subtype="FILE_PATH",
                                description="The last flock simulated or solved (flockkit .npz)")  # fmt: skip
    template: PointerProperty(
        name="Animated mesh", type=bpy.types.Object, poll=lambda self, obj: obj.type == "MESH",
        description="The animated mesh a scene is made of (its animation over the scene's frame range)",
    )  # fmt: skip
    arrow: FloatVectorProperty(
        name="Held arrow", size=3, default=(0.0, 0.0, 0.0),
        description="The arrow the mesh's animation holds in its own axes (zero: its own travel)",
    )  # fmt: skip
    layers_file: StringProperty(name="Layers file", subtype="FILE_PATH")
    parts: IntProperty(name="Parts")
    ground: PointerProperty(name="Ground", type=bpy.types.Object, poll=lambda self, obj: obj.type == "MESH")
    count: IntProperty(name="Copies", default=6, min=1)


CLASSES = (FlockkitPreferences, FlockkitParameter, FlockkitHint, FlockkitObject, FlockkitSettings)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.flockkit = PointerProperty(type=FlockkitSettings)
    bpy.types.Object.flockkit = PointerProperty(type=FlockkitObject)


def unregister():
    del bpy.types.Object.flockkit
    del bpy.types.Scene.flockkit
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
