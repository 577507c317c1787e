"""flockkit's pytest plugin, as a plugin author's test suite meets it (through pytester)."""

import flockkit
from flockkit.testing import checks_for

pytest_plugins = ["pytester"]

DRIFT = '''
import numpy as np
import flockkit


class Drift:
    """Agents keep their velocity."""

    def __init__(self, dt=0.1):
        self.dt = dt

    def forward(self, initial, steps, rng):
        t = np.arange(steps + 1)[:, None, None] * self.dt
        return flockkit.Motion(positions=initial.positions + t * initial.velocities, dt=self.dt)

    def backward(self, final, steps, rng):
        t = np.arange(-steps, 1)[:, None, None] * self.dt
        return flockkit.Motion(positions=final.positions + t * final.velocities, dt=self.dt)

    def log_plausibility(self, motion, start=0, stop=None):
        stop = motion.n_frames if stop is None else stop
        return np.zeros(stop - start)
'''


def test_register_fixture_lasts_one_test(pytester):
    pytester.makepyfile(
        DRIFT
        + """

def test_registered(flockkit_register):
    flockkit_register("behavior", "drift", Drift, description="constant velocity")
    assert isinstance(flockkit.get("behavior", "drift"), Drift)


def test_forgotten_after():
    assert "drift" not in flockkit.available("behavior")
    assert "boids" in flockkit.available("behavior")
"""
    )
    pytester.runpytest_subprocess("-p", "no:cacheprovider").assert_outcomes(passed=2)


def test_kit_inputs_are_fixtures(pytester):
    pytester.makepyfile(
        """
import flockkit

def test_inputs(flockkit_recording, flockkit_graph, flockkit_parts, flockkit_walker):
    assert flockkit_recording.n_agents == 6 and len(flockkit_graph.transitions) > 0
    motion, truth = flockkit_parts
    assert motion.n_agents == len(truth) and flockkit_walker.skeleton.n_joints == 11

def test_degenerate(flockkit_degenerate_configurations):
    labels = [label for label, _ in flockkit_degenerate_configurations]
    assert any("square" in label for label in labels) and any("one agent" in label for label in labels)
"""
    )
    pytester.runpytest_subprocess("-p", "no:cacheprovider").assert_outcomes(passed=3)


def test_kit_option_checks_every_installed_component_of_a_kind(pytester):
    result = pytester.runpytest_subprocess("--flockkit-kit=metric", "-p", "no:cacheprovider", "-v")
    outcomes = result.parseoutcomes()
    assert outcomes.get("failed", 0) == 0 and outcomes["passed"] >= 14
    result.stdout.fnmatch_lines(["*kit:metric:icp-hungarian-check_symmetric PASSED*"])


def test_kit_option_fails_a_broken_installed_component_with_the_fix(pytester):
    pytester.makeconftest(
        '''
import numpy as np
import flockkit
from flockkit import registry


class Lopsided:
    """The built-in metric, counting distances three times over one way round."""

    capabilities = flockkit.Capabilities()

    def __init__(self):
        self.inner = flockkit.get("metric", "icp-hungarian")

    def compare(self, a, b):
        found = self.inner.compare(a, b)
        scale = 3.0 if a.center_of_mass()[0] < b.center_of_mass()[0] else 1.0
        return flockkit.Alignment(distance=found.distance * scale, assignment=found.assignment,
                                  rotation=found.rotation, translation=found.translation)


class Plugin:
    @flockkit.hookimpl
    def flockkit_register_metrics(registry):
        registry.add("lopsided", Lopsided)


registry.register(Plugin, "lopsided")
'''
    )
    result = pytester.runpytest_subprocess("--flockkit-kit=metric", "-p", "no:cacheprovider")
    outcomes = result.parseoutcomes()
    assert outcomes["passed"] + outcomes["failed"] + outcomes["skipped"] == 2 * len(checks_for("metric"))
    result.stdout.fnmatch_lines(["*check_symmetric failed for metric 'lopsided'*", "*to fix:*"])
    assert "FAILED ::kit:metric:lopsided-check_symmetric" in result.stdout.str()
    assert "FAILED ::kit:metric:icp-hungarian" not in result.stdout.str()


def test_kit_option_refuses_an_unknown_kind(pytester):
    result = pytester.runpytest_subprocess("--flockkit-kit=metrc", "-p", "no:cacheprovider")
    assert result.ret != 0
    result.stderr.fnmatch_lines(["*unknown kind 'metrc'*"])


def test_kit_from_limits_the_kit_to_one_distribution(pytester):
    ours = {found.distribution for found in flockkit.registry.describe("metric")} - {None}
    assert ours, "the built-in metric comes from an installed distribution"
    result = pytester.runpytest_subprocess(f"--flockkit-kit-from={ours.pop().upper()}", "-p", "no:cacheprovider", "-v")
    outcomes = result.parseoutcomes()
    assert outcomes.get("failed", 0) == 0 and outcomes["passed"] >= 14
    result.stdout.fnmatch_lines(["*kit:metric:icp-hungarian-check_symmetric PASSED*"])
    assert "kit:behavior:boids" in result.stdout.str()


def test_kit_from_refuses_a_distribution_that_registers_nothing(pytester):
    result = pytester.runpytest_subprocess("--flockkit-kit-from=numpy", "-p", "no:cacheprovider")
    assert result.ret != 0
    result.stderr.fnmatch_lines(["*no installed distribution 'numpy' registers a flockkit component*"])
