"""The kinds as one declared table: the registry, the kit and the docs read it, and the contracts
the newer code relies on (a scene's walks, a crowd's clip players, a controller's skeleton) are
declared there and checked at registration, instead of failing deep inside a run."""

import numpy as np
import pytest

import flockkit
from flockkit import hookspecs, registry
from flockkit.errors import PluginError, ValidationError
from flockkit.kinds import KINDS

pytestmark = pytest.mark.usefixtures("fresh_registry")


def test_every_kind_has_a_hook_a_protocol_and_kit_checks_and_every_hook_a_kind():
    import importlib

    hooks = {name for name in vars(hookspecs) if name.startswith("flockkit_register_")}
    assert {kind.hook for kind in KINDS.values()} == hooks
    for kind in KINDS.values():
        assert importlib.import_module(kind.kit).CHECKS  # the kit checks each kind's behaviour
        assert set(kind.optional) <= kind.fields and set(kind.factory_parameters) <= kind.fields
    assert registry.KINDS == tuple(KINDS) and set(flockkit.available()) == set(KINDS)


class _Follower:
    """A walk that says it takes targets, and does not."""

    capabilities = flockkit.Capabilities(targets=True)

    def walk(self, graph, rng, duration):
        raise AssertionError("never walked")


class _Plugin:
    def __init__(self, factory):
        self.factory = factory

    @flockkit.hookimpl
    def flockkit_register_walks(self, registry):
        registry.add("follower", self.factory)


def test_a_walk_declaring_targets_must_take_target_features_and_avoid():
    registry.register(_Plugin(_Follower), name="follower-plugin")
    with pytest.raises(PluginError, match="no parameter 'target' \\(capabilities.targets is declared\\)"):
        flockkit.available()


def test_a_scene_refuses_a_walk_that_takes_no_targets_before_any_work():
    from tests.core.test_scene import MEADOW, plants

    with pytest.raises(ValidationError, match="a Scene's walks need a walk declaring Capabilities\\(targets=True\\)"):
        flockkit.Scene(templates=[plants()], region=MEADOW, counts=[2], duration=5, walk="random")


def _walker():
    from flockkit.testing import inputs

    return inputs.walker()


def test_a_stream_takes_a_controller_by_name_or_instance():
    from flockkit.crowd import Stream

    clip = _walker()
    by_name = Stream(controller="clip", controller_params={"clip": clip, "rate": 2.0}, history=4)
    made = flockkit.get("controller", "clip", clip=clip, rate=2.0)
    assert by_name.controller == made
    assert Stream(controller=made, history=4).controller is made
    with pytest.raises(ValidationError, match="controller_params are for a controller made by name"):
        Stream(controller=made, controller_params={"rate": 1.0}, history=4)
    with pytest.raises(flockkit.errors.UnknownPluginError, match="Stream.controller: no controller named 'clips'"):
        Stream(controller="clips", history=4)


class _NoSkeleton:
    def pose(self, times):
        raise AssertionError

    def events(self, start, stop):
        return []


def test_a_controller_without_a_skeleton_is_refused_where_it_is_used():
    from flockkit.crowd import Stream

    with pytest.raises(ValidationError, match="skeleton: missing \\(an attribute\\)"):
        Stream(controller=_NoSkeleton(), history=4)


def test_a_crowd_helper_refuses_a_controller_that_plays_no_clips():
    from flockkit.crowd import driven_sliding

    clip = _walker()
    motion = flockkit.Motion(positions=np.zeros((3, 1, 2)), dt=0.1)
    with pytest.raises(ValidationError, match="declaring Capabilities\\(clip_player=True\\); controller graph-walk"):
        driven_sliding(motion, clip, clip, ["foot.L"], [1.0], controller="graph-walk")
