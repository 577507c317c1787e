"""Every case the hardening review found, replayed: a named flockkit error (or a result), never a
raw exception, a traceback or a hang; and nothing written where the command failed."""

import pytest

import flockkit
from flockkit import io as fio

from . import cases
from .harness import cli_outcome, outcome


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("robustness")


def _library_cases():
    return [name for name, _ in cases.library(_scratch())]


def _cli_cases():
    return [name for name, _ in cases.cli(_scratch())]


def _scratch():
    import tempfile
    from pathlib import Path

    return Path(tempfile.mkdtemp(prefix="flockkit-robustness-"))


@pytest.fixture(scope="module")
def library_cases(folder):
    return dict(cases.library(folder))


@pytest.fixture(scope="module")
def cli_cases(folder):
    return dict(cases.cli(folder))


LIBRARY = _library_cases()
CLI = _cli_cases()


@pytest.mark.parametrize("name", LIBRARY)
def test_library_case_gets_a_named_error(name, library_cases):
    kind, what = outcome(library_cases[name])
    assert kind == "named", f"{name}: {kind}: {what}"


@pytest.mark.parametrize("name", CLI)
def test_cli_case_is_one_line_and_a_non_zero_exit(name, cli_cases, folder):
    before = {p.name for p in folder.iterdir()}
    kind, what = cli_outcome(cli_cases[name])
    assert kind == "named", f"{name}: {kind}: {what}"
    left = {p.name for p in folder.iterdir()} - before
    assert not [n for n in left if n.startswith(".")], f"{name} left temporary files: {left}"


def test_an_infeasible_scenario_exits_3_naming_the_worst_constraint(cli_cases):
    kind, line = cli_outcome(cli_cases["solve an infeasible scenario"])
    assert kind == "named" and "constraint(s) not met; the worst is constraints[" in line


def test_a_bom_headerless_csv_keeps_its_first_row(folder):
    motion = fio.read_long(cases.bom_table(folder), fps=10)
    assert motion.n_frames == 3 and motion.positions[0, 0, 0] == 1.0


def test_messages_name_the_field_or_option(library_cases, cli_cases):
    assert "seed" in outcome(library_cases["simulate seed -1"])[1]
    assert "dt" in outcome(library_cases["simulate dt 1e300"])[1]
    assert "needs" in outcome(library_cases["walk 1e9 s"])[1] and "available" in outcome(library_cases["walk 1e9 s"])[1]
    assert "set it with --dt" in cli_outcome(cli_cases["simulate --param dt"])[1]
    assert "/proc/g.npz" in cli_outcome(cli_cases["build -o /proc/g.npz"])[1]
    assert "not a regular file" in cli_outcome(cli_cases["info /dev/null"])[1]


def test_a_plugin_that_exits_at_import_is_named(tmp_path, monkeypatch, fresh_registry):
    from flockkit import registry

    dist = tmp_path / "exiting-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: exiting\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[flockkit]\nexiting = exiting_plugin\n")
    (tmp_path / "exiting_plugin.py").write_text("import sys\nsys.exit(0)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.reset()
    kind, what = outcome(flockkit.available)
    assert kind == "named" and "plugin 'exiting'" in what and "SystemExit" in what


def test_two_distributions_with_one_plugin_name_are_both_named(tmp_path, monkeypatch, fresh_registry):
    from flockkit import registry

    for letter in "ab":
        dist = tmp_path / f"twin_{letter}-0.1.dist-info"
        dist.mkdir()
        (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: twin-{letter}\nVersion: 0.1\n")
        (dist / "entry_points.txt").write_text(f"[flockkit]\ntwin = twin_{letter}\n")
        (tmp_path / f"twin_{letter}.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.reset()
    kind, what = outcome(flockkit.available)
    assert kind == "named" and "twin-a" in what and "twin-b" in what


def test_a_factory_that_raises_is_named_with_its_plugin(fresh_registry):
    from flockkit import registry

    def broken(**params):
        raise RuntimeError("no")

    class Plugin:
        @flockkit.hookimpl
        def flockkit_register_behaviors(self, registry):
            registry.add("broken", broken)

    registry.register(Plugin(), name="breaker")
    kind, what = outcome(lambda: flockkit.get("behavior", "broken"))
    assert kind == "named" and "plugin 'breaker'" in what and "RuntimeError: no" in what
