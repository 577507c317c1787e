"""flockkit new-plugin: for every kind, the distribution it writes installs (for real, into a fresh
virtual environment), is found through its entry point there and passes its own tests unchanged;
and every refusal is one line."""

import os
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from flockkit import cli
from flockkit.kinds import KINDS
from flockkit.testing import check_plugin
from flockkit.testing.template import write_plugin

# The most one step (an install, one distribution's tests) may take: a hung step fails the test
# instead of stopping the suite. The eight distributions take about a minute together.
STEP_TIMEOUT = 300


def _run(command, **options) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in command], capture_output=True, text=True, timeout=STEP_TIMEOUT, **options)


def _builds_wheels(python) -> bool:
    """Whether `python` can build a wheel without build isolation: setuptools 70.1 and later
    build one themselves, older ones with the wheel package's bdist_wheel."""
    if _run([python, "-c", "import setuptools.command.bdist_wheel"]).returncode == 0:
        return True
    return _run([python, "-c", "import setuptools, wheel.bdist_wheel"]).returncode == 0


@pytest.fixture(scope="session")
def fresh_python(tmp_path_factory) -> Path:
    """The interpreter of a fresh virtual environment, made once per session: it installs into
    its own site-packages but sees this environment's packages (flockkit, its plugins, pytest,
    hypothesis, pip, setuptools) through a .pth file, so the distributions install from their
    folders alone (``--no-index --no-build-isolation``).

    It is made without pip (``--without-pip``): this environment's pip, seen through the .pth
    file, installs into it, and an ensurepip of an older Python would bring its own setuptools.
    Where this environment's setuptools cannot build wheels without build isolation (before 70.1,
    without the wheel package), a newer one is installed into the fresh environment, once, from
    pip's configured index (the test extra asks for setuptools >= 70.1, so that is rare)."""
    root = tmp_path_factory.mktemp("venv")
    made = _run([sys.executable, "-m", "venv", "--without-pip", root])
    assert made.returncode == 0, made.stderr
    python = root / "bin" / "python"
    purelib = _run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip()
    stdlib = {sysconfig.get_paths()[key] for key in ("stdlib", "platstdlib")}
    sites = [d for d in site.getsitepackages() if os.path.isdir(d)]
    paths = [  # the repository's paths and the like, as this interpreter sees them
        p for p in sys.path if p and os.path.isdir(p) and p not in sites and not any(p.startswith(s) for s in stdlib)
    ]
    # site.addsitedir also runs those folders' own .pth files (editable installs' finders)
    lines = [f"import site; site.addsitedir({d!r})" for d in sites] + paths
    (Path(purelib) / "_parent_environment.pth").write_text("\n".join(lines) + "\n")
    if _run([python, "-m", "pip", "--version"]).returncode != 0:
        ensured = _run([python, "-m", "ensurepip", "--default-pip"])
        assert ensured.returncode == 0, ensured.stderr
    if not _builds_wheels(python):
        fetched = _run([python, "-m", "pip", "install", "-q", "--disable-pip-version-check", "setuptools>=70.1"])
        assert fetched.returncode == 0 and _builds_wheels(python), (
            "setuptools here cannot build wheels without build isolation (it predates 70.1 and the wheel "
            f"package is missing; the test extra asks for a newer one), nor could pip install one: "
            f"{fetched.stderr.strip()[-300:]}"
        )
    return python


# what the fresh environment runs to find an installed plugin: where its module lives, and the
# `flockkit plugins` table
PROBE = """
import sys
import flockkit
from flockkit.cli import main

kind, name = sys.argv[1:]
component = flockkit.get(kind, name)
print(sys.modules[type(component).__module__].__file__)
sys.exit(main(["plugins", "--kind", kind]))
"""


INSTALL = 'pip install -e ".[test]"'


@pytest.mark.parametrize("kind", list(KINDS))
def test_the_distribution_installs_and_passes_its_own_tests(kind, fresh_python, tmp_path):
    name = f"made-{kind}"  # one name per kind: every distribution ends up in the one environment
    folder = write_plugin(kind, name, tmp_path / f"flockkit-{name}")
    pip = [fresh_python, "-m", "pip", "install", "-q", "--disable-pip-version-check"]
    installed = _run([*pip, "--no-deps", "--no-build-isolation", "--no-index", folder])
    assert installed.returncode == 0, installed.stdout[-2000:] + installed.stderr[-3000:]

    # from another folder, so that the installed package is imported, not the source beside the tests
    work = tmp_path / "elsewhere"
    work.mkdir()
    tests = _run([fresh_python, "-m", "pytest", folder / "tests", "-q", "-p", "no:cacheprovider"], cwd=work)
    assert tests.returncode == 0, tests.stdout[-4000:] + tests.stderr[-2000:]
    assert " passed" in tests.stdout and " failed" not in tests.stdout

    probe = _run([fresh_python, "-c", PROBE, kind, name], cwd=work)
    assert probe.returncode == 0, probe.stderr[-3000:]
    module, header, *rows = probe.stdout.splitlines()
    assert Path(module).is_relative_to(fresh_python.parent.parent), f"{module} is not the installed copy"
    assert header.split() == ["kind", "name", "plugin", "distribution", "version"]
    assert [kind, name, name, f"flockkit-{name}", "0.1.0"] in [row.split() for row in rows]


