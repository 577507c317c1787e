"""`flockkit scene` from what `flockkit build --layers` writes (layers without feature arrows),
with --features keyframes|motion; `render` of every source `segment` reads; --up and
--meters-per-unit; scene and crowd outputs written whole or not at all."""

import numpy as np
import pytest

import flockkit
from flockkit.cli import main
from flockkit.errors import ValidationError

WIND = "[[0, [0.8, 0]], [4, [0.8, 0]], [6, [0, 0.8]], [10, [0, 0.8]], [12, [-0.8, 0]], [16, [-0.8, 0]], " \
       "[18, [0, -0.8]], [22, [0, -0.8]], [24, [0.8, 0]]]"  # fmt: skip

SCENE = """
duration = 8
seed = 2
region = [[0, 0], [30, 0], [30, 20], [0, 20]]
headings = "aligned"

[[templates]]
layers = "plants.npz"
count = 6
FEATURES

[[arrows]]
position = [15, 10]
keyframes = [[0, [0.8, 0]], [4, [0.8, 0]], [6, [0, 0.8]]]
"""


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The plants of flockkit.testing.inputs as `build --layers` writes them (no features), and
    as the library builds them with their wind (inputs.plants' own Features)."""
    from flockkit.testing import inputs

    folder = tmp_path_factory.mktemp("built")
    motion, labels, wind = inputs.plants()
    motion.save(folder / "plants-motion.npz")
    flockkit.Segmentation(labels=labels, n_parts=2).save(folder / "parts.npz")
    assert main(["build", str(folder / "plants-motion.npz"), "--layers", "--parts", str(folder / "parts.npz"),
                 "--seed", "1", "--param", "transitions_per_minute=400", "-o", str(folder / "plants.npz"),
                 "--quiet"]) == 0  # fmt: skip
    layers = flockkit.GraphLayers.load(folder / "plants.npz")
    assert layers.features is None
    flockkit.build_layers(motion, segmentation=flockkit.Segmentation(labels=labels, n_parts=2), features=wind,
                          seed=1, transitions_per_minute=400).save(folder / "plants-wind.npz")  # fmt: skip
    return folder, wind


def scene_file(folder, features="", layers="plants.npz", text=SCENE, name="scene.toml"):
    path = folder / name
    path.write_text(text.replace("FEATURES", features).replace("plants.npz", layers))
    return path


def test_layers_from_build_are_refused_naming_both_ways_and_no_constraints_claimed(capsys, built):
    folder, _ = built
    for text in (SCENE, SCENE[: SCENE.index("[[arrows]]")]):  # with arrows, and with none
        scene = scene_file(folder, text=text)
        code, _, err = run(capsys, "scene", scene, "-o", folder / "out", "--quiet")
        assert code == 1 and len(err.strip().splitlines()) == 1, err
        assert "[[templates]] 0 (plants.npz)" in err and "--features motion" in err and "features = [[time" in err
        assert "constraints" not in err
        assert not (folder / "out").exists()


def test_the_library_says_why_a_scene_needs_features_without_claiming_constraints(built):
    folder, _ = built
    layers = flockkit.GraphLayers.load(folder / "plants.npz")
    square = flockkit.Polygon(vertices=[[0, 0], [30, 0], [30, 30], [0, 30]])
    with pytest.raises(ValidationError, match="has no features") as caught:
        flockkit.Scene(templates=[layers], region=square, counts=[2], duration=4)
    assert "but the scene has constraints" not in str(caught.value)


def test_keyframes_in_the_scene_file_give_what_the_layers_built_with_them_give(capsys, built):
    folder, wind = built
    keyframed = scene_file(folder, f"features = {WIND}", name="keyframed.toml")
    code, out, err = run(capsys, "scene", keyframed, "--features", "keyframes", "-o", folder / "keyframed", "--quiet",
                         "--no-usd", "--no-pictures")  # fmt: skip
    assert code == 0 and "6 objects, 80 frames" in out, err
    carried = scene_file(folder, layers="plants-wind.npz", name="carried.toml")
    code, _, err = run(capsys, "scene", carried, "-o", folder / "carried", "--quiet", "--no-usd", "--no-pictures")
    assert code == 0, err
    ours = flockkit.SceneAnimation.load(folder / "keyframed" / "scene.npz")
    theirs = flockkit.SceneAnimation.load(folder / "carried" / "scene.npz")
    np.testing.assert_allclose(ours.templates[0].features.vectors, wind.vectors, atol=1e-12)
    np.testing.assert_array_equal(ours.source_frames(), theirs.source_frames())
    # an entry's keyframes are read whatever --features says, and without it
    code, _, err = run(capsys, "scene", keyframed, "-o", folder / "plain", "--quiet", "--no-usd", "--no-pictures")
    assert code == 0, err
    np.testing.assert_array_equal(flockkit.SceneAnimation.load(folder / "plain" / "scene.npz").source_frames(),
                                  ours.source_frames())  # fmt: skip


def test_features_from_the_motion_itself(capsys, built):
    from flockkit.scene import read_scene

    folder, _ = built
    scene = read_scene(scene_file(folder, name="motion.toml"), features="motion")
    source = flockkit.GraphLayers.load(folder / "plants.npz").source
    assert scene.templates[0].features == flockkit.Features.from_motion(source)


@pytest.mark.parametrize(
    ("features", "option", "message"),
    [
        ("", "keyframes", "[[templates]] 0 (plants.npz): features='keyframes' (flockkit scene --features keyframes) "
                          "but the entry has no features keyframes"),
        ("features = [[0, [0.8, 0]], [30, [0, 0.8]]]", "keyframes",
         "[[templates]] 0 (plants.npz) features: Features.from_keyframes: keyframes: keyframe times must lie in 0..24"),
        ("features = [[0, [1.5, 0]]]", None, "arrow lengths are normalized to [0, 1]"),
        ("features = 'wind'", None, "[[templates]] 0 (plants.npz) features"),
    ],
)  # fmt: skip
def test_bad_features_are_named_in_one_line_and_nothing_is_written(capsys, built, features, option, message):
    folder, _ = built
    scene = scene_file(folder, features, name="bad.toml")
    code, _, err = run(capsys, "scene", scene, "-o", folder / "bad", "--quiet",
                       *(["--features", option] if option else []))  # fmt: skip
    assert code == 1 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (folder / "bad").exists()


def test_keyframes_for_a_template_that_carries_its_own_arrows_are_refused(capsys, built):
    folder, _ = built
    scene = scene_file(folder, "features = [[0, [0.8, 0]]]", layers="plants-wind.npz", name="twice.toml")
    code, _, err = run(capsys, "scene", scene, "--features", "keyframes", "-o", folder / "twice", "--quiet")
    assert code == 1 and "its layers carry their own feature arrows; leave out features here" in err, err
    with pytest.raises(SystemExit) as usage:
        main(["scene", str(scene), "--features", "wind", "-o", str(folder / "twice")])
    assert usage.value.code == 2 and "invalid choice: 'wind'" in capsys.readouterr().err
    from flockkit.scene import read_scene

    with pytest.raises(ValidationError, match="read_scene: features must be one of 'keyframes', 'motion' or None"):
        read_scene(scene, features="wind")


def test_a_scene_that_fails_late_writes_nothing(capsys, built, monkeypatch):
    """USD missing is refused before the walks; a picture failing after the animation was saved
    leaves no folder and no file."""
    import flockkit.io.usd
    import flockkit.viz
    from flockkit.errors import MissingDependencyError

    folder, _ = built
    scene = scene_file(folder, layers="plants-wind.npz", name="late.toml")

    def missing():
        raise MissingDependencyError("USD export needs usd-core: pip install 'flockkit[usd]'")

    with monkeypatch.context() as patch:
        patch.setattr(flockkit.io.usd, "require_usd_core", missing)
        code, _, err = run(capsys, "scene", scene, "-o", folder / "late", "--quiet")
    assert code == 1 and "flockkit[usd]" in err and not (folder / "late").exists()

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(flockkit.viz, "animate_scene", broken)
    code, _, err = run(capsys, "scene", scene, "-o", folder / "late", "--quiet", "--no-usd")
    assert code == 1 and "disk full" in err and len(err.strip().splitlines()) == 1
    assert not (folder / "late").exists() and not [p for p in folder.iterdir() if p.name.startswith(".late")]
    (folder / "kept").mkdir()
    (folder / "kept" / "notes.txt").write_text("mine")
    code, _, _ = run(capsys, "scene", scene, "-o", folder / "kept", "--quiet", "--no-usd")
    assert code == 1 and [p.name for p in (folder / "kept").iterdir()] == ["notes.txt"]


def _obj_sequence(folder, frames=40):
    """A quad strip of 8 x 2 vertices whose right half waves, as OBJ files frame0.obj, ..."""
    folder.mkdir()
    x, y = np.tile(np.arange(8.0), 2), np.repeat([0.0, 1.0], 8)
    faces = [(i, i + 1, i + 9, i + 8) for i in range(7)]
    for t in range(frames):
        z = np.where(x > 3.5, 0.3 * np.sin(2 * np.pi * (t / frames + x / 8)) * (x - 3.5), 0.0)
        vertices = "".join(f"v {float(a)!r} {float(b)!r} {float(c)!r}\n" for a, b, c in zip(x, y, z))
        (folder / f"frame{t}.obj").write_text(vertices + "".join(f"f {a + 1} {b + 1} {c + 1} {d + 1}\n"
                                                                 for a, b, c, d in faces))  # fmt: skip
    return folder


@pytest.mark.parametrize("pattern", ["{folder}", "{folder}/frame*", "{folder}/frame*.obj"])
def test_render_takes_every_source_segment_takes(capsys, tmp_path, pattern):
    source = pattern.format(folder=_obj_sequence(tmp_path / "strip"))
    code, out, err = run(capsys, "segment", source, "--parts", "2", "--seed", "0", "-o", tmp_path / "parts.npz")
    assert code == 0, err
    for name in ("strip.png", "strip.gif"):
        code, out, err = run(capsys, "render", source, "--parts", tmp_path / "parts.npz", "-o", tmp_path / name)
        assert code == 0 and (tmp_path / name).stat().st_size > 1000, err


def test_meshes_are_turned_into_flockkits_axes_when_their_axes_are_stated(capsys, tmp_path):
    strip = _obj_sequence(tmp_path / "strip")
    mesh = flockkit.io.read_mesh_animation(strip)
    code, _, err = run(capsys, "build", strip, "--layers", "--seed", "0", "--meters-per-unit", "cm",
                       "--segmenter-param", "n_parts=2", "-o", tmp_path / "layers.npz")  # fmt: skip
    assert code == 0, err
    layers = flockkit.GraphLayers.load(tmp_path / "layers.npz")
    expected = mesh.to_flockkit_axes(meters_per_unit=0.01).motion.positions
    np.testing.assert_allclose(layers.source.positions, expected)  # y up -> z up, centimetres -> metres
    code, _, err = run(capsys, "segment", strip, "--up", "z", "--meters-per-unit", "2", "-o", tmp_path / "p.npz")
    assert code == 0, err
    code, _, err = run(capsys, "segment", strip, "-o", tmp_path / "q.npz", "--meters-per-unit", "furlong")
    assert code == 1 and "meters_per_unit must be metres per unit" in err and not (tmp_path / "q.npz").exists()
    flockkit.simulate(n_agents=4, steps=20, seed=1).save(tmp_path / "flock.npz")
    code, _, err = run(capsys, "segment", tmp_path / "flock.npz", "--up", "y", "-o", tmp_path / "r.npz")
    assert code == 1 and "is a motion, not an animated mesh" in err and not (tmp_path / "r.npz").exists()
