"""The built-in proposal moves ``bump``, ``velocity`` and ``regenerate`` (paper 004, section 3.4.1)."""

import flockkit

from .moves import Bump, Regenerate, Retime

__all__ = ["Bump", "Retime", "Regenerate"]


@flockkit.hookimpl
def flockkit_register_proposals(registry):
    registry.add("bump", Bump, description="1-3 quartic bumps added in multi-resolution coordinates (0.6)")
    registry.add("velocity", Retime, description="re-time one agent along its own path, ends fixed (0.1)")
    registry.add("regenerate", Regenerate, description="rebuild all, or 1-3 windows, as initial trajectories (0.1)")
