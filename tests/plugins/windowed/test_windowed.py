"""The windowed builder and graph layers on real meshes (paper 002, section 4)."""

import warnings

import numpy as np
import pytest

import flockkit
from flockkit.errors import FileFormatError, ValidationError
from flockkit.scene.layers import seam_stretch

WINDOWED = flockkit.get("builder", "windowed")


def fox(shared_data, clip):
    return flockkit.io.read_mesh_animation(shared_data / "fox-gltf" / "Fox.glb", clip=clip)


def largest_step(motion):
    return np.linalg.norm(np.diff(motion.positions, axis=0), axis=-1).max()


def test_the_cost_is_the_papers_on_a_hand_computed_case():
    """D(p, q) sums alpha d_x + beta d_v over the window; here by loops, point by point."""
    rng = np.random.default_rng(0)
    motion = flockkit.Motion(positions=np.cumsum(rng.normal(size=(12, 4, 3)), axis=0), dt=0.1)
    builder = flockkit.get("builder", "windowed", window=1, alpha=2.0, beta=0.5)
    total, _, _ = builder.costs(motion)
    x = motion.positions
    v = np.concatenate([np.diff(x, axis=0), np.diff(x, axis=0)[-1:]])
    p, q = 4, 8
    expected = sum(
        2.0 * np.mean(np.sum((x[p + k] - x[q + k]) ** 2, axis=1))
        + 0.5 * np.mean(np.sum((v[p + k] - v[q + k]) ** 2, axis=1))
        for k in (-1, 0, 1)
    )
    assert total[p, q] == pytest.approx(expected)


@pytest.mark.parametrize("period", [4, 5, 12, 17])
def test_a_cycle_shorter_than_the_shift_blend_gets_shifts_blended_over_the_cycle(period):
    """A looping clip shorter than shift_blend (0.6 s: 18 frames at 30 fps) is built: its phase
    shifts blend over the cycle less one frame, with only the sizes such a blend hides, and a
    minute of it plays without a step larger than the blend's bound."""
    phase = 2 * np.pi * np.arange(period)[:, None] / period
    s = np.linspace(0.2, 1.0, 6)[None, :]
    wing = np.stack(np.broadcast_arrays(s, 0 * s, 0.4 * s * np.sin(phase + s)), axis=2)
    motion = flockkit.Motion(positions=wing, dt=1 / 30)
    graph = flockkit.build_graph(motion, builder="windowed")
    assert graph.period == period
    blend = period - 1
    shifts = [t for t, shift in zip(graph.transitions, graph.shifts) if shift]
    assert shifts and all(t.blend == blend for t in shifts)
    hidden = [size for size in (1, 2) if 3 * size <= blend + 1]
    assert sorted(set(graph.shifts[graph.shifts != 0].tolist())) == sorted(hidden + [-h for h in hidden])
    walk = flockkit.walk(graph, duration=60, seed=1)
    played = flockkit.synthesize(graph, walk)
    assert played.n_frames >= 1800
    largest = np.linalg.norm(np.diff(np.concatenate([wing, wing[:1]]), axis=0), axis=2).max()
    worst = max(hidden)
    assert largest_step(played) <= largest * (1 + 1.5 * 2 * worst / (blend + 1)) + 1e-12
    # built into layers and played in a scene of duplicates, as any short loop is
    layers = flockkit.build_layers(motion, segmentation=flockkit.Segmentation(labels=np.zeros(6, int), n_parts=1),
                                   features=flockkit.Features(vectors=np.zeros((period, 3)), dt=1 / 30))  # fmt: skip
    region = flockkit.Polygon(vertices=[[0, 0], [20, 0], [20, 20], [0, 20]])
    scene = flockkit.Scene(templates=[layers], region=region, counts=[4], duration=10, seed=2)
    with warnings.catch_warnings():  # a 4-frame cycle has too few phases for 3 close neighbours: warned
        warnings.simplefilter("ignore", flockkit.errors.FlockkitWarning)
        assert scene.synthesize().n_frames == 300


def test_the_walk_clip_loops(shared_data):
    """The Fox's Walk clip loops: its graph has the transition from its last frame to its first."""
    walk = fox(shared_data, "Walk")
    graph = flockkit.build_graph(walk.motion, builder="windowed")
    last = walk.motion.n_frames - 1
    assert any(t.start == last and t.end == 0 for t in graph.transitions)
    assert all(np.array_equal(t.alignment.rotation, np.eye(3)) for t in graph.transitions)


def test_a_layered_fox_plays_a_minute_without_jumps_or_tears(shared_data):
    survey = fox(shared_data, "Survey")
    layers = flockkit.build_layers(survey, seed=0)
    assert layers.n_parts >= 2 and layers.faces is not None
    played = flockkit.synthesize(layers, flockkit.walk(layers, duration=60, seed=1))
    assert played.duration >= 60 and played.n_agents == survey.motion.n_agents
    assert largest_step(played) <= 1.5 * largest_step(survey.motion)
    seam = seam_stretch(played, survey.faces, layers.segmentation.labels, reference=survey.motion)
    assert seam <= 1.5 * seam_stretch(survey.motion, survey.faces)
    # the parts are out of step: not one part's frames replayed for all
    walks = flockkit.walk(layers, duration=60, seed=1).walks
    assert len({(w.start, tuple(w.edges[:3])) for w in walks}) > 1


