"""The built-in ``kovar`` motion-graph builder (paper 000, section 4.3)."""

import flockkit

from .builder import Kovar

__all__ = ["Kovar"]


@flockkit.hookimpl
def flockkit_register_builders(registry):
    registry.add("kovar", Kovar, description="transitions at local minima of the difference matrix (Kovar et al. 2002)")
