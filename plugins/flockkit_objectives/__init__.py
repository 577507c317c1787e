"""The built-in objective terms ``com``, ``shape`` and ``flocks`` (paper 004, section 3.4.2)."""

import flockkit

from .terms import ComTerm, FlockTerm, ShapeTerm

__all__ = ["ComTerm", "ShapeTerm", "FlockTerm"]


@flockkit.hookimpl
def flockkit_register_objectives(registry):
    registry.add("com", ComTerm, description="Gaussian on the center-of-mass error at COM-constrained frames (g_c)")
    registry.add("shape", ShapeTerm, description="-c_S x squared distance of agents outside their shape (g_s)")
    registry.add("flocks", FlockTerm, description="-c_F x |flocks - preferred| at every frame (g_f)")