def seam_edge_stretch(motion, mesh, labels):
    """|length / mean source length - 1| of every edge of a face spanning two parts, every frame."""
    faces = mesh.faces[np.any(labels[mesh.faces] != labels[mesh.faces][:, :1], axis=1)]
    edges = flockkit.mesh.face_edges(faces)

    def length(positions):
        return np.linalg.norm(positions[:, edges[:, 0]] - positions[:, edges[:, 1]], axis=2)

    return np.abs(length(motion.positions) / length(mesh.motion.positions).mean(axis=0) - 1)


def test_seams_are_smoothed(shared_data, monkeypatch):
    """Without the smoothing the same walk stretches its seams more, typically (the mean and the
    90th percentile over seam edges and frames; the Fox's vertices are welded, so no copy parts).
    Its largest stretch is not lowered: on a mesh this coarse the smoothed zone is most of the
    body, and the smoothing moves it even where the parts play in step."""
    import flockkit.scene.layers

    survey = fox(shared_data, "Survey")
    layers = flockkit.build_layers(survey, seed=0)
    assert layers.welds is not None
    walk = flockkit.walk(layers, duration=30, seed=2)
    smoothed = flockkit.synthesize(layers, walk)
    smooth = seam_edge_stretch(smoothed, survey, layers.segmentation.labels)
    monkeypatch.setattr(flockkit.scene.layers, "SEAM_PASSES", 0)
    raw = seam_edge_stretch(flockkit.synthesize(layers, walk), survey, layers.segmentation.labels)
    assert smooth.mean() < 0.9 * raw.mean()
    assert np.percentile(smooth, 90) < 0.8 * np.percentile(raw, 90)
    assert flockkit.scene.crack_width(smoothed, survey) <= 1e-6


def test_layers_save_load_and_walk_deterministically(tmp_path, shared_data):
    layers = flockkit.build_layers(fox(shared_data, "Survey"), seed=0)
    layers.save(tmp_path / "fox-layers.npz")
    loaded = flockkit.GraphLayers.load(tmp_path / "fox-layers.npz")
    assert loaded == layers
    assert flockkit.walk(loaded, duration=10, seed=4) == flockkit.walk(layers, duration=10, seed=4)
    flockkit.segment(layers.source, seed=0).save(tmp_path / "parts.npz")
    with pytest.raises(FileFormatError, match="parts.npz"):
        flockkit.GraphLayers.load(tmp_path / "parts.npz")


def test_layers_refuse_what_does_not_fit(shared_data):
    survey = fox(shared_data, "Survey")
    with pytest.raises(ValidationError, match="labels 3 points but the motion has 1728"):
        flockkit.build_layers(survey, segmentation=flockkit.Segmentation(labels=[0, 1, 1], n_parts=2))
    layers = flockkit.build_layers(survey, seed=0)
    with pytest.raises(ValidationError, match="LayeredWalk"):
        flockkit.synthesize(layers, flockkit.walk(layers.graphs[0], duration=5, seed=0))
    with pytest.raises(ValidationError, match="one a part"):
        flockkit.GraphLayers(source=layers.source, segmentation=layers.segmentation, graphs=layers.graphs[:1])


def test_windowed_passes_the_builder_kit_on_a_boids_motion(monkeypatch):
    """The kit's builder checks, with a boids recording in place of the kit's own."""
    import flockkit.testing.builder as kit
    from flockkit.testing import checks_for

    boids = flockkit.simulate(n_agents=8, steps=150, seed=3)
    monkeypatch.setattr(kit, "_recording", lambda builder: flockkit.Motion(positions=boids.positions, dt=boids.dt))
    checks = checks_for("builder", WINDOWED)
    assert len(checks) >= 6
    for check in checks:
        check("windowed", WINDOWED)


