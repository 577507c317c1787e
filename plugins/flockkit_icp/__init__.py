"""The built-in ``icp-hungarian`` configuration metric (paper 000, section 4.2)."""

import flockkit

from .metric import IcpHungarian, exact_distance

__all__ = ["IcpHungarian", "exact_distance"]


@flockkit.hookimpl
def flockkit_register_metrics(registry):
    registry.add(
        "icp-hungarian",
        IcpHungarian,
        description="mean squared distance after the best rigid motion and agent matching (Lai et al. 2005)",
    )
