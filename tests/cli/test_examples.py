"""Every scene and crowd file in examples/ runs as its header says, and writes what it says.

Each file's header holds the commands that make its inputs and run it, one per line as
``#   flockkit ...``, run from the repository root; and what they write ("8 objects, 180 frames",
"300 agents, 96 frames"). Here they run in a copy of examples/ with the shared data beside it,
as in a checkout, and the outputs are checked against the file and its header.
"""

import json
import math
import shlex
import shutil
import tomllib
from pathlib import Path

import pytest

import flockkit
from flockkit.cli import main

from ..conftest import SHARED_DATA, require_folder

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = sorted([*(ROOT / "examples" / "scenes").glob("*.toml"), *(ROOT / "examples" / "crowds").glob("*.toml")])


def header_commands(text: str) -> list[list[str]]:
    """The commands a header gives, each as argv after `flockkit`."""
    return [shlex.split(line)[2:] for line in text.splitlines() if line.startswith("#   flockkit ")]


def option(argv: list[str], name: str) -> str:
    return argv[argv.index(name) + 1]


def foxes_face_the_wind_upright_at_true_size(animation):
    """scenes/foxes.toml's claims: out of step, every fox turned to face east (the Fox faces -y:
    a quarter turn), standing on the ground about 0.75 m tall."""
    import numpy as np

    assert animation.report["pairs_in_step_after"] == 0.0

    turned = np.stack([np.cos(animation.placement.headings), np.sin(animation.placement.headings)], axis=1)
    np.testing.assert_allclose(turned, [[0.0, 1.0]] * animation.placement.n_objects, atol=1e-9)
    for i, scale in enumerate(animation.placement.scales):
        heights = animation.motions[i].positions[..., 2]
        assert heights.min() > -0.05 * scale and 0.7 < (heights.max() - heights.min()) / scale < 0.85


# what an example's header claims beyond files, objects, agents and frames: file -> check of its output
CLAIMS = {"scenes/foxes.toml": foxes_face_the_wind_upright_at_true_size}


def test_there_are_scene_and_crowd_examples():
    folders = {path.parent.name for path in EXAMPLES}
    assert folders == {"scenes", "crowds"}


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_example_runs_as_its_header_says(example, tmp_path, monkeypatch, capsys):
    text = example.read_text()
    if "../shared/data" in text:
        (tmp_path / "shared").symlink_to(require_folder(SHARED_DATA).parent, target_is_directory=True)
    repo = tmp_path / "repo"
    for folder in ("scenes", "crowds"):  # the files only: inputs left from a run here are made again
        shutil.copytree(ROOT / "examples" / folder, repo / "examples" / folder, ignore=shutil.ignore_patterns("*.npz"))
    monkeypatch.chdir(repo)
    commands = header_commands(text)
    relative = str(example.relative_to(ROOT))
    assert commands and commands[-1][:2] in (["scene", relative], ["crowd", relative]), commands
    for argv in commands:
        code = main(argv)
        out, err = capsys.readouterr()
        assert code == 0, f"flockkit {shlex.join(argv)}: {err}"
    run = commands[-1]
    output = repo / option(run, "-o")
    data = tomllib.loads(text)
    usd, pictures = "--no-usd" not in run, "--no-pictures" not in run
    from PIL import Image
    from pxr import Usd

    if run[0] == "scene":
        objects = sum(entry["count"] for entry in data["templates"])
        first = data["templates"][0]
        template = (flockkit.GraphLayers.load(example.parent.relative_to(ROOT) / first["layers"]).source
                    if "layers" in first else
                    flockkit.MotionGraph.load(example.parent.relative_to(ROOT) / first["graph"]).motion)  # fmt: skip
        frames = math.ceil(data["duration"] / template.dt)
        written = {"scene.npz", *(["scene.usda"] if usd else []), *(["scene.png", "scene.gif"] if pictures else [])}
        assert {p.name for p in output.iterdir()} == written
        animation = flockkit.SceneAnimation.load(output / "scene.npz")
        assert animation.placement.n_objects == objects and animation.n_frames == frames
        assert f"{objects} objects, {frames} frames" in out
        assert f"{objects} objects, {frames} frames" in text  # the header says what it writes
        CLAIMS.get(f"{example.parent.name}/{example.name}", lambda animation: None)(animation)
        if usd:
            stage = Usd.Stage.Open(str(output / "scene.usda"))
            assert len(stage.GetPseudoRoot().GetChild("Scene").GetChildren()) == objects
        if pictures:
            assert 1 < Image.open(output / "scene.gif").n_frames <= min(frames, 150)  # at most 150 drawn
    else:
        summary = json.loads((output / "crowd.json").read_text())
        frames = round(data["seconds"] * data.get("fps", 30))
        sources = data["trajectories"]
        agents = (sources["simulate"]["agents"] if "simulate" in sources else
                  flockkit.Motion.load(example.parent.relative_to(ROOT) / sources["motion"]).n_agents)  # fmt: skip
        recorded = min(data.get("record", 64), agents)
        written = {"crowd.json", *(["crowd.usdc"] if usd else []), *(["crowd.gif"] if pictures else [])}
        assert {p.name for p in output.iterdir()} == written
        assert (summary["agents"], summary["frames"], summary["recorded"]) == (agents, frames, recorded)
        assert summary["streams"] == [stream["name"] for stream in data["streams"]]
        assert summary["stream switches"] > 0 and f"{agents} agents, {frames} frames" in out
        assert f"{agents} agents, {frames} frames" in text
        if usd:
            stage = Usd.Stage.Open(str(output / "crowd.usdc"))
            assert len(stage.GetPseudoRoot().GetChild("Crowd").GetChildren()) == recorded
        if pictures:
            assert Image.open(output / "crowd.gif").n_frames == frames


def test_example_headers_name_commands_that_exist():
    """A header's commands parse (the test above runs them; this one needs no data)."""
    from flockkit.cli import build_parser

    for example in EXAMPLES:
        for argv in header_commands(example.read_text()):
            build_parser().parse_args(argv)
