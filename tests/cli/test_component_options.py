"""Each component a command makes is chosen and configured on the command line: --<option> NAME,
--<option>-param KEY=VALUE, --param for the command's main one; options that need a capability are
refused before anything is made when the component does not declare it."""

import argparse
import re
from pathlib import Path

import numpy as np
import pytest

import flockkit
from flockkit.cli import build_parser, main
from flockkit.cli._options import KINDS_OF_OPTIONS

from ..testing.fakes import RandomVelocity

DOCS = Path(__file__).resolve().parents[2] / "docs" / "cli.md"

# command -> (its main component's option, the kind it names, what --help calls it)
MAIN = {"simulate": ("behavior", "behavior", "behavior"), "build": ("builder", "builder", "builder"),
        "segment": ("segmenter", "segmenter", "segmenter"), "walk": ("strategy", "walk", "walk strategy")}  # fmt: skip


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> bool:
    return len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("components") / "flock.npz"
    flockkit.simulate(n_agents=6, steps=150, seed=4).save(path)
    return path


def subcommands() -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_a_metric_parameter_reaches_the_metric(capsys, tmp_path, recording):
    """--metric-param velocity_weight=0 builds the graph the library builds with that metric, whose
    transition costs differ from the default metric's, and the provenance records it."""
    motion = flockkit.Motion.load(recording)
    code, _, err = run(capsys, "build", recording, "--metric-param", "velocity_weight=0", "--quiet",
                       "-o", tmp_path / "g.npz")  # fmt: skip
    assert code == 0, err
    built = flockkit.MotionGraph.load(tmp_path / "g.npz")
    expected = flockkit.build_graph(motion, metric_params={"velocity_weight": 0})
    default = flockkit.build_graph(motion)
    costs = [t.alignment.distance for t in built.transitions]
    assert costs == [t.alignment.distance for t in expected.transitions]
    assert costs != [t.alignment.distance for t in default.transitions]
    assert built.provenance["metric_params"] == {"velocity_weight": 0}
    assert built.provenance["builder_params"] == {}


def test_param_and_the_main_components_own_option_are_the_same(capsys, tmp_path, recording):
    """--param goes to the main component: the builder of build, the behavior of simulate, the
    strategy of walk; --builder-param and --param together give both."""
    code, _, err = run(capsys, "build", recording, "--param", "blend_time=0.3", "--builder-param", "min_gap=2",
                       "--quiet", "-o", tmp_path / "g.npz")  # fmt: skip
    assert code == 0, err
    graph = flockkit.MotionGraph.load(tmp_path / "g.npz")
    assert graph.provenance["builder_params"] == {"blend_time": 0.3, "min_gap": 2}
    assert graph.provenance["metric_params"] == {}
    code, _, err = run(capsys, "simulate", "--agents", "5", "--steps", "20", "--seed", "1", "--param",
                       "cohesion_weight=2", "--quiet", "-o", tmp_path / "a.npz")  # fmt: skip
    assert code == 0, err
    code, _, err = run(capsys, "simulate", "--agents", "5", "--steps", "20", "--seed", "1", "--behavior-param",
                       "cohesion_weight=2", "--quiet", "-o", tmp_path / "b.npz")  # fmt: skip
    assert code == 0, err
    expected = flockkit.simulate(n_agents=5, steps=20, seed=1, cohesion_weight=2)
    assert flockkit.Motion.load(tmp_path / "a.npz") == expected == flockkit.Motion.load(tmp_path / "b.npz")
    assert expected != flockkit.simulate(n_agents=5, steps=20, seed=1)
    code, _, err = run(capsys, "walk", tmp_path / "g.npz", "--duration", "10", "--seed", "2", "--strategy-param",
                       "start=0", "-o", tmp_path / "w.npz")  # fmt: skip
    assert code == 0, err
    walked = flockkit.walk(graph, duration=10, seed=2, start=0)
    assert walked.start == 0
    assert flockkit.Motion.load(tmp_path / "w.npz") == flockkit.synthesize(graph, walked)


