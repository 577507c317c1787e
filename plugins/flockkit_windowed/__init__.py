"""The built-in builder ``windowed`` (paper 002, section 4.3): motion graphs of objects that stay in place."""

import flockkit

from .builder import Windowed

__all__ = ["Windowed"]


@flockkit.hookimpl
def flockkit_register_builders(registry):
    registry.add(
        "windowed",
        Windowed,
        description="windows of positions and velocities compared in place (no alignment), per-transition blends",
    )
