"""The built-in walk strategies ``random``, ``region`` (paper 000, section 5) and ``annotated``
(paper 002, section 6.1)."""

import flockkit

from .annotated import AnnotatedWalk
from .strategies import RandomWalk, RegionWalk

__all__ = ["AnnotatedWalk", "RandomWalk", "RegionWalk"]


@flockkit.hookimpl
def flockkit_register_walks(registry):
    registry.add("random", RandomWalk, description="uniformly random edges (Lai et al. 2005, 5.1)")
    registry.add("region", RegionWalk, description="keep the center of mass inside a region (Lai et al. 2005, 5.2)")
    registry.add(
        "annotated", AnnotatedWalk, description="follow a target feature track (Wang and Chen, paper 002, 6.1)"
    )
