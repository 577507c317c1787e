"""Welding a mesh's copies of one point (flockkit.mesh.weld_map) and the crack measure
(flockkit.scene.crack_width): a triangle soup, or a file that splits vertices along its texture
seams, segments and plays as the surface it is, and its seams never crack."""

import numpy as np
import pytest

import flockkit
from flockkit.errors import ValidationError
from flockkit.mesh import WELD_TOLERANCE, object_size, weld_map
from flockkit.scene import crack_width

# what "no crack" means: the gap between copies, relative to the object's size
NO_CRACK = 1e-6


def soup(mesh: flockkit.AnimatedMesh) -> flockkit.AnimatedMesh:
    """`mesh` with every face given its own corners: no two faces share a vertex."""
    faces = mesh.faces
    positions = mesh.motion.positions[:, faces.ravel()]
    motion = flockkit.Motion(positions=positions, dt=mesh.motion.dt)
    return flockkit.AnimatedMesh(motion=motion, faces=np.arange(faces.size).reshape(faces.shape), name="soup")


def flag(side=10, frames=90):
    """A grid whose left and right halves wave at different rates, and its halves as labels."""
    u, v = np.meshgrid(np.linspace(0, 1, side), np.linspace(0, 1, side))
    u, v = u.ravel(), v.ravel()
    t = np.arange(frames)[:, None] / 30
    wave = np.where(u < 0.5, 0.1 * np.sin(2 * np.pi * (0.7 * t + u)), 0.15 * np.sin(2 * np.pi * (1.3 * t + 2 * u)))
    positions = np.stack([np.broadcast_to(u, wave.shape), np.broadcast_to(v, wave.shape), wave * u], axis=2)
    index = np.arange(side * side).reshape(side, side)
    quads = np.stack([index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1]], axis=2).reshape(-1, 4)
    mesh = flockkit.AnimatedMesh(motion=flockkit.Motion(positions=positions, dt=1 / 30), faces=quads, name="flag")
    return mesh, (u >= 0.5).astype(int)


def groups(welds):
    """The welded groups of more than one point, as a set of frozensets."""
    return {frozenset(np.flatnonzero(welds == w).tolist()) for w in np.unique(welds) if np.sum(welds == w) > 1}


# --- weld_map and object_size


def test_a_soup_welds_back_into_its_shared_vertices():
    mesh, _ = flag()
    welds = weld_map(soup(mesh))
    corners = mesh.faces.ravel()  # soup point i is a copy of shared vertex corners[i]
    expected = {frozenset(np.flatnonzero(corners == v).tolist()) for v in np.unique(corners)}
    assert groups(welds) == {g for g in expected if len(g) > 1}
    assert np.array_equal(welds[welds], welds) and np.all(welds <= np.arange(len(welds)))
    assert np.array_equal(welds, [np.flatnonzero(corners == c)[0] for c in corners])  # the first copy
    np.testing.assert_array_equal(weld_map(mesh), np.arange(mesh.motion.n_agents))  # nothing to weld


def test_points_that_touch_only_in_some_frames_are_not_welded():
    """Lips closed at rest that open later are two points, not one."""
    frames = 20
    positions = np.zeros((frames, 4, 3))
    positions[:, 1, 1] = 0.1 * np.arange(frames)  # starts on point 0, then leaves
    positions[:, 2, 0] = positions[:, 3, 0] = 1.0  # 2 and 3 together throughout
    positions[:, 3, 2] = 1e-3 * np.sin(np.arange(frames))  # ... within 1e-3 of the size
    motion = flockkit.Motion(positions=positions, dt=0.1)
    assert groups(weld_map(motion)) == set()  # 1e-3 is beyond the default tolerance
    assert groups(weld_map(motion, 1e-2)) == {frozenset({2, 3})}
    size = object_size(motion)
    assert groups(weld_map(motion, 0.99e-3 / size)) == set()


