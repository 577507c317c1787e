"""The built-in walk strategies ``random`` and ``region`` (paper 000, section 5)."""

import flockkit

from .strategies import RandomWalk, RegionWalk

__all__ = ["RandomWalk", "RegionWalk"]


@flockkit.hookimpl
def flockkit_register_walks(registry):
    registry.add("random", RandomWalk, description="uniformly random edges (Lai et al. 2005, 5.1)")
    registry.add("region", RegionWalk, description="keep the center of mass inside a region (Lai et al. 2005, 5.2)")
