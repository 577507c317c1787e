"""The built-in segmenter ``ica-kmeans`` (paper 002, section 4.1)."""

import flockkit

from .segmenter import IcaKmeans

__all__ = ["IcaKmeans"]


@flockkit.hookimpl
def flockkit_register_segmenters(registry):
    registry.add(
        "ica-kmeans",
        IcaKmeans,
        description="ICA of the per-point velocity energy, k-means on the mixing matrix (parts chosen automatically)",
    )
