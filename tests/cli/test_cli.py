import shutil
import subprocess

import pytest

import flockkit
from flockkit.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_plugins_lists_kind_name_plugin_distribution_version(capsys):
    code, out, _ = run(capsys, "plugins")
    assert code == 0
    header, *rows = out.splitlines()
    assert header.split() == ["kind", "name", "plugin", "distribution", "version"]
    assert ["behavior", "boids", "boids", "flockkit", flockkit.__version__] in [row.split() for row in rows]


def test_simulate_writes_motion_and_picture(capsys, tmp_path):
    out_file, picture = tmp_path / "flock.npz", tmp_path / "flock.png"
    code, out, err = run(
        capsys, "simulate", "--agents", "12", "--steps", "30", "--seed", "4", "-o", str(out_file),
        "--picture", str(picture), "--param", "cohesion_weight=2.5",
    )
    assert code == 0, err
    motion = flockkit.Motion.load(out_file)
    assert motion == flockkit.simulate(n_agents=12, steps=30, seed=4, cohesion_weight=2.5)
    assert picture.read_bytes().startswith(b"\x89PNG") and str(picture) in out


def test_check_runs_the_kit(capsys):
    code, out, _ = run(capsys, "check", "behavior", "boids")
    assert code == 0 and "checks passed" in out


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["simulate", "--agents", "0", "--steps", "5", "-o", "{tmp}/a.npz"], "n_agents must be an integer >= 1"),
        (["simulate", "--agents", "3", "--steps", "5", "-o", "{tmp}/a.csv"], "unknown extension '.csv'"),
        (["simulate", "--agents", "3", "--steps", "5", "-o", "{tmp}/missing/a.npz"], "does not exist"),
        (["simulate", "--agents", "3", "--steps", "5", "-o", "{tmp}/a.npz", "--picture", "{tmp}/a.gif"], "'.gif'"),
        (["simulate", "--agents", "3", "--steps", "5", "--behavior", "boidz", "-o", "{tmp}/a.npz"], "Did you mean 'boids'"),
        (["simulate", "--agents", "3", "--steps", "5", "--param", "speed=2", "-o", "{tmp}/a.npz"], "its parameters are"),
        (["check", "behavior", "nothing"], "no behavior named 'nothing'"),
    ],
)
def test_errors_are_one_line_and_nothing_is_written(capsys, tmp_path, argv, expected):
    code, out, err = run(capsys, *[a.format(tmp=tmp_path) for a in argv])
    assert code == 1
    assert err.count("\n") == 1 and expected in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_failing_check_is_one_line(capsys, monkeypatch):
    from flockkit import registry

    from ..testing.fakes import PrefersNoise

    class Plugin:
        @flockkit.hookimpl
        def flockkit_register_behaviors(self, registry):
            registry.add("contrarian", PrefersNoise)

    registry.reset()
    registry.register(Plugin(), name="contrarian-plugin")
    try:
        code, _, err = run(capsys, "check", "behavior", "contrarian")
    finally:
        registry.reset()
    assert code == 1 and err.count("\n") == 1 and "check_log_plausibility_prefers_forward" in err


def test_console_script_is_installed():
    exe = shutil.which("flockkit")
    assert exe is not None
    result = subprocess.run([exe, "--version"], capture_output=True, text=True)
    assert result.returncode == 0 and flockkit.__version__ in result.stdout
    result = subprocess.run([exe, "simulate"], capture_output=True, text=True)
    assert result.returncode == 2 and "required" in result.stderr