@pytest.mark.parametrize(
    "argv, component, key",
    [
        (["build", "MOTION", "--metric-param", "bogus=1"], "metric 'icp-hungarian'", "'bogus'"),
        (["build", "MOTION", "--param", "bogus=1"], "builder 'kovar'", "'bogus'"),
        (["build", "MOTION", "--builder", "windowed", "--builder-param", "bogus=1"], "builder 'windowed'", "'bogus'"),
        (["simulate", "--agents", "3", "--steps", "3", "--behavior-param", "bogus=1"], "behavior 'boids'", "'bogus'"),
        (["segment", "MOTION", "--segmenter-param", "bogus=1"], "segmenter 'ica-kmeans'", "'bogus'"),
    ],
)
def test_an_unknown_parameter_is_one_line_naming_the_component_and_key(capsys, tmp_path, recording, argv,
                                                                        component, key):  # fmt: skip
    output = tmp_path / "out.npz"
    code, _, err = run(capsys, *[recording if a == "MOTION" else a for a in argv], "-o", output)
    assert code == 1 and one_line(err), err
    assert component in err and key in err and "its parameters are" in err
    assert not output.exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["segment", "MOTION", "--param", "seed=1"], "--param seed: set it with --seed"),
        (["segment", "MOTION", "--segmenter-param", "n_parts=2"], "--segmenter-param n_parts: set it with --parts"),
        (
            ["build", "MOTION", "--builder-param", "metric_params=1"],
            "--builder-param metric_params: set it with --metric-param",
        ),
        (["build", "MOTION", "--param", "n_jobs=2"], "--param n_jobs: set it with --jobs"),
        (["walk", "GRAPH", "--duration", "3", "--param", "region=1"], "--param region: set it with --region"),
        (
            ["simulate", "--agents", "3", "--steps", "3", "--behavior-param", "dt=1"],
            "--behavior-param dt: set it with --dt",
        ),
        (["build", "MOTION", "--metric-param", "x"], "--metric-param expects key=value"),
        (["build", "MOTION", "--segmenter", "ica-kmeans"], "--segmenter, --segmenter-param"),
        (["build", "MOTION", "--layers", "--parts", "P.npz", "--segmenter-param", "n_parts=2"], "--segmenter"),
    ],
)
def test_parameters_the_command_sets_itself_are_refused_naming_the_option(capsys, tmp_path, recording, argv, message):
    graph = tmp_path / "g.npz"
    if "GRAPH" in argv:
        flockkit.build_graph(flockkit.Motion.load(recording)).save(graph)
    argv = [recording if a == "MOTION" else graph if a == "GRAPH" else a for a in argv]
    code, _, err = run(capsys, *argv, "-o", tmp_path / "out.npz")
    assert code == 1 and one_line(err) and message in err, err
    assert not (tmp_path / "out.npz").exists()


class Fenced(RandomVelocity):
    """A behavior that declares it avoids obstacles (and takes them, as that declaration promises)."""

    capabilities = flockkit.Capabilities(obstacles=True)

    def __init__(self, dt=0.1, obstacles=()):
        super().__init__(dt=dt)
        self.obstacles = list(obstacles)


