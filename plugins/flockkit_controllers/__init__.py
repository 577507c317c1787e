"""The built-in controllers ``clip``, ``blend``, ``mask``, ``graph-walk`` and ``locomotion`` (paper 003,
section 3.4)."""

import flockkit

from .controllers import Blend, ClipPlayer, GraphWalk, Locomotion, Mask

__all__ = ["ClipPlayer", "Blend", "Mask", "GraphWalk", "Locomotion"]


@flockkit.hookimpl
def flockkit_register_controllers(registry):
    registry.add("clip", ClipPlayer, description="plays a skeletal clip, looping or once, at a playback rate")
    registry.add("blend", Blend, description="two children mixed by a weight, rotations on the sphere (Equation 2)")
    registry.add("mask", Mask, description="children combined joint by joint by blend masks (Equation 3)")
    registry.add(
        "graph-walk",
        GraphWalk,
        description="an endless, non-repeating stream: a random walk through a motion graph of a clip",
    )
    registry.add(
        "locomotion",
        Locomotion,
        description="a live state machine fed speed and turn rate each frame: clips blended by speed, in step",
    )