def test_copies_that_agree_in_the_probe_frames_and_on_average_still_part():
    """A point that matches another in the frames used to find candidates, and on average, but
    leaves it in others, is not welded to it; the copies that truly stay together still are."""
    frames = 20
    positions = np.zeros((frames, 5, 3))
    positions[:, :, 0] = np.arange(frames)[:, None] * 0.01
    probe = set(np.linspace(0, frames - 1, min(frames, flockkit.mesh.WELD_PROBE_FRAMES)).round().astype(int))
    odd = [t for t in range(frames) if t not in probe][:2]
    positions[odd[0], 1, 1], positions[odd[1], 1, 1] = 0.5, -0.5  # same mean, leaves in two frames
    positions[odd[0], 2, 1], positions[odd[1], 2, 1] = 0.5, -0.5  # ... as 2 does, with it
    positions[:, 4, 2] = 1.0
    welds = weld_map(flockkit.Motion(positions=positions, dt=0.1))
    assert groups(welds) == {frozenset({0, 3}), frozenset({1, 2})}


def test_object_size_is_one_frames_box_whatever_the_travel():
    positions = np.zeros((10, 2, 3))
    positions[:, 1] = [3.0, 4.0, 0.0]
    still = flockkit.Motion(positions=positions, dt=0.1)
    travelling = flockkit.Motion(positions=positions + np.arange(10)[:, None, None] * 100.0, dt=0.1)
    assert object_size(still) == object_size(travelling) == pytest.approx(5.0)


@pytest.mark.parametrize("tolerance", [-1e-6, 0.5, float("nan"), "small"])
def test_bad_tolerances_are_refused(tolerance):
    mesh, _ = flag(4, 10)
    with pytest.raises(ValidationError, match="weld tolerance"):
        weld_map(mesh, tolerance)


@pytest.mark.parametrize("weld", ["yes", [1e-6], -1.0, 0.5])
def test_bad_weld_options_are_refused_naming_the_option(weld):
    mesh, _ = flag(4, 10)
    with pytest.raises(ValidationError, match="weld"):
        flockkit.segment(mesh, seed=0, weld=weld)
    with pytest.raises(ValidationError, match="weld"):
        flockkit.build_layers(mesh, seed=0, weld=weld)


# --- segmentation


def test_a_soup_segments_as_its_surface():
    mesh, _ = flag()
    shared = flockkit.segment(mesh, seed=0)
    parts = flockkit.segment(soup(mesh), seed=0)
    assert parts.n_points == soup(mesh).motion.n_agents
    assert flockkit.scene.same_partition(parts.labels, shared.labels[mesh.faces.ravel()])
    welds = weld_map(soup(mesh))
    assert np.array_equal(parts.labels[welds], parts.labels)  # every copy in its first's part


def test_the_weld_option_on_plain_motion_and_off():
    """A Motion's agents are not welded unless asked; weld=True or a tolerance welds them."""
    mesh, _ = flag(6, 40)
    motion = soup(mesh).motion
    assert flockkit.build_layers(motion, segmentation=flockkit.Segmentation(labels=np.zeros(motion.n_agents,
                                 dtype=int), n_parts=1), seed=0).welds is None  # fmt: skip
    for weld in (True, WELD_TOLERANCE, 1e-4):
        layers = flockkit.build_layers(motion, seed=0, weld=weld)
        assert np.array_equal(layers.welds, weld_map(motion))
    assert flockkit.build_layers(soup(mesh), seed=0, weld=False).welds is None
    assert flockkit.build_layers(mesh, seed=0).welds is None  # nothing to weld: no map


