"""Components, not names: declared capabilities, instances everywhere, hooks called through pluggy."""

import ast
import warnings
from pathlib import Path

import numpy as np
import pluggy
import pytest

import flockkit
from flockkit import registry
from flockkit.constrained.sampler import Scorer
from flockkit.errors import FlockkitWarning, PluginError, ValidationError
from flockkit.testing import check_plugin, checks_for, skipped_checks

from ..testing.fakes import (
    ComTerm,
    Declaring,
    GlobalRandomness,
    IcpHungarian,
    Kovar,
    RandomVelocity,
    RandomWalk,
    Retime,
    Walker,
)

ROOT = Path(__file__).resolve().parents[2]
BUILTIN_PLUGINS = "boids,icp,kovar,walks,objectives,proposals,ica,skinparts,windowed,controllers"


pytestmark = pytest.mark.usefixtures("fresh_registry")


class Plugin:
    """A run-time plugin registering one component of a kind."""

    def __init__(self, kind="behavior", name="walker", factory=RandomVelocity):
        self.kind, self.name, self.factory = kind, name, factory

    def _add(self, registry):
        if registry.kind == self.kind:
            registry.add(self.name, self.factory)

    @flockkit.hookimpl
    def flockkit_register_behaviors(self, registry):
        self._add(registry)

    @flockkit.hookimpl
    def flockkit_register_metrics(self, registry):
        self._add(registry)


# -- the declaration --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"dims": (4,)}, "Capabilities.dims"),
        ({"dims": ()}, "Capabilities.dims"),
        ({"dims": (2, 2)}, "Capabilities.dims"),
        ({"guide": 1}, "Capabilities.guide must be True or False"),
        ({"plausibility_reach": -1}, "Capabilities.plausibility_reach"),
        ({"plausibility_reach": 1.5}, "Capabilities.plausibility_reach"),
        ({"coupling": True}, "Capabilities.coupling needs residuals=True"),
    ],
)
def test_bad_declarations_are_refused(fields, message):
    with pytest.raises(ValidationError, match=message):
        flockkit.Capabilities(**fields)


def test_capabilities_reads_the_declaration_or_gives_the_defaults():
    assert flockkit.capabilities(RandomVelocity()) == flockkit.Capabilities()
    assert flockkit.capabilities(Declaring).guide and flockkit.capabilities(Declaring()).plausibility_reach == 1
    assert flockkit.Capabilities(dims=[3, 2]).dims == (2, 3)
    boids = flockkit.get("behavior", "boids")
    assert flockkit.capabilities(boids).declared() == {
        "guide": True,
        "group_guide": True,
        "obstacles": True,
        "plausibility_reach": 2,
        "residuals": True,
        "coupling": True,
        "progress": True,
    }

    class Odd(RandomVelocity):
        capabilities = {"dims": (2,)}

    with pytest.raises(ValidationError, match="Odd.capabilities must be a flockkit.Capabilities; got dict"):
        flockkit.capabilities(Odd())


class GuideWithoutKeyword(RandomVelocity):
    capabilities = flockkit.Capabilities(guide=True)


class PairsWithoutMethod(IcpHungarian):
    capabilities = flockkit.Capabilities(pairs_within=True)

    pairs_within = None


class PairsWithoutRows:
    capabilities = flockkit.Capabilities(pairs_within=True)

    def compare(self, a, b):
        return IcpHungarian().compare(a, b)

    def pairs_within(self, configurations, threshold):
        return np.zeros((0, 2), dtype=int)


class MetricFieldOnABehavior(RandomVelocity):
    capabilities = flockkit.Capabilities(pairwise=True)


class ObstaclesNotTaken(RandomVelocity):
    capabilities = flockkit.Capabilities(obstacles=True)


@pytest.mark.parametrize(
    "kind, factory, problem",
    [
        (
            "behavior",
            GuideWithoutKeyword,
            "forward(initial, steps, rng, guide=): missing keyword parameter 'guide' (capabilities.guide is declared)",
        ),
        (
            "metric",
            PairsWithoutMethod,
            "pairs_within(configurations, threshold, rows=): missing (capabilities.pairs_within is declared)",
        ),
        ("metric", PairsWithoutRows, "missing keyword parameter 'rows'"),
        ("behavior", MetricFieldOnABehavior, "capabilities.pairwise is declared, but only metric components use it"),
        (
            "behavior",
            ObstaclesNotTaken,
            "the factory has no parameter 'obstacles' (capabilities.obstacles is declared)",
        ),
    ],
)
def test_declared_operations_are_checked_at_registration(kind, factory, problem):
    registry.register(Plugin(kind=kind, factory=factory), name="promiser")
    with pytest.raises(PluginError) as info:
        flockkit.available()
    assert problem in str(info.value) and "plugin 'promiser'" in str(info.value)