def test_arena_with_a_behavior_lacking_obstacles_names_the_capability(capsys, tmp_path, flockkit_register):
    """--arena and --obstacle need Capabilities(obstacles=True): a behavior without it is refused in
    one line naming the options, the behavior, the capability and those that declare it, before
    the behavior is made; never a TypeError."""
    made = []

    class Drifter(RandomVelocity):
        def __init__(self, dt=0.1):
            made.append(dt)
            super().__init__(dt=dt)

    flockkit_register("behavior", "drifter", Drifter)
    flockkit_register("behavior", "fenced", Fenced)
    output = tmp_path / "out.npz"
    code, _, err = run(capsys, "simulate", "--agents", "3", "--steps", "3", "--behavior", "drifter", "--arena", "5",
                       "-o", output)  # fmt: skip
    assert code == 1 and one_line(err), err
    assert "obstacles (--arena) need a behavior declaring Capabilities(obstacles=True)" in err
    assert "behavior drifter does not declare it" in err
    assert "--behavior (installed: boids, fenced)" in err and "leave out --arena" in err
    assert "unexpected keyword" not in err and "TypeError" not in err
    assert made == [] and not output.exists()
    code, _, err = run(capsys, "simulate", "--agents", "3", "--steps", "3", "--behavior", "drifter", "--obstacle",
                       "ball:1,1,0.5", "--param", "bogus=1", "-o", output)  # fmt: skip
    assert code == 1 and one_line(err) and "obstacles (--obstacle) need" in err and "bogus" not in err, err
    assert made == [] and not output.exists()
    code, _, err = run(capsys, "simulate", "--agents", "3", "--steps", "3", "--behavior", "drifter", "-o", output)
    assert code == 0, err
    assert made == [0.1]
    code, _, err = run(capsys, "simulate", "--agents", "3", "--steps", "3", "--behavior", "fenced", "--arena", "5",
                       "-o", output)  # fmt: skip
    assert code == 0, err


def test_region_with_a_strategy_that_takes_none_names_the_option_and_those_that_do(capsys, tmp_path, recording):
    graph, output = tmp_path / "graph.npz", tmp_path / "walk.npz"
    assert run(capsys, "build", recording, "-o", graph)[0] == 0
    code, _, err = run(capsys, "walk", graph, "--duration", "5", "--region", "box:-50,-50,50,50", "-o", output)
    assert code == 1 and one_line(err), err
    assert "--region: walk 'random' takes no region=" in err and "--strategy (installed: region)" in err, err
    assert not output.exists()
    code, _, err = run(capsys, "walk", graph, "--duration", "5", "--strategy", "region", "--region",
                       "box:-50,-50,50,50", "-o", output)  # fmt: skip
    assert code == 0 and output.exists(), err


@pytest.mark.parametrize("command", sorted(MAIN))
def test_help_names_the_main_component_of_param(capsys, command):
    option, kind, noun = MAIN[command]
    with pytest.raises(SystemExit) as exit:
        main([command, "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert exit.value.code == 0
    assert f"--param KEY=VALUE a parameter of the command's main component, the {noun} (as --{option}-param)" in out
    assert f"any installed {kind}: flockkit plugins --kind {kind}" in out


def test_every_component_option_is_documented():
    """docs/cli.md shows each command's --<component> and --<component>-param options in its usage
    and names the main component of --param for each command."""
    text = DOCS.read_text()
    usage = dict(re.findall(r"^flockkit ([\w-]+) (.*?)(?=^ {4}\S)", text, flags=re.S | re.M))
    for name, parser in subcommands().items():
        if parser.get_default("components") is None:  # a command that makes no component by name
            continue
        for action in parser._actions:
            for option in action.option_strings:
                if option.endswith("-param") or action.dest in KINDS_OF_OPTIONS:
                    assert option in usage[name], f"flockkit {name} {option} is not in docs/cli.md's usage"
    explained = " ".join(text.split())
    for command, (option, _, _) in MAIN.items():
        assert f"the {option} of `{command}`" in explained


def test_build_layers_takes_the_segmenter_and_the_metric(capsys, tmp_path):
    """build --layers takes the segmenter and the metric, with their parameters: the parts' graphs
    record the metric's."""
    rng = np.random.default_rng(0)
    positions = np.cumsum(rng.normal(scale=0.05, size=(120, 6, 2)), axis=0)
    motion = flockkit.Motion(positions=positions, dt=0.1)
    motion.save(tmp_path / "m.npz")
    code, out, err = run(capsys, "build", tmp_path / "m.npz", "--layers", "--segmenter-param", "n_parts=2",
                         "--metric-param", "velocity_weight=0.5", "--seed", "1", "-o", tmp_path / "l.npz")  # fmt: skip
    assert code == 0, err
    layers = flockkit.GraphLayers.load(tmp_path / "l.npz")
    assert layers.n_parts == 2
    assert all(g.provenance["metric_params"] == {"velocity_weight": 0.5} for g in layers.graphs)