@pytest.mark.parametrize("kind", list(KINDS))
def test_each_component_passes_the_kit_where_it_is_written(kind, tmp_path, monkeypatch):
    """The same check without installing: quick, and where no environment can be made."""
    name = f"kit-{kind}"
    folder = write_plugin(kind, name, tmp_path / "plugin")
    monkeypatch.syspath_prepend(str(folder))
    module = __import__(f"flockkit_kit_{kind}")
    component = getattr(module, f"Kit{kind.capitalize()}")()
    report = check_plugin(kind, component)
    assert report.passed[0] == "check_interface"


def test_the_sources_pass_ruff_as_written(tmp_path):
    """Generated code is lint-clean and formatted under its own pyproject's ruff settings, with
    flockkit a third-party package and the plugin's own package first-party."""
    pytest.importorskip("ruff")
    for kind in KINDS:
        folder = write_plugin(kind, f"tidy-{kind}", tmp_path / kind)
        for command in (["check", "--select", "E,W,F,I,B,C4,UP", "."], ["format", "--check", "."]):
            done = _run([sys.executable, "-m", "ruff", *command], cwd=folder)
            assert done.returncode == 0, f"{kind}: {done.stdout}{done.stderr}"


def test_the_distribution_has_its_parts(tmp_path):
    folder = write_plugin("segmenter", "patches", tmp_path / "out")
    files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
    assert files == [
        "README.md",
        "flockkit_patches/__init__.py",
        "flockkit_patches/segmenter.py",
        "pyproject.toml",
        "tests/test_conformance.py",
        "tests/test_properties.py",
    ]
    pyproject = (folder / "pyproject.toml").read_text()
    assert '[project.entry-points.flockkit]\npatches = "flockkit_patches"' in pyproject
    assert 'dependencies = ["flockkit"]' in pyproject
    readme = (folder / "README.md").read_text()
    assert INSTALL in readme and "pytest" in readme and "## What to change" in readme
    for source in folder.rglob("*.py"):  # public API only: no built-in plugin package
        text = source.read_text()
        assert "flockkit_" not in text.replace("flockkit_patches", "").replace("flockkit_register_", ""), source
    assert "flockkit.testing" not in (folder / "flockkit_patches" / "segmenter.py").read_text()


# -- the command ---------------------------------------------------------------------------------


@pytest.fixture
def command(capsys):
    """Run ``flockkit new-plugin ...``: (exit status, stdout, stderr)."""

    def run(*argv):
        code = cli.main(["new-plugin", *map(str, argv)])
        out, err = capsys.readouterr()
        return code, out, err

    return run


def test_the_command_is_listed(capsys):
    with pytest.raises(SystemExit):
        cli.main(["--help"])
    assert "new-plugin" in capsys.readouterr().out


def test_the_command_writes_the_folder_named_after_the_plugin(command, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = command("walk", "wander")
    assert code == 0, err
    assert (tmp_path / "flockkit-wander" / "flockkit_wander" / "walk.py").is_file()
    assert "flockkit-wander" in out
    # one way to install a new plugin: what the command prints, the README it writes and the docs say
    assert INSTALL in out and INSTALL in (tmp_path / "flockkit-wander" / "README.md").read_text()
    assert INSTALL in (Path(__file__).parents[2] / "docs" / "plugins.md").read_text()
    code, _, err = command("objective", "spacing", tmp_path / "deeper" / "spacing")
    assert code == 0, err
    assert (tmp_path / "deeper" / "spacing" / "pyproject.toml").is_file()
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = command("controller", "sway", empty)  # an empty folder is filled
    assert code == 0, err
    assert (empty / "README.md").is_file()


def _one_line_error(code, err, *words):
    assert code == 1
    assert len(err.splitlines()) == 1, err
    assert err.startswith("flockkit new-plugin: error: ")
    for word in words:
        assert word in err


def test_an_unknown_kind_is_one_line(command, tmp_path):
    code, _, err = command("flavour", "spread", tmp_path / "out")
    _one_line_error(code, err, "kind must be one of behavior, metric", "'flavour'")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", ["Spread", "9lives", "my--walk", "my walk", "spread-", "flock.kit", ""])
def test_a_bad_name_is_one_line(command, tmp_path, name):
    code, _, err = command("metric", name, tmp_path / "out")
    _one_line_error(code, err, "name must be lower-case letters and digits")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("kind, name", [("behavior", "boids"), ("walk", "random"), ("metric", "icp")])
def test_a_name_already_installed_is_one_line(command, tmp_path, kind, name):
    code, _, err = command(kind, name, tmp_path / "out")
    _one_line_error(code, err, f"name {name!r} is taken")


def test_an_existing_folder_with_files_is_left_alone(command, tmp_path):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("keep me")
    code, _, err = command("segmenter", "patches", folder)
    _one_line_error(code, err, str(folder), "not empty")
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]
    (tmp_path / "a-file").write_text("")
    code, _, err = command("segmenter", "patches", tmp_path / "a-file")
    _one_line_error(code, err, "not a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file", "mine"]  # no temporary folder left


def test_a_failed_write_leaves_nothing(tmp_path, monkeypatch):
    written = []

    def fail_on_the_third(self, text, encoding=None):
        written.append(self)
        if len(written) == 3:
            raise OSError(28, "No space left on device")
        return self.open("w", encoding=encoding).write(text)

    monkeypatch.setattr(Path, "write_text", fail_on_the_third)
    with pytest.raises(OSError, match="No space left on device"):
        write_plugin("proposal", "nudge", tmp_path / "flockkit-nudge")
    assert list(tmp_path.iterdir()) == []
