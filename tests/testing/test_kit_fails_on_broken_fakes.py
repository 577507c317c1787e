"""Every check of the kit passes on a correct model and fails on a model broken in its way."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument

import flockkit
from flockkit.testing import check_plugin, checks_for, inputs, parametrize_with_checks, skipped_checks
from flockkit.testing import strategies as fst

from . import fakes
from .fakes import (
    BROKEN_BY_KIND,
    ComTerm,
    Declaring,
    IcaKmeans,
    IcpHungarian,
    Kovar,
    Locomotor,
    RandomVelocity,
    RandomWalk,
    Retime,
    Strider,
    Walker,
)

CASES = [(kind, name) for kind, fakes in BROKEN_BY_KIND.items() for name in sorted(fakes)]


def check_named(kind, name):
    return {check.__name__: check for check in checks_for(kind)}[name]


@pytest.mark.parametrize("kind", sorted(BROKEN_BY_KIND))
def test_every_check_has_a_broken_fake(kind):
    assert set(BROKEN_BY_KIND[kind]) == {check.__name__ for check in checks_for(kind)}


@parametrize_with_checks(
    [
        ("behavior", RandomVelocity()),
        ("behavior", Declaring()),
        ("metric", IcpHungarian()),
        ("builder", Kovar()),
        ("walk", RandomWalk()),
        ("objective", ComTerm()),
        ("proposal", Retime()),
        ("segmenter", IcaKmeans()),
        ("controller", Walker()),
        ("controller", Strider()),
        ("controller", Locomotor()),
    ]
)
def test_correct_components_pass(component, check):
    check(component)


@pytest.mark.parametrize("kind, check_name", CASES)
def test_check_fails_on_its_broken_fake(kind, check_name):
    with pytest.raises(AssertionError):
        check_named(kind, check_name)("broken", BROKEN_BY_KIND[kind][check_name]())


@pytest.mark.parametrize("kind, check_name", CASES)
def test_check_plugin_names_the_failed_check_and_plugin(kind, check_name):
    with pytest.raises(AssertionError) as info:
        check_plugin(kind, BROKEN_BY_KIND[kind][check_name](), name="broken-component")
    message = str(info.value)
    assert "broken-component" in message and f"failed for {kind}" in message


class AsymmetricWithWrongPairwise(fakes.Asymmetric, fakes.WrongPairwise):
    """Two independent defects in one metric."""


def test_check_plugin_lists_every_failed_check_not_only_the_first():
    with pytest.raises(AssertionError) as info:
        check_plugin("metric", AsymmetricWithWrongPairwise(), name="two-defects")
    message = str(info.value)
    failed = int(message.split(" checks failed for metric 'two-defects':", 1)[0])
    assert failed >= 2 and message.count("to fix:") == failed
    assert "check_symmetric failed" in message and "check_pairwise failed" in message


def test_a_failed_interface_check_ends_the_run():
    with pytest.raises(AssertionError) as info:
        check_plugin("metric", fakes.NoCompare(), name="no-compare")
    assert str(info.value).startswith("check_interface failed for metric 'no-compare'")


class PlanarOnly:
    """Declares every dimension, walks only planar graphs."""

    def walk(self, graph, rng, duration):
        if graph.motion.dims == 3:
            raise flockkit.errors.ValidationError("cannot walk a 3D graph")
        return RandomWalk().walk(graph, rng, duration)


@pytest.mark.parametrize("check_name", ["check_walk_covers_duration", "check_walks_a_single_loop"])
def test_a_walk_is_checked_in_every_dimension_it_declares(check_name):
    with pytest.raises(AssertionError, match="3D"):
        check_named("walk", check_name)("planar", PlanarOnly())
    planar = PlanarOnly()
    planar.capabilities = flockkit.Capabilities(dims=(2,))  # declared per instance, as a region walk does
    check_named("walk", check_name)("planar", planar)


def test_a_segmenter_that_depends_on_point_order_only_where_parts_are_ambiguous_is_caught(monkeypatch):
    import flockkit_ica.segmenter as ica

    monkeypatch.setattr(ica, "_canonical_order", lambda positions: np.arange(positions.shape[1]))
    with pytest.raises(AssertionError, match="on a waving sheet"):
        check_named("segmenter", "check_order_of_points_does_not_matter")("indexed", IcaKmeans())


class PrefersTransitions:
    """Takes a transition whenever one is allowed, else the clip; gives up after 2 000 edges."""

    def walk(self, graph, rng, duration):
        if not duration > 0:
            raise flockkit.errors.ValidationError(f"duration must be > 0; got {duration}")
        node, since, played, edges = 0, math.inf, 0.0, []
        while played < duration:
            if len(edges) > 2000:
                raise flockkit.errors.ValidationError("no walk found within 2 000 edges")
            options = graph.allowed_edges(node, since)
            edge = next((e for e in options if e[0] == "transition"), options[0])
            frames = graph.clips[edge[1]].n_frames - 1 if edge[0] == "clip" else 0
            edges.append(edge)
            played += frames * graph.motion.dt
            since = since + frames if edge[0] == "clip" else 0
            node = graph.edge_target(edge)
        return flockkit.Walk(start=0, edges=edges)


def test_a_walk_that_only_advances_between_blends_is_caught_on_blends_of_zero():
    walk = PrefersTransitions()
    played = flockkit.synthesize(inputs.graph(), walk.walk(inputs.graph(), np.random.default_rng(0), 30.0))
    assert played.duration >= 30.0  # it works while blends keep transitions apart
    with pytest.raises(AssertionError, match="blends of 0 frames"):
        check_named("walk", "check_walk_covers_duration")("prefers-transitions", walk)


def test_checks_for_unknown_kind():
    with pytest.raises(ValueError, match="unknown plugin kind"):
        checks_for("behaviour")


def test_parametrize_ids_name_kind_component_and_check():
    mark = parametrize_with_checks([("behavior", RandomVelocity())])
    ids = [param.id for param in mark.args[1]]
    assert ids[0] == "behavior:RandomVelocity-check_interface"
    assert len(ids) == len(checks_for("behavior"))


@pytest.mark.parametrize(
    "factory, kwargs",
    [
        (fst.configurations, {"min_agents": 0}),
        (fst.configurations, {"min_agents": 5, "max_agents": 2}),
        (fst.configurations, {"dims": 4}),
        (fst.configurations, {"max_coordinate": -1.0}),
        (fst.states, {"max_speed": float("nan")}),
        (fst.states, {"extra": ["not an identifier"]}),
        (fst.motions, {"min_frames": 0}),
        (fst.motions, {"dt": 0}),
        (fst.motions, {"channels": [3]}),
        (fst.com_tracks, {"min_constraints": 3, "max_constraints": 2}),
        (fst.com_tracks, {"max_gap": 0.2}),
    ],
)
def test_strategies_reject_bad_arguments_eagerly(factory, kwargs):
    with pytest.raises(InvalidArgument):
        factory(**kwargs)


@settings(max_examples=30, deadline=None)
@given(st.data())
def test_strategies_respect_their_bounds(data):
    config = data.draw(fst.configurations(min_agents=2, max_agents=4, dims=3, max_coordinate=5.0, max_speed=2.0))
    assert 2 <= config.n_agents <= 4 and config.dims == 3
    assert abs(config.positions).max() <= 5.0 and abs(config.velocities).max() <= 2.0
    state = data.draw(fst.states(max_agents=3, extra=["wander"]))
    assert set(state.extra) == {"wander"} and state.extra["wander"].shape == state.positions.shape
    motion = data.draw(fst.motions(min_frames=2, max_frames=5, dims=2, dt=0.25, channels=["wander"]))
    assert 2 <= motion.n_frames <= 5 and motion.dims == 2 and motion.dt == 0.25
    assert motion.channels["wander"].shape == motion.positions.shape
    track = data.draw(fst.com_tracks(min_constraints=3, max_constraints=4, dims=2, max_coordinate=2.0, max_gap=1.0))
    times = np.array([c.time for c in track])
    assert 3 <= len(track) <= 4 and times[0] == 0 and np.all(np.diff(times) >= 0.5 - 1e-12)
    assert np.all(np.diff(times) <= 1.0 + 1e-12) and all(abs(c.position).max() <= 2.0 for c in track)


class ClaimsReachZero(RandomVelocity):
    """Declares a plausibility reach of 0 frames; its plausibility reads a frame's neighbours."""

    capabilities = flockkit.Capabilities(plausibility_reach=0)