def test_the_kit_reports_undeclared_operations_as_skipped_with_the_reason():
    report = check_plugin("behavior", RandomVelocity())
    assert set(report.skipped) == {
        "check_guide",
        "check_group_guide",
        "check_progress",
        "check_plausibility_reach",
        "check_residuals",
        "check_coupling",
    }
    assert all("does not declare Capabilities." in reason for reason in report.skipped.values())
    assert not set(report.passed) & set(report.skipped)
    assert {c.__name__ for c in checks_for("behavior", Declaring())} >= {
        "check_guide",
        "check_group_guide",
        "check_progress",
        "check_plausibility_reach",
        "check_residuals",
        "check_coupling",
    }
    assert skipped_checks("metric", IcpHungarian()) == {}


class Planar(RandomVelocity):
    """Breaks on 3D input like a 2D-only model does."""

    def forward(self, initial, steps, rng):
        if initial.dims == 3:
            raise ValueError("operands could not be broadcast together with shapes (8,3) (8,2)")
        return super().forward(initial, steps, rng)


def test_a_failure_a_declaration_explains_says_which_declaration_to_add():
    with pytest.raises(AssertionError) as info:
        check_plugin("behavior", Planar(), name="planar")
    message = str(info.value)
    assert "check_forward_shape failed for behavior 'planar'" in message and "in 3D" in message
    assert "declare it: capabilities = flockkit.Capabilities(dims=(2,))" in message

    class Declared(Planar):
        capabilities = flockkit.Capabilities(dims=(2,))

    assert "check_forward_shape" in check_plugin("behavior", Declared()).passed


def test_expected_failures_are_reported_and_must_still_fail():
    report = check_plugin("behavior", GlobalRandomness(), expected_failed_checks={"check_deterministic": "unseeded"})
    assert report.expected_failures == {"check_deterministic": "unseeded"} and "check_forward_shape" in report.passed
    with pytest.raises(AssertionError, match="check_interface passed .* listed in expected_failed_checks"):
        check_plugin("behavior", RandomVelocity(), expected_failed_checks={"check_interface": "wrongly listed"})


# -- the kit needs no built-in ---------------------------------------------------------------


def test_with_every_builtin_blocked_the_kit_checks_third_party_components_given_their_partners(monkeypatch):
    monkeypatch.setenv("FLOCKKIT_BLOCK_PLUGINS", BUILTIN_PLUGINS + ",vicsek")
    registry.reset()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FlockkitWarning)
        assert not any(flockkit.available().values())
    behavior = RandomVelocity()
    for kind, component, partners in (
        ("metric", IcpHungarian(), None),
        ("builder", Kovar(), {"metric": IcpHungarian()}),
        ("walk", RandomWalk(), None),
        ("proposal", Retime(), {"behavior": behavior}),
        ("objective", ComTerm(), None),
        ("controller", Walker(), None),
    ):
        assert check_plugin(kind, component, partners=partners).passed
    with pytest.raises(ValidationError, match=r"the builder checks need a metric: pass partners=\{'metric': \.\.\.\}"):
        check_plugin("builder", Kovar())


def test_no_component_at_all_is_a_warning_not_silence(monkeypatch):
    monkeypatch.setenv("FLOCKKIT_BLOCK_PLUGINS", BUILTIN_PLUGINS + ",vicsek")
    registry.reset()
    with pytest.warns(FlockkitWarning, match="no flockkit plugin component was found"):
        flockkit.available()


# -- hooks called through pluggy -------------------------------------------------------------


