"""The built-in segmenter ``skin-parts``: a skinned mesh's parts from its joints and weights,
merged along the skeleton by how they move."""

import flockkit

from .segmenter import SkinParts, joint_adjacency, rigid_residual

__all__ = ["SkinParts", "joint_adjacency", "rigid_residual"]


@flockkit.hookimpl
def flockkit_register_segmenters(registry):
    registry.add(
        "skin-parts",
        SkinParts,
        description="a skinned mesh's joints (each vertex to its largest weight), neighbours in the skeleton merged "
        "while they move as one rigid body (needs a skin)",
    )
