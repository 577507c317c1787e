"""The built-in ``boids`` behavior model (paper 004, section 3.1), registered as a flockkit plugin."""

import flockkit

from .model import Boids

__all__ = ["Boids"]


@flockkit.hookimpl
def flockkit_register_behaviors(registry):
    registry.add(
        "boids",
        Boids,
        description="Reynolds flocking with wander; forward, backward and plausibility (Anderson et al. 2003)",
    )