def test_hooks_are_called_through_pluggy_so_wrappers_and_monitoring_see_them():
    seen, wrapped = [], []

    class Wrapper:
        @flockkit.hookimpl(wrapper=True)
        def flockkit_register_behaviors(self, registry):
            wrapped.append("before")
            result = yield
            wrapped.append(sorted(registry._table))
            return result

    registry.register(Wrapper(), name="wrapper")
    registry.register(Plugin(name="first"), name="one")
    registry.register(Plugin(name="second"), name="two")
    manager = registry.plugin_manager()
    undo = manager.add_hookcall_monitoring(lambda name, impls, kwargs: seen.append(name), lambda *args: None)
    try:
        registry._state.components = None
        flockkit.available()
    finally:
        undo()
    assert seen.count("flockkit_register_behaviors") == 1 and "flockkit_register_metrics" in seen
    assert wrapped[0] == "before" and {"boids", "first", "second"} <= set(wrapped[1])
    origin = {c.name: c.plugin for c in registry.describe("behavior")}
    assert origin["first"] == "one" and origin["second"] == "two" and origin["boids"] == "boids"


# -- instances everywhere --------------------------------------------------------------------


def test_resolve_takes_names_and_instances_and_refuses_the_rest():
    boids = flockkit.get("behavior", "boids")
    assert flockkit.resolve("behavior", boids) is boids
    assert flockkit.resolve("behavior", "boids", cohesion_weight=2.0).cohesion_weight == 2.0
    with pytest.raises(ValidationError, match="parameters cohesion_weight are for a behavior made by name"):
        flockkit.resolve("behavior", boids, cohesion_weight=2.0)
    with pytest.raises(ValidationError, match=r"got the class RandomVelocity; pass an instance"):
        flockkit.resolve("behavior", RandomVelocity)
    with pytest.raises(ValidationError, match="does not honour the BehaviorModel interface"):
        flockkit.resolve("behavior", object())


def small_problem(**extra):
    return flockkit.Problem(
        n_agents=6,
        duration=2.0,
        constraints=[
            flockkit.PointConstraint(agent=0, time=0.5, position=[0.0, 0.0], velocity=[1.0, 0.0]),
            flockkit.ComConstraint(time=2.0, position=[2.0, 0.5], velocity=[1.0, 0.0]),
        ],
        **extra,
    )


def test_solve_takes_behavior_parameters_and_instances_of_every_component():
    problem = small_problem()
    by_name = flockkit.solve(problem, behavior_params={"cohesion_weight": 1.0}, iterations=10, seed=1)
    instance = flockkit.get("behavior", "boids", dt=problem.dt, cohesion_weight=1.0)
    moves = [(flockkit.get("proposal", "bump"), 0.6), ("velocity", 0.1), (flockkit.get("proposal", "regenerate"), 0.1)]
    objectives = [flockkit.get("objective", name) for name in ("com", "shape", "flocks")]
    given = flockkit.solve(problem, behavior=instance, proposals=moves, objectives=objectives, iterations=10, seed=1)
    assert given.motion == by_name.motion and given.log_g == by_name.log_g
    assert set(given.acceptance) <= {"Bump", "velocity", "Regenerate"}
    other = flockkit.solve(problem, behavior_params={"cohesion_weight": 6.0}, iterations=10, seed=1)
    assert other.motion != by_name.motion
    with pytest.raises(ValidationError, match="behavior_params dt come from the problem"):
        flockkit.solve(problem, behavior_params={"dt": 0.2}, iterations=1)


def test_solve_refuses_obstacles_for_a_model_that_does_not_declare_them():
    registry.register(Plugin(), name="runtime")
    problem = small_problem(obstacles=[flockkit.Ball(center=[1.0, 3.0], radius=0.5)])
    with pytest.raises(
        ValidationError,
        match=r"behavior walker does not avoid obstacles \(it does not declare Capabilities\(obstacles=True\)\)",
    ):
        flockkit.solve(problem, behavior="walker", iterations=1)


def test_a_runtime_registered_component_gives_the_same_bytes_with_two_workers():
    registry.register(Plugin(factory=Declaring), name="runtime")
    problem = small_problem()
    one = flockkit.solve(problem, behavior="walker", chains=2, iterations=15, seed=4, n_jobs=1)
    two = flockkit.solve(problem, behavior="walker", chains=2, iterations=15, seed=4, n_jobs=2)
    assert [m.positions.tobytes() for m in one.motions] == [m.positions.tobytes() for m in two.motions]