def test_a_segmentation_that_splits_welded_points_is_refused():
    mesh, labels = flag(6, 40)
    pieces = soup(mesh)
    labels = labels[mesh.faces.ravel()].copy()
    welds = weld_map(pieces)
    copy = int(np.flatnonzero(welds != np.arange(len(welds)))[0])
    labels[copy] = 1 - labels[copy]
    split = flockkit.Segmentation(labels=labels, n_parts=2)
    with pytest.raises(ValidationError, match=rf"segmentation.*point {copy} is welded to point {welds[copy]}"):
        flockkit.build_layers(pieces, segmentation=split, seed=0)
    assert flockkit.build_layers(pieces, segmentation=split, seed=0, weld=False).welds is None
    good = flockkit.build_layers(pieces, segmentation=flockkit.Segmentation(labels=labels[welds], n_parts=2), seed=0)
    across = np.arange(len(welds))  # a point of part 1 welded to a later point of part 0
    first = int(np.flatnonzero(good.segmentation.labels == 1)[0])
    later = int(np.flatnonzero((good.segmentation.labels == 0) & (across > first))[0])
    across[later] = first
    with pytest.raises(ValidationError, match=rf"GraphLayers.welds: point {later} is welded to point {first}"):
        flockkit.GraphLayers(source=good.source, segmentation=good.segmentation, graphs=good.graphs,
                             faces=good.faces, welds=across)  # fmt: skip
    with pytest.raises(ValidationError, match="GraphLayers.welds"):
        flockkit.GraphLayers(source=good.source, segmentation=good.segmentation, graphs=good.graphs,
                             welds=good.welds[:-1])  # fmt: skip
    with pytest.raises(ValidationError, match="GraphLayers.welds"):
        flockkit.GraphLayers(source=good.source, segmentation=good.segmentation, graphs=good.graphs,
                             welds=np.arange(len(welds))[::-1])  # fmt: skip


# --- synthesis


def smoothed_by_hand(positions, layers):
    """The documented smoothing on the welded faces, point by point: the zone is the points of
    welded faces spanning two parts and SEAM_RINGS rings around them; each pass gives every zone
    point the mean displacement (from its mean source position) of its welded neighbours; every
    copy then takes its first's position."""
    import flockkit.scene.layers as module

    labels, faces = layers.segmentation.labels, layers.welds[layers.faces]
    neighbors = [set() for _ in labels]
    for face in faces:
        for a, b in zip(face, np.roll(face, -1)):
            neighbors[a].add(b)
            neighbors[b].add(a)
    zone = {p for face in faces if len(set(labels[face])) > 1 for p in face}
    for _ in range(module.SEAM_RINGS):
        zone |= {q for p in zone for q in neighbors[p]}
    rest = layers.source.positions.mean(axis=0)
    shifted = positions - rest
    for _ in range(module.SEAM_PASSES):
        before = shifted.copy()
        for p in zone:
            shifted[:, p] = np.mean([before[:, q] for q in neighbors[p]], axis=0)
    return (shifted + rest)[:, layers.welds]


def test_a_soup_plays_smoothed_over_its_welded_faces_without_cracks():
    mesh, labels = flag()
    pieces = soup(mesh)
    parts = flockkit.Segmentation(labels=labels[mesh.faces.ravel()], n_parts=2)
    layers = flockkit.build_layers(pieces, segmentation=parts, seed=0)
    assert layers.welds is not None
    walk = flockkit.walk(layers, duration=10, seed=3)
    own = [flockkit.synthesize(graph, w).positions for graph, w in zip(layers.graphs, walk.walks)]
    frames = min(len(p) for p in own)
    assembled = np.empty((frames, pieces.motion.n_agents, 3))
    for points, played in zip(parts.parts(), own):
        assembled[:, points] = played[:frames]
    played = flockkit.synthesize(layers, walk)
    assert played.n_agents == pieces.motion.n_agents  # every vertex, in the file's order
    np.testing.assert_allclose(played.positions, smoothed_by_hand(assembled, layers), rtol=0, atol=1e-12)
    assert crack_width(played, pieces) == 0.0
    # unwelded, each quad is smoothed on its own and the surface cracks
    unwelded = flockkit.build_layers(pieces, segmentation=parts, seed=0, weld=False)
    cracked = flockkit.synthesize(unwelded, flockkit.walk(unwelded, duration=10, seed=3))
    assert crack_width(cracked, pieces) > 1e-3
    assert 0 < crack_width(cracked, pieces, statistic="mean") < crack_width(cracked, pieces)


