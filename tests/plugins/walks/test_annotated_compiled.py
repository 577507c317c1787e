"""The annotated walk's compiled loops (first pass and replacement searches on graphs that do not
turn) give the very walks of its Python reference (annotated._COMPILED = False): the same edges,
energies and random stream afterwards, on a looping short cycle with phase shifts, a recording of
plants, and a turning graph (which the reference walks either way), with and without walks to
avoid; and a scene of duplicates, de-synchronised, is the same scene."""

import warnings

import numpy as np
import pytest

import flockkit
from flockkit.testing import inputs


def _cycle():
    """A 30-frame flapping cycle, looped with phase shifts by the windowed builder."""
    phase = 2 * np.pi * np.arange(30)[:, None] / 30
    s = np.linspace(0.2, 1.0, 5)[None, :]
    motion = flockkit.Motion(positions=np.stack(np.broadcast_arrays(s, 0 * s, 0.4 * s * np.sin(phase + s)), axis=2),
                             dt=1 / 30)  # fmt: skip
    features = flockkit.Features.from_keyframes([[0, [0.3, 0]], [0.5, [0.6, 0.1]], [0.9, [0.3, 0]]],
                                                n_frames=30, dt=1 / 30)  # fmt: skip
    return flockkit.build_graph(motion, builder="windowed"), features


def _source(name):
    if name == "cycle":
        return _cycle()
    if name == "plants":
        motion, _, features = inputs.plants(dt=1 / 30, seconds=24.0, points=40, rates=(1.5, 3.0))
        return flockkit.build_graph(motion, builder="windowed"), features
    return inputs.graph(), None  # transitions turn the group: the reference walks it


def _walks(monkeypatch, compiled, graph, seeds, duration, **params):
    from flockkit_walks import annotated

    monkeypatch.setattr(annotated, "_COMPILED", compiled)
    strategy = flockkit.get("walk", "annotated", **params)
    made = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        walk = strategy.walk(graph, rng, duration)
        made.append((walk, strategy.energy(graph, walk, duration), rng.random()))
    return made


def test_the_compiled_sum_is_numpys_pairwise_sum():
    from flockkit_walks._kernels import _pairwise

    rng = np.random.default_rng(0)
    for n in [*range(300), 1000, 1031, 3600, 20011]:
        a = rng.random(n + 5) * 10 ** rng.uniform(-4, 4, n + 5)
        assert _pairwise(a, n) == a[:n].sum()  # bit for bit: a plain running sum differs


@pytest.mark.parametrize("avoiding", [False, True])
@pytest.mark.parametrize("source", ["cycle", "plants", "turning"])
def test_compiled_walks_are_the_reference_walks(monkeypatch, source, avoiding):
    from flockkit_walks import annotated

    graph, features = _source(source)
    if source == "cycle":
        assert graph.period == 30 and np.any(graph.shifts)
    duration = 20.0 if source != "turning" else 40.0
    frames = round(duration / graph.motion.dt)
    target = (
        [[0, [0.4, 0]], [10, [0.6, 0.05]], [20, [0.35, 0]]] if source != "turning" else [[0, [1.0, 0]], [20, [0, -1.0]]]
    )
    avoid = None
    if avoiding:
        rng = np.random.default_rng(5)
        avoid = rng.integers(0, graph.motion.n_frames if graph.period is None else graph.period, (3, frames))
        avoid[2] = -1  # a walk yet to be made
    params = {"target": target, "features": features, "avoid": avoid}
    problem = annotated._Problem(flockkit.get("walk", "annotated", **params), graph, duration)
    assert problem._compiled() == (source != "turning")
    seeds = range(4)
    fast = _walks(monkeypatch, True, graph, seeds, duration, **params)
    reference = _walks(monkeypatch, False, graph, seeds, duration, **params)
    assert [w for w, _, _ in fast] == [w for w, _, _ in reference]
    assert [e for _, e, _ in fast] == [e for _, e, _ in reference]
    assert [r for _, _, r in fast] == [r for _, _, r in reference]  # the stream left where the reference leaves it
    assert any(kind == "transition" for w, _, _ in fast for kind, _ in w.edges)  # choices were made
    # a start given, a long budget and short segments: many replacements
    more = {**params, "start": 3, "budget": 60, "segment": 0.5}
    assert _walks(monkeypatch, True, graph, [7], duration, **more) == _walks(monkeypatch, False, graph, [7], duration,
                                                                            **more)  # fmt: skip


def test_a_scene_of_a_short_cycle_is_the_same_scene(monkeypatch):
    """Duplicates of a looping part with phase shifts, de-synchronised (walks avoiding others,
    some yet to be made): every walk the same."""
    from flockkit_walks import annotated

    phase = 2 * np.pi * np.arange(24)[:, None] / 24
    s = np.linspace(0.1, 1.0, 6)[None, :]
    wing = np.stack(np.broadcast_arrays(s, 0 * s, 0.5 * s * np.sin(phase)), axis=2)
    motion = flockkit.Motion(positions=np.concatenate([wing, wing * [-1, 1, 1]], axis=1), dt=1 / 30)
    parts = flockkit.Segmentation(labels=np.repeat([0, 1], 6), n_parts=2)
    wind = flockkit.Features(vectors=np.tile([0.5, 0.0, 0.0], (24, 1)), dt=1 / 30)
    layers = flockkit.build_layers(motion, segmentation=parts, features=wind, seed=0)
    region = flockkit.Polygon(vertices=[[0, 0], [12, 0], [12, 12], [0, 12]])
    scene = flockkit.Scene(templates=[layers], region=region, counts=[8], duration=12, seed=2, headings="aligned")
    made = []
    for compiled in (True, False):
        monkeypatch.setattr(annotated, "_COMPILED", compiled)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", flockkit.errors.FlockkitWarning)  # parts left in step: the same either way
            made.append(scene.synthesize())
    assert made[0].walks == made[1].walks
    assert made[0].report["first_rounds"] > 1  # neighbours were walked in rounds, later ones avoiding earlier ones