def test_a_runtime_registered_metric_builds_the_same_graph_with_two_workers(tmp_path):
    registry.register(Plugin(kind="metric", name="copied", factory=IcpHungarian), name="runtime")
    recording = flockkit.simulate(n_agents=6, steps=150, seed=2)
    graphs = [flockkit.build_graph(recording, metric="copied", seed=0, n_jobs=jobs) for jobs in (1, 2)]
    for index, graph in enumerate(graphs):
        graph.save(tmp_path / f"{index}.npz")
    assert graphs[0] == graphs[1] and graphs[0].provenance["metric"] == "copied"


def test_simulate_and_build_graph_take_instances():
    model = flockkit.get("behavior", "boids", dt=0.1, cohesion_weight=2.0)
    assert flockkit.simulate(model, n_agents=5, steps=20, seed=1) == flockkit.simulate(
        "boids", n_agents=5, steps=20, seed=1, cohesion_weight=2.0
    )
    with pytest.raises(ValidationError, match="dt is for a behavior made by name"):
        flockkit.simulate(model, n_agents=5, steps=20, dt=0.2)
    recording = flockkit.simulate(n_agents=6, steps=150, seed=2)
    graph = flockkit.build_graph(recording, builder=Kovar(blend_time=1.0), metric=IcpHungarian(), seed=0)
    assert graph.provenance["builder"] == "Kovar" and graph.provenance["builder_params"]["blend_time"] == 1.0
    assert flockkit.walk(graph, strategy=RandomWalk(start=0), duration=5, seed=1).start == 0


# -- declarations read, never guessed ---------------------------------------------------------


class Spy(RandomVelocity):
    """Takes guide and progress keywords but declares nothing: it must never be handed them."""

    handed = []

    def forward(self, initial, steps, rng, *, guide=None, progress=None):
        Spy.handed.append((guide is not None, progress is not None))
        return super().forward(initial, steps, rng)

    def backward(self, final, steps, rng, *, guide=None, progress=None):
        Spy.handed.append((guide is not None, progress is not None))
        return super().backward(final, steps, rng)


def test_undeclared_operations_are_never_used_and_declared_ones_are():
    Spy.handed.clear()
    problem = flockkit.Problem(
        n_agents=4,
        duration=2.0,
        constraints=[flockkit.PointConstraint(agent=0, time=t, position=[t, 0.0]) for t in (0.5, 1.0, 1.5)],
    )
    flockkit.solve(problem, behavior=Spy(), iterations=0, seed=1)
    flockkit.simulate(Spy(), n_agents=4, steps=5, progress=True)
    assert Spy.handed and not any(guide or progress for guide, progress in Spy.handed)
    assert Scorer(problem, Spy(), []).reach is None
    assert Scorer(problem, Declaring(), []).reach == 1


def _string_constants(path):
    return [
        node.value
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.Constant) and isinstance(node.value, str)
    ]


def test_the_core_names_no_builtin_outside_convenience_defaults_and_sniffs_no_signature():
    # the built-in names that are not also ordinary words of the core (com, shape, random, ...)
    builtins = {*flockkit.available("behavior"), *flockkit.available("metric"), *flockkit.available("builder"),
                *flockkit.available("segmenter"), "bump"}  # fmt: skip
    builtins -= {"vicsek"}
    # where defaults are set: the convenience layer, the solver's and the kit's, the command line
    # (its options' defaults), and the crowd file format (its [trajectories] simulate, as simulate's)
    defaults = {"convenience.py", "constrained/sampler.py", "testing/_expect.py", "crowd/file.py"}
    named = {
        str(path.relative_to(ROOT)): sorted(builtins & set(_string_constants(path)))
        for path in (ROOT / "flockkit").rglob("*.py")
        if str(path.relative_to(ROOT / "flockkit")) not in defaults and path.parent.name != "cli"
    }
    assert {path: names for path, names in named.items() if names} == {}
    sniffing = [
        str(path.relative_to(ROOT))
        for path in [*(ROOT / "flockkit").rglob("*.py"), *(ROOT / "plugins").rglob("*.py")]
        if path.name != "registry.py" and "inspect.signature" in path.read_text()
    ]
    assert sniffing == []
    assert not any("args.builder ==" in path.read_text() for path in (ROOT / "flockkit" / "cli").glob("*.py"))
    assert pluggy.HookimplMarker("flockkit")  # hooks are pluggy's own
