import ast
import importlib.metadata
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import flockkit
from flockkit import registry
from flockkit.errors import FlockkitError, PluginError, UnknownPluginError, ValidationError

from ..testing.fakes import RandomVelocity

ROOT = Path(__file__).resolve().parents[2]


pytestmark = pytest.mark.usefixtures("fresh_registry")


class Plugin:
    """A run-time plugin registering one behavior with a given name and factory."""

    def __init__(self, name="walker", factory=RandomVelocity):
        self.name, self.factory = name, factory

    @flockkit.hookimpl
    def flockkit_register_behaviors(self, registry):
        registry.add(self.name, self.factory, description="test model")


def test_builtins_come_from_entry_points():
    points = {ep.name: ep.value for ep in importlib.metadata.entry_points(group="flockkit")}
    assert points.get("boids") == "flockkit_boids"
    listed = {(c.kind, c.name): c for c in registry.describe()}
    boids = listed[("behavior", "boids")]
    assert boids.plugin == "boids" and boids.distribution == "flockkit" and boids.version == flockkit.__version__


def test_available_and_get():
    assert "boids" in flockkit.available("behavior")
    everything = flockkit.available()
    assert set(everything) == {
        "behavior",
        "metric",
        "builder",
        "walk",
        "proposal",
        "objective",
        "segmenter",
        "controller",
    }
    model = flockkit.get("behavior", "boids", cohesion_weight=2.0)
    assert model.cohesion_weight == 2.0


def test_unknown_names_list_what_is_installed_and_suggest():
    with pytest.raises(UnknownPluginError) as info:
        flockkit.get("behavior", "boid")
    message = str(info.value)
    assert "'boid'" in message and "installed behaviors: boids" in message and "Did you mean 'boids'" in message
    assert isinstance(info.value, KeyError) and isinstance(info.value, FlockkitError)
    with pytest.raises(KeyError, match="Did you mean 'behavior'"):
        flockkit.available("behaviour")


def test_bad_parameters_name_the_component_and_its_parameters():
    with pytest.raises(ValidationError) as info:
        flockkit.get("behavior", "boids", cohesion=2.0)
    assert "behavior 'boids'" in str(info.value) and "cohesion_weight" in str(info.value)


def test_runtime_plugin_is_found_and_reset_forgets_it():
    registry.register(Plugin(), name="test-plugin")
    assert "walker" in flockkit.available("behavior")
    assert isinstance(flockkit.get("behavior", "walker"), RandomVelocity)
    registry.reset()
    assert "walker" not in flockkit.available("behavior")


def test_duplicate_names_name_both_plugins():
    registry.register(Plugin(name="boids"), name="impostor")
    with pytest.raises(PluginError) as info:
        flockkit.available()
    message = str(info.value)
    assert "behavior 'boids' is registered twice" in message
    assert "distribution flockkit" in message and "'impostor'" in message


def test_bad_component_names_are_refused():
    registry.register(Plugin(name="Bad Name"), name="shouty")
    with pytest.raises(PluginError, match="'shouty'.*'Bad Name'"):
        flockkit.available()


class WrongSignature(RandomVelocity):
    def forward(self, initial, count, generator):
        return super().forward(initial, count, generator)


class NoBackward:
    forward = RandomVelocity.forward
    log_plausibility = RandomVelocity.log_plausibility


class NoDefault(RandomVelocity):
    def log_plausibility(self, motion, start, stop):
        return super().log_plausibility(motion, start, stop)


@pytest.mark.parametrize(
    "factory, problem",
    [
        (WrongSignature, "forward(initial, steps, rng): parameter 2 is named 'count'; expected 'steps'"),
        (NoBackward, "backward(final, steps, rng): missing"),
        (NoDefault, "parameter 'start' needs a default"),
    ],
)
def test_wrong_signatures_are_refused_at_registration(factory, problem):
    registry.register(Plugin(factory=factory), name="sloppy")
    with pytest.raises(PluginError) as info:
        flockkit.available()
    message = str(info.value)
    assert "plugin 'sloppy'" in message and "behavior 'walker'" in message and "BehaviorModel" in message
    assert problem in message and "\n" in message
    assert "FLOCKKIT_BLOCK_PLUGINS=sloppy" in message


def test_a_factory_function_returning_a_bad_instance_fails_at_get():
    registry.register(Plugin(factory=lambda: NoBackward()), name="lazy")
    assert "walker" in flockkit.available("behavior")
    with pytest.raises(PluginError, match="backward"):
        flockkit.get("behavior", "walker")


def test_misspelled_hook_fails_loudly():
    class Misspelled:
        @flockkit.hookimpl
        def flockkit_register_behavior(self, registry):  # missing the final s
            pass

    registry.register(Misspelled(), name="typo")
    with pytest.raises(PluginError, match="'typo'.*does not define"):
        flockkit.available()


def test_failing_hook_names_the_plugin():
    class Crashes:
        @flockkit.hookimpl
        def flockkit_register_behaviors(self, registry):
            raise RuntimeError("boom")

    registry.register(Crashes(), name="crashy")
    with pytest.raises(PluginError, match="'crashy' failed in flockkit_register_behaviors"):
        flockkit.available()


def test_block_plugins_by_name(monkeypatch):
    monkeypatch.setenv("FLOCKKIT_BLOCK_PLUGINS", " boids ,other")
    registry.reset()
    assert "boids" not in flockkit.available("behavior")
    registry.register(Plugin(), name="other")
    assert "walker" not in flockkit.available("behavior")


def test_manager_is_built_lazily():
    code = "import flockkit, flockkit.registry as r; print(r._state.manager is None)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True"


def test_core_never_imports_plugins():
    offenders = []
    for path in (ROOT / "flockkit").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            offenders += [f"{path.name}: {name}" for name in names if name.split(".")[0].startswith("flockkit_")]
    assert offenders == []


def test_plugins_use_only_the_public_api():
    private = []
    for path in (ROOT / "plugins").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("flockkit."):
                if any(part.startswith("_") for part in node.module.split(".")):
                    private.append(f"{path.name}: {node.module}")
    assert private == []


def test_entry_point_that_fails_to_import_is_reported(tmp_path, monkeypatch):
    dist = tmp_path / "broken_plugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[flockkit]\nbroken = no_such_module_anywhere\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.reset()
    with pytest.raises(PluginError) as info:
        flockkit.available()
    message = str(info.value)
    assert "plugin 'broken'" in message and "broken-plugin 0.1" in message and "ModuleNotFoundError" in message
    monkeypatch.setenv("FLOCKKIT_BLOCK_PLUGINS", "broken")
    registry.reset()
    assert "boids" in flockkit.available("behavior")


def test_plain_install_finds_every_builtin(tmp_path):
    """A non-editable install (a wheel, as `pip install .` builds) registers the built-ins."""
    wheel_dir, target = tmp_path / "wheel", tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheel_dir), str(ROOT)],
        check=True,
    )
    wheel = next(wheel_dir.glob("flockkit-*.whl"))
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)], check=True
    )
    code = textwrap.dedent(
        """
        import sys, flockkit
        assert flockkit.__file__.startswith(sys.argv[1]), flockkit.__file__
        print(flockkit.available("behavior"))
        """
    )
    env = {"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, "-c", code, str(target)], capture_output=True, text=True, env=env, cwd=tmp_path
    )
    assert out.returncode == 0, out.stderr
    assert "'boids'" in out.stdout