class ReachZero(RandomVelocity):
    """Scores each frame by its own position only: its reach is really 0."""

    capabilities = flockkit.Capabilities(plausibility_reach=0)

    def log_plausibility(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        if not 0 <= start <= stop <= motion.n_frames:
            raise flockkit.errors.ValidationError(f"window {start}:{stop} outside 0..{motion.n_frames}")
        return -0.5 * np.sum(motion.positions[start:stop] ** 2, axis=(1, 2)) * 1e-3


def test_a_declared_reach_of_zero_is_checked_not_skipped():
    assert "check_plausibility_reach" not in skipped_checks("behavior", ClaimsReachZero())
    with pytest.raises(AssertionError, match="check_plausibility_reach failed.*plausibility_reach=0"):
        check_plugin("behavior", ClaimsReachZero(), name="reach-zero")
    position_only = {"check_log_plausibility_at_motion_dt": "it scores positions, not how fast they change"}
    report = check_plugin("behavior", ReachZero(), expected_failed_checks=position_only)
    assert "check_plausibility_reach" in report.passed


@pytest.mark.parametrize("kind, check_name", CASES)
def test_every_failure_ends_with_what_to_fix(kind, check_name):
    with pytest.raises(AssertionError) as info:
        check_plugin(kind, BROKEN_BY_KIND[kind][check_name](), name="broken-component")
    last = str(info.value).splitlines()[-1]
    assert last.startswith("  to fix: ") and len(last) > 40


def test_ids_tell_configurations_apart():
    import flockkit_icp

    mark = parametrize_with_checks(
        [("metric", flockkit_icp.IcpHungarian()), ("metric", flockkit_icp.IcpHungarian(velocity_weight=0.0))]
    )
    ids = {param.id.split("-check_")[0] for param in mark.args[1]}
    assert ids == {"metric:icp-hungarian", "metric:icp-hungarian(velocity_weight=0.0)"}
    named = parametrize_with_checks([("behavior", RandomVelocity())], ids=["mine"])
    assert named.args[1][0].id == "behavior:mine-check_interface"
    with pytest.raises(flockkit.errors.ValidationError, match="ids"):
        parametrize_with_checks([("behavior", RandomVelocity())], ids=["a", "b"])


def test_a_failure_through_pytest_names_check_component_and_fix():
    mark = parametrize_with_checks([("metric", BROKEN_BY_KIND["metric"]["check_symmetric"]())], ids=["lopsided"])
    run = {param.id: param.values[1] for param in mark.args[1]}["metric:lopsided-check_symmetric"]
    with pytest.raises(AssertionError) as info:
        run(BROKEN_BY_KIND["metric"]["check_symmetric"]())
    assert "check_symmetric failed for metric 'lopsided'" in str(info.value) and "to fix:" in str(info.value)


def test_a_root_mean_square_metric_fails_the_mean_of_squares_check():
    from .fakes import RootMeanSquare

    with pytest.raises(AssertionError, match="a root"):
        check_named("metric", "check_distance_is_a_mean_of_squares")("broken", RootMeanSquare())


def test_a_walk_that_loops_for_ever_fails_its_check_within_the_time_limit(monkeypatch):
    from flockkit.testing import walk as walk_checks

    from .fakes import TabuWalk

    monkeypatch.setattr(walk_checks, "WALK_SECONDS", 0.5)
    with pytest.raises(AssertionError, match="ran past 0.5 s"):
        walk_checks.check_walks_a_single_loop("tabu", TabuWalk(patient=True))


def test_a_failure_without_a_message_says_where_it_was_raised():
    from .fakes import RandomVelocity

    class Silent(RandomVelocity):
        def forward(self, initial, steps, rng):
            raise AssertionError  # as a bare assert in a module pytest does not rewrite

    with pytest.raises(AssertionError, match=r"check_forward_shape failed .*: \(no message\) at .*test_kit_fails"):
        check_plugin("behavior", Silent(), name="silent")


def test_a_plausibility_returned_as_a_list_fails_its_check():
    from .fakes import ReturnsAList

    with pytest.raises(AssertionError, match="returned list, not a numpy array"):
        check_named("behavior", "check_log_plausibility_finite")("listy", ReturnsAList())


def test_a_value_flockkit_refuses_gets_that_errors_advice_and_the_plugins_line():
    class LabelsOutOfRange(IcaKmeans):
        def segment(self, motion, rng):
            found = super().segment(motion, rng)
            return flockkit.Segmentation(labels=found.labels + 5, n_parts=found.n_parts)  # the refused value

    with pytest.raises(AssertionError) as info:
        check_plugin("segmenter", LabelsOutOfRange(), name="out-of-range")
    fix = str(info.value).splitlines()[-1]
    assert "Segmentation.labels must lie in" in str(info.value)
    assert "raised ValidationError at test_kit_fails_on_broken_fakes.py:" in fix and "kinds/segmenter/" in fix


def _returns_a_list_pairwise():
    from .fakes import _Wrapped

    class PairwiseList(_Wrapped):
        def pairwise(self, configurations, pairs=None):
            return list(super().pairwise(configurations, pairs))

    return PairwiseList()


def _returns_an_array_bound():
    from .fakes import _Wrapped

    class BoundArray(_Wrapped):
        def lower_bound(self, a, b):
            return np.array([super().lower_bound(a, b)])

    return BoundArray()


def _takes_anything_metric():
    from .fakes import _Wrapped

    class DuckTyped(_Wrapped):
        """Compares anything with positions, refusing only sizes that differ."""

        def compare(self, a, b):
            a, b = (flockkit.Configuration(positions=x.positions, velocities=x.velocities) if hasattr(x, "velocities")
                    else flockkit.Configuration(positions=x, velocities=np.zeros_like(x)) for x in (a, b))  # fmt: skip
            return super().compare(a, b)

    return DuckTyped()


def _takes_any_graph_walk():
    class WalksAMotion(RandomWalk):
        def walk(self, graph, rng, duration):
            if isinstance(graph, flockkit.Motion):
                flockkit.validate.number(duration, "duration", minimum=0, strict=True)
                return flockkit.Walk(start=0, edges=[])
            return super().walk(graph, rng, duration)

    return WalksAMotion()


def _fixed_step_motion():
    class FixedStep(RandomVelocity):
        def forward(self, initial, steps, rng):
            motion = super().forward(initial, steps, rng)
            return flockkit.Motion(positions=motion.positions, dt=0.1)

    return FixedStep(dt=0.05)


@pytest.mark.parametrize(
    "kind, check_name, make, words",
    [
        ("behavior", "check_forward_shape", _fixed_step_motion, "the model's dt is 0.05 s"),
        ("metric", "check_pairwise", _returns_a_list_pairwise, "not a float64 numpy array"),
        ("metric", "check_lower_bound", _returns_an_array_bound, "not a float"),
        ("metric", "check_rejects_mismatched_sizes", _takes_anything_metric, "compare(a, a State)"),
        ("walk", "check_rejects_bad_duration", _takes_any_graph_walk, "a Motion as the graph"),
    ],
)
def test_returned_types_and_refused_arguments_are_checked(kind, check_name, make, words):
    with pytest.raises(AssertionError, match=words.replace("(", r"\(").replace(")", r"\)")):
        check_named(kind, check_name)("broken", make())
