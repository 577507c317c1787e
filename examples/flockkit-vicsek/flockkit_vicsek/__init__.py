"""A Vicsek-style behavior model registered with flockkit through an entry point."""

import flockkit

from .model import Vicsek

__all__ = ["Vicsek"]


@flockkit.hookimpl
def flockkit_register_behaviors(registry):
    registry.add("vicsek", Vicsek, description="Vicsek alignment at constant speed with angular noise")