def test_welds_survive_save_and_load_and_a_scene_file(tmp_path):
    mesh, labels = flag(6, 40)
    pieces = soup(mesh)
    layers = flockkit.build_layers(pieces, segmentation=flockkit.Segmentation(labels=labels[mesh.faces.ravel()],
                                   n_parts=2), seed=0)  # fmt: skip
    layers.save(tmp_path / "layers.npz")
    loaded = flockkit.GraphLayers.load(tmp_path / "layers.npz")
    assert loaded == layers and np.array_equal(loaded.welds, layers.welds)
    walk = flockkit.walk(loaded, duration=5, seed=1)
    np.testing.assert_array_equal(flockkit.synthesize(loaded, walk).positions,
                                  flockkit.synthesize(layers, walk).positions)  # fmt: skip
    assert crack_width(flockkit.synthesize(loaded, walk), loaded) == 0.0


# --- crack_width


def test_crack_width_measures_copies_pulled_apart():
    positions = np.zeros((4, 4, 3))
    positions[:, 1, 0] = 2.0  # size: 2
    reference = flockkit.Motion(positions=positions, dt=0.1)  # 2 and 3 copies of 0
    pulled = positions.copy()
    pulled[2, 2] += [0.0, 0.1, 0.0]  # one frame, one copy, 0.1 away
    pulled[3, 3] += [0.0, 0.0, 0.3]
    motion = flockkit.Motion(positions=pulled, dt=0.1)
    assert crack_width(motion, reference) == pytest.approx(0.3 / 2)
    assert crack_width(motion, reference, statistic="mean") == pytest.approx((0.1 + 0.3) / (4 * 2) / 2)
    assert crack_width(reference, reference) == 0.0
    assert crack_width(motion, flockkit.Motion(positions=positions[:, :2].repeat(2, axis=1), dt=0.1)) >= 0
    mesh = flockkit.AnimatedMesh(motion=reference, faces=[[0, 1, 2]])
    assert crack_width(flockkit.AnimatedMesh(motion=motion, faces=[[0, 1, 2]]), mesh) == pytest.approx(0.15)


def test_crack_width_refuses_what_it_cannot_measure():
    motion = flockkit.Motion(positions=np.zeros((3, 4, 3)), dt=0.1)
    with pytest.raises(ValidationError, match="statistic"):
        crack_width(motion, motion, statistic="median")
    with pytest.raises(ValidationError, match="motion has 4 points but the reference has 2"):
        crack_width(motion, flockkit.Motion(positions=np.zeros((3, 2, 3)), dt=0.1))
    with pytest.raises(ValidationError, match="reference must be"):
        crack_width(motion, np.zeros((3, 4, 3)))
    with pytest.raises(ValidationError, match="motion must be"):
        crack_width(np.zeros((3, 4, 3)), motion)


# --- the real corpus

ASSETS = [
    ("fox-gltf/Fox.glb", "Survey"),
    ("robot-expressive-gltf/RobotExpressive.glb", "Wave"),
    ("morph-stress-test-gltf/MorphStressTest.gltf", "TheWave"),
]


@pytest.mark.parametrize("path, clip", ASSETS, ids=[c for _, c in ASSETS])
@pytest.mark.parametrize("soup_it", [False, True], ids=["asset", "soup"])
def test_real_assets_never_crack_with_seams_smoothed(shared_data, path, clip, soup_it):
    mesh = flockkit.io.read_mesh_animation(shared_data / path, clip=clip)
    if soup_it:
        mesh = soup(mesh)
    layers = flockkit.build_layers(mesh, seed=0)
    assert layers.n_parts >= 2 and layers.welds is not None
    played = flockkit.synthesize(layers, flockkit.walk(layers, duration=20, seed=1))
    assert played.n_agents == mesh.motion.n_agents
    assert crack_width(played, mesh) <= NO_CRACK


def test_the_fox_cracks_unwelded(shared_data):
    """What welding prevents: the Fox's file gives every triangle its own corners."""
    mesh = flockkit.io.read_mesh_animation(shared_data / "fox-gltf" / "Fox.glb", clip="Survey")
    layers = flockkit.build_layers(mesh, seed=0, weld=False)
    played = flockkit.synthesize(layers, flockkit.walk(layers, duration=20, seed=1))
    assert crack_width(played, mesh) > 0.01
