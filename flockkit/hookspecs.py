"""The pluggy hook specifications: one ``flockkit_register_<kind>s(registry)`` per extension kind.

A plugin module implements any of them with ``@flockkit.hookimpl`` and calls
``registry.add(name, factory, description=...)`` for each component it offers::

    import flockkit

    @flockkit.hookimpl
    def flockkit_register_behaviors(registry):
        registry.add("vicsek", Vicsek, description="Vicsek alignment with angular noise")

It is found through an entry point in the ``flockkit`` group of its distribution. Which hook
registers which kind is ``flockkit.kinds.KINDS[kind].hook``.
"""

from __future__ import annotations

import pluggy

PROJECT = "flockkit"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def flockkit_register_behaviors(registry):
    """Register behavior models (protocol ``flockkit.interfaces.BehaviorModel``)."""


@hookspec
def flockkit_register_metrics(registry):
    """Register configuration metrics (protocol ``flockkit.interfaces.ConfigurationMetric``)."""


@hookspec
def flockkit_register_builders(registry):
    """Register motion-graph builders (protocol ``flockkit.interfaces.GraphBuilder``)."""


@hookspec
def flockkit_register_walks(registry):
    """Register walk strategies (protocol ``flockkit.interfaces.WalkStrategy``)."""


@hookspec
def flockkit_register_proposals(registry):
    """Register sampler proposal moves (protocol ``flockkit.interfaces.ProposalMove``)."""


@hookspec
def flockkit_register_objectives(registry):
    """Register sampler objective terms (protocol ``flockkit.interfaces.Objective``)."""


@hookspec
def flockkit_register_segmenters(registry):
    """Register segmenters (protocol ``flockkit.interfaces.Segmenter``)."""


@hookspec
def flockkit_register_controllers(registry):
    """Register animation controllers (protocol ``flockkit.interfaces.Controller``)."""
