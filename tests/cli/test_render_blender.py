"""`flockkit render --blender` and viz.render_blender: without bpy, one line naming what
to install and nothing written; with a Python that has bpy (FLOCKKIT_BPY_PYTHON), stills and
GIFs of the size asked, showing the agents on the ground, whose frames last the span rendered;
glTF files get the scene's frame range from their keys (Blender's importer leaves 1-250)."""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import flockkit
from flockkit import viz
from flockkit.cli import main
from flockkit.errors import ValidationError

BLENDER_PYTHON = os.environ.get("FLOCKKIT_BPY_PYTHON")  # a Python with Blender's bpy module (pip install bpy)
needs_blender = pytest.mark.skipif(
    not BLENDER_PYTHON, reason="set FLOCKKIT_BPY_PYTHON to a Python with bpy (pip install bpy) to render in Blender"
)


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def motion_file(tmp_path):
    path = tmp_path / "flock.npz"
    flockkit.simulate(n_agents=12, steps=50, seed=1).save(path)  # 5 s
    return path


def test_without_bpy_render_names_what_to_install_and_writes_nothing(capsys, tmp_path, motion_file, monkeypatch):
    import importlib.util

    monkeypatch.delenv("FLOCKKIT_BPY_PYTHON", raising=False)
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "bpy" else real(name, *a))
    code, _, err = run(capsys, "render", str(motion_file), "--blender", "-o", str(tmp_path / "flock.png"))
    assert code == 1 and "FLOCKKIT_BPY_PYTHON" in err and "pip install bpy" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "flock.png").exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["-o", "flock.mp4"], "-o"),
        (["-o", "flock.png", "--time", "soon"], "--time"),
        (["-o", "flock.gif", "--time", "4:2"], "start < end"),
        (["-o", "flock.png", "--size", "wide"], "--size"),
    ],
)
def test_bad_render_requests_are_refused_in_one_line(capsys, tmp_path, motion_file, monkeypatch, argv, message):
    monkeypatch.setenv("FLOCKKIT_BPY_PYTHON", "python3")  # refused before Blender would start
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, "render", str(motion_file), "--blender", *argv)
    assert code == 1 and message in err and len(err.splitlines()) == 1, err
    assert [p.name for p in tmp_path.iterdir()] == ["flock.npz"]


def test_render_blender_refuses_what_blender_does_not_import(tmp_path):
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(ValidationError, match="Motion or one of"):
        viz.render_blender(tmp_path / "notes.txt", tmp_path / "x.png", python="python3")
    with pytest.raises(ValidationError, match="engine"):
        viz.render_blender(tmp_path / "notes.txt", tmp_path / "x.png", engine="povray", python="python3")


def agent_pixels(image) -> np.ndarray:
    """Where a picture shows the agents' orange (render_blender's COLOUR) rather than the ground."""
    rgb = np.asarray(image.convert("RGB")).astype(int)
    return (rgb[..., 0] > rgb[..., 1] + 25) & (rgb[..., 0] > rgb[..., 2] + 50)  # the ground is greener


@needs_blender
def test_render_blender_writes_a_still_of_the_size_asked_showing_the_agents(capsys, tmp_path, motion_file):
    from PIL import Image

    picture = tmp_path / "flock.png"
    code, out, err = run(capsys, "render", str(motion_file), "--blender", "-o", str(picture), "--size", "160x90",
                         "--time", "2.5")  # fmt: skip
    assert code == 0 and f"wrote {picture}" in out, err
    with Image.open(picture) as image:
        assert image.size == (160, 90)
        shown = agent_pixels(image)
    assert 0.005 < shown.mean() < 0.5  # the flock is in the picture, and the camera is not inside it
    rows, columns = np.flatnonzero(shown.any(axis=1)), np.flatnonzero(shown.any(axis=0))
    assert rows.min() > 0 and columns.min() > 0 and rows.max() < 89 and columns.max() < 159  # framed: none cut


@needs_blender
def test_a_blender_gif_lasts_the_span_rendered(tmp_path):
    from PIL import Image

    motion = flockkit.simulate(n_agents=6, steps=50, seed=2)
    path = viz.render_blender(motion, tmp_path / "flock.gif", time=(1.0, 2.0), fps=4, size=(96, 64))
    with Image.open(path) as image:
        assert image.size == (96, 64) and image.n_frames == 5  # 1.0, 1.25, ..., 2.0 s
        durations = []
        for k in range(image.n_frames):
            image.seek(k)
            durations.append(image.info["duration"])
            assert agent_pixels(image).any()
    assert sum(durations) == 1250  # five frames of a quarter second: the span and its last frame


@needs_blender
def test_a_gltf_export_gets_the_scene_range_of_its_keys(tmp_path):
    """Blender's glTF importer keys an animation of 5 s at frames 0 to 120 (24 fps) but leaves the
    scene's range at 1-250; the render script and examples/blender/import_flockkit.py set it to
    the keys' span."""
    from flockkit.viz import render

    flockkit.io.export(flockkit.simulate(n_agents=4, steps=50, seed=3), tmp_path / "flock.glb")
    job = {"file": str(tmp_path / "flock.glb"), "times": [5.0], "duration": 5.0,
           "outputs": [str(tmp_path / "end.png")], "width": 64, "height": 36, "engine": "BLENDER_WORKBENCH",
           "samples": 1, "colour": list(render.COLOUR)}  # fmt: skip
    (tmp_path / "job.json").write_text(json.dumps(job))
    script = Path(render.__file__).with_name("_in_blender.py")
    done = subprocess.run([BLENDER_PYTHON, str(script), str(tmp_path / "job.json")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "frames 0 to 120" in done.stdout and "rendered 1 frames (120 to 120)" in done.stdout
    assert (tmp_path / "end.png").stat().st_size > 0
    example = Path(__file__).resolve().parents[2] / "examples" / "blender" / "import_flockkit.py"
    done = subprocess.run([BLENDER_PYTHON, str(example), str(tmp_path / "flock.glb")], capture_output=True, text=True)
    assert done.returncode == 0 and "scene frames 0 to 120 at 24 fps" in done.stdout, done.stderr[-2000:]


def test_a_blender_that_fails_is_named_and_the_demo_goes_on(tmp_path, monkeypatch):
    """A Python without bpy given as Blender's: render_blender raises a FlockkitError with
    Blender's last lines and writes nothing; the demo's renders report the failure in the
    summary, timed, and the tour goes on."""
    import sys

    from flockkit.cli import demo
    from flockkit.errors import FlockkitError

    motion = flockkit.simulate(n_agents=4, steps=20, seed=1)
    with pytest.raises(FlockkitError, match=r"(?s)exit status 1\): .*No module named .bpy."):
        viz.render_blender(motion, tmp_path / "flock.png", python=sys.executable)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setenv("FLOCKKIT_BPY_PYTHON", sys.executable)
    tour = demo._Tour(tmp_path, progress=False)
    done = demo._renders(tour, motion, {})
    assert list(done) == ["the flock"] and done["the flock"].startswith("failed: Blender")
    assert list(tour.timings) == ["render the flock in Blender"] and tour.written == []
