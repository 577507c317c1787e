"""flockkit inside Blender: the add-on's sources (a Blender extension, built by ``flockkit
blender-addon -o flockkit_addon.zip``).

Nothing in flockkit imports this package; it imports ``bpy`` in its modules only, and those are
loaded by :func:`register`, which Blender calls. It never imports flockkit either: every piece of
flockkit's work (simulate, the reach check, solve, layers, scenes, crowds) runs in the Python where
flockkit is installed, as ``python -m flockkit.cli.blender JOB.json`` (see that module), so that
Blender's own numpy is untouched and a long solve never freezes Blender's interface. The add-on
turns Blender objects into jobs and results into objects and keys:

- ``_props``: the settings (the scene's flock, solve, scene and crowd settings; each object's role
  as a constraint, obstacle or flow arrow; the add-on's preference naming flockkit's Python);
- ``_job``: one worker process, its progress and result (no bpy: safe from any thread);
- ``_bridge``: Blender objects to the job's constraints, regions and meshes, and motions back to
  keyed objects;
- ``_ops``: the operators; ``_ui``: the panels in the 3D view's sidebar (tab "flockkit").
"""

_MODULES = ("_props", "_ops", "_ui")


def register():
    import importlib

    for name in _MODULES:
        importlib.import_module(f".{name}", __package__).register()


def unregister():
    import importlib

    for name in reversed(_MODULES):
        importlib.import_module(f".{name}", __package__).unregister()
