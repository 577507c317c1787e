"""Each extension kind of flockkit as one declared object: the pluggy hook that registers it, the
protocol its components honour (methods, and attributes such as a controller's ``skeleton``), the
``Capabilities`` fields it reads, the operations and factory parameters those fields promise, and
the module of the conformance kit that checks it.

The registry, the conformance kit, the command line and the docs read this table; nothing else
lists the kinds::

    from flockkit.kinds import KINDS

    KINDS["walk"].hook           # "flockkit_register_walks"
    KINDS["walk"].protocol       # flockkit.interfaces.WalkStrategy
    KINDS["walk"].factory_parameters["targets"]   # ("target", "features", "avoid")
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import attrs

from . import interfaces

__all__ = ["Kind", "KINDS"]


def _frozen(value) -> Mapping:
    return MappingProxyType(dict(value))


@attrs.frozen(kw_only=True)
class Kind:
    """One extension kind.

    Attributes
    ----------
    name : str
        What ``flockkit.get(kind, ...)`` and the command line call it ("behavior").
    hook : str
        The pluggy hook a plugin implements to register components of the kind
        (``flockkit.hookspecs``).
    protocol : type
        The ``typing.Protocol`` its components honour (``flockkit.interfaces``): the methods, with
        the parameters registration checks, and the contract in its docstring.
    attributes : tuple of str
        Attributes (not methods) every component has: a controller's ``skeleton``.
    fields : frozenset of str
        The ``Capabilities`` fields, besides ``dims``, that something reads for this kind; a
        component declaring another is refused at registration.
    optional : mapping of str to type
        Capabilities field -> a protocol of the methods a component declaring it must offer.
    factory_parameters : mapping of str to tuple of str
        Capabilities field -> the parameters the factory of a component declaring it must take
        (a behavior declaring ``obstacles`` takes ``obstacles=``).
    kit : str
        The module of ``flockkit.testing`` whose ``CHECKS`` check the kind's behaviour.
    receives, returns : tuple of str
        The value types (dotted paths) its components are handed and give back: what its
        reference page documents, field by field, and ``flockkit.testing.strategies`` draws.
    """

    name: str
    hook: str
    protocol: type
    attributes: tuple = ()
    fields: frozenset = attrs.field(default=frozenset(), converter=frozenset)
    optional: Mapping = attrs.field(factory=dict, converter=_frozen)
    factory_parameters: Mapping = attrs.field(factory=dict, converter=_frozen)
    kit: str
    receives: tuple = ()
    returns: tuple = ()


KINDS: Mapping[str, Kind] = _frozen(
    (kind.name, kind)
    for kind in (
        Kind(
            name="behavior",
            hook="flockkit_register_behaviors",
            protocol=interfaces.BehaviorModel,
            fields={"guide", "group_guide", "obstacles", "plausibility_reach", "residuals", "coupling", "progress"},
            optional={
                "guide": interfaces.Guided,
                "group_guide": interfaces.GroupGuided,
                "residuals": interfaces.Residuals,
                "coupling": interfaces.Coupling,
                "progress": interfaces.SimulationProgress,
            },
            factory_parameters={"obstacles": ("obstacles",)},
            kit="flockkit.testing.behavior",
            receives=("flockkit.motion.State", "flockkit.motion.Motion"),
            returns=("flockkit.motion.Motion",),
        ),
        Kind(
            name="metric",
            hook="flockkit_register_metrics",
            protocol=interfaces.ConfigurationMetric,
            fields={"lower_bound", "pairs_within", "pairwise"},
            optional={
                "lower_bound": interfaces.LowerBound,
                "pairs_within": interfaces.PairsWithin,
                "pairwise": interfaces.Pairwise,
            },
            kit="flockkit.testing.metric",
            receives=("flockkit.motion.Configuration",),
            returns=("flockkit.motion.Alignment",),
        ),
        Kind(
            name="builder",
            hook="flockkit_register_builders",
            protocol=interfaces.GraphBuilder,
            fields={"progress"},
            optional={"progress": interfaces.BuildProgress},
            kit="flockkit.testing.builder",
            receives=("flockkit.motion.Motion",),
            returns=("flockkit.graphs.MotionGraph", "flockkit.graphs.Clip", "flockkit.graphs.Transition"),
        ),
        Kind(
            name="walk",
            hook="flockkit_register_walks",
            protocol=interfaces.WalkStrategy,
            fields={"targets"},
            factory_parameters={"targets": ("target", "features", "avoid")},
            kit="flockkit.testing.walk",
            receives=("flockkit.graphs.MotionGraph", "flockkit.graphs.Clip", "flockkit.graphs.Transition"),
            returns=("flockkit.graphs.Walk",),
        ),
        Kind(
            name="proposal",
            hook="flockkit_register_proposals",
            protocol=interfaces.ProposalMove,
            kit="flockkit.testing.proposal",
            receives=("flockkit.motion.Motion", "flockkit.constrained.ProposalContext"),
            returns=("flockkit.constrained.Proposal",),
        ),
        Kind(
            name="objective",
            hook="flockkit_register_objectives",
            protocol=interfaces.Objective,
            kit="flockkit.testing.objective",
            receives=("flockkit.motion.Motion", "flockkit.constrained.Problem"),
            returns=(),
        ),
        Kind(
            name="segmenter",
            hook="flockkit_register_segmenters",
            protocol=interfaces.Segmenter,
            fields={"skin"},
            optional={"skin": interfaces.Skinned},
            kit="flockkit.testing.segmenter",
            receives=("flockkit.motion.Motion", "flockkit.mesh.MeshSkin"),
            returns=("flockkit.scene.Segmentation",),
        ),
        Kind(
            name="controller",
            hook="flockkit_register_controllers",
            protocol=interfaces.Controller,
            attributes=("skeleton",),
            fields={"clip_player", "root_motion", "batch", "live"},
            optional={
                "root_motion": interfaces.RootMotionSource,
                "batch": interfaces.BatchedController,
                "live": interfaces.LiveController,
            },  # fmt: skip
            factory_parameters={"clip_player": ("clip", "rate")},
            kit="flockkit.testing.controller",
            receives=("flockkit.skeleton.SkeletalClip", "flockkit.skeleton.Channel"),
            returns=("flockkit.skeleton.Pose", "flockkit.skeleton.Event", "flockkit.skeleton.Skeleton"),
        ),
    )
)


def page(kind: str, section: str | None = None) -> str:
    """Where flockkit's documentation describes `kind` (and one `section` of that page), as error
    messages cite it."""
    where = f"the {kind} page of flockkit's documentation (kinds/{kind}/)"
    return f'{where}, section "{section}"' if section else where