def test_layered_synthesis_equals_each_part_played_and_smoothed_pass_by_pass(monkeypatch):
    """The fast assembly (runs of points copied as slices, scattered points gathered) and the
    composed smoothing give what playing each part and smoothing pass by pass gives."""
    import flockkit.scene.layers

    side, frames = 12, 90
    u, v = np.meshgrid(np.arange(side) / side, np.arange(side) / side)
    u, v = u.ravel(), v.ravel()
    t = np.arange(frames)[:, None] / 30
    wave = np.where(u < 0.5, np.sin(2 * np.pi * (t + u)), 0.5 * np.sin(2 * np.pi * (1.7 * t + v)))
    positions = np.stack([np.broadcast_to(u, wave.shape), np.broadcast_to(v, wave.shape), 0.1 * wave], axis=2)
    index = np.arange(side * side).reshape(side, side)
    quads = np.stack([index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1]], axis=2).reshape(-1, 4)
    mesh = flockkit.AnimatedMesh(motion=flockkit.Motion(positions=positions, dt=1 / 30), faces=quads)
    # part 0: the left half (runs of 6), part 1: every other point of the right half (scattered)
    labels = np.where(u < 0.5, 0, 1 + (np.arange(side * side) % 2))
    layers = flockkit.build_layers(mesh, segmentation=flockkit.Segmentation(labels=labels, n_parts=3), seed=0)
    walk = flockkit.walk(layers, duration=8, seed=3)
    played = [flockkit.synthesize(graph, w).positions for graph, w in zip(layers.graphs, walk.walks)]
    n = min(len(p) for p in played)
    expected = np.empty((n, side * side, 3))
    for points, part in zip(layers.segmentation.parts(), played):
        expected[:, points] = part[:n]
    monkeypatch.setattr(flockkit.scene.layers, "SEAM_PASSES", 0)
    np.testing.assert_array_equal(flockkit.synthesize(layers, walk).positions, expected)

    monkeypatch.setattr(flockkit.scene.layers, "SEAM_PASSES", 3)
    neighbors = [set() for _ in range(side * side)]
    for a, b in flockkit.mesh.face_edges(quads):
        neighbors[a].add(b)
        neighbors[b].add(a)
    spanning = {p for face in quads if len(set(labels[face])) > 1 for p in face}
    zone = spanning | {q for p in spanning for q in neighbors[p]}  # SEAM_RINGS = 1
    rest = positions.mean(axis=0)
    displacement = expected - rest
    for _ in range(3):
        before = displacement.copy()
        for p in zone:
            displacement[:, p] = before[:, sorted(neighbors[p])].mean(axis=1)
    smoothed = flockkit.synthesize(layers, walk).positions
    np.testing.assert_allclose(smoothed, displacement + rest, atol=1e-12)
    assert not np.allclose(smoothed, expected)


def small_flag(side=12, frames=90):
    """A grid whose left and right halves wave at different rates, with its halves as parts."""
    u, v = np.meshgrid(np.linspace(0, 1, side), np.linspace(0, 1, side))
    u, v = u.ravel(), v.ravel()
    t = np.arange(frames)[:, None] / 30
    wave = np.where(u < 0.5, 0.1 * np.sin(2 * np.pi * (0.7 * t + u)), 0.15 * np.sin(2 * np.pi * (1.3 * t + 2 * u)))
    positions = np.stack([np.broadcast_to(u, wave.shape), np.broadcast_to(v, wave.shape), wave * u], axis=2)
    index = np.arange(side * side).reshape(side, side)
    quads = np.stack([index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1]], axis=2).reshape(-1, 4)
    mesh = flockkit.AnimatedMesh(motion=flockkit.Motion(positions=positions, dt=1 / 30), faces=quads, name="flag")
    return mesh, flockkit.Segmentation(labels=(u >= 0.5).astype(int), n_parts=2)


def smoothed_by_hand(positions, layers):
    """The documented smoothing, point by point: the zone is the points of faces that span two
    parts and SEAM_RINGS rings around them; each pass gives every zone point the mean displacement
    (from its mean source position) of its mesh neighbors."""
    import flockkit.scene.layers as module

    labels = layers.segmentation.labels
    neighbors = [set() for _ in labels]
    for face in layers.faces:
        for a, b in zip(face, np.roll(face, -1)):
            neighbors[a].add(b)
            neighbors[b].add(a)
    zone = {p for face in layers.faces if len(set(labels[face])) > 1 for p in face}
    for _ in range(module.SEAM_RINGS):
        zone |= {q for p in zone for q in neighbors[p]}
    rest = layers.source.positions.mean(axis=0)
    shifted = positions - rest
    for _ in range(module.SEAM_PASSES):
        before = shifted.copy()
        for p in zone:
            shifted[:, p] = np.mean([before[:, q] for q in neighbors[p]], axis=0)
    return shifted + rest


@pytest.mark.parametrize("moved", [False, True])
def test_layered_synthesis_is_its_parts_played_and_smoothed(moved):
    """Every part plays exactly what synthesize plays for its own walk (a part moved by its walk's
    start pose included), and the seams are smoothed as documented."""
    mesh, parts = small_flag()
    layers = flockkit.build_layers(mesh, segmentation=parts, seed=0)
    walk = flockkit.walk(layers, duration=10, seed=3)
    assert all(any(kind == "transition" for kind, _ in w.edges) for w in walk.walks)  # blends played
    if moved:  # the second part played a little to the side
        shifted = walk.walks[1]
        shifted = flockkit.Walk(start=shifted.start, edges=shifted.edges, translation=[0.0, 0.0, 0.05])
        walk = flockkit.LayeredWalk(walks=[walk.walks[0], shifted])
    own = [flockkit.synthesize(graph, w).positions for graph, w in zip(layers.graphs, walk.walks)]
    frames = min(len(p) for p in own)
    assembled = np.empty((frames, mesh.motion.n_agents, 3))
    for points, played in zip(parts.parts(), own):
        assembled[:, points] = played[:frames]
    played = flockkit.synthesize(layers, walk).positions
    np.testing.assert_allclose(played, smoothed_by_hand(assembled, layers), rtol=0, atol=1e-12)
    assert not np.allclose(played, assembled)  # the smoothing did something
