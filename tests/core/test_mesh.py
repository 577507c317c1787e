"""Animated meshes in: glTF (skinning, morph targets), OBJ sequences, USD; AnimatedMesh files."""

import base64
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

import flockkit
from flockkit.errors import FileFormatError, ValidationError

FPS = 30.0


def fox(shared_data):
    return shared_data / "fox-gltf" / "Fox.glb"


def morph(shared_data):
    return shared_data / "morph-stress-test-gltf" / "MorphStressTest.gltf"


class Independent:
    """The glTF spec evaluated vertex by vertex, through pygltflib and scipy: a second reading of
    the file, sharing no code with flockkit's reader."""

    def __init__(self, path):
        pygltflib = pytest.importorskip("pygltflib")
        self.gltf = pygltflib.GLTF2().load(str(path))
        self.blob = self.gltf.binary_blob()
        if self.blob is None:  # a data URI
            self.blob = base64.b64decode(self.gltf.buffers[0].uri.split(",", 1)[1])

    def accessor(self, index):
        a = self.gltf.accessors[index]
        view = self.gltf.bufferViews[a.bufferView]
        dtype = {5126: "<f4", 5123: "<u2", 5121: "u1", 5125: "<u4"}[a.componentType]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[a.type]
        size = np.dtype(dtype).itemsize * width
        stride = view.byteStride or size
        start = (view.byteOffset or 0) + (a.byteOffset or 0)
        rows = [np.frombuffer(self.blob, dtype=dtype, count=width, offset=start + i * stride) for i in range(a.count)]
        return np.array(rows, dtype=float)

    def channel(self, animation, node, path, t):
        for c in animation.channels:
            if c.target.node == node and c.target.path == path:
                s = animation.samplers[c.sampler]
                times = self.accessor(s.input)[:, 0]
                values = self.accessor(s.output).reshape(len(times), -1)  # morph weights: W per key
                t = min(max(t, times[0]), times[-1])
                if path == "rotation":
                    return Slerp(times, Rotation.from_quat(values))([t]).as_quat()[0]
                return np.array([np.interp(t, times, values[:, k]) for k in range(values.shape[1])])
        return None

    def local(self, animation, node, t):
        n = self.gltf.nodes[node]
        translation = self.channel(animation, node, "translation", t)
        rotation = self.channel(animation, node, "rotation", t)
        scale = self.channel(animation, node, "scale", t)
        translation = translation if translation is not None else np.array(n.translation or [0, 0, 0], dtype=float)
        rotation = rotation if rotation is not None else np.array(n.rotation or [0, 0, 0, 1], dtype=float)
        scale = scale if scale is not None else np.array(n.scale or [1, 1, 1], dtype=float)
        m = np.eye(4)
        m[:3, :3] = Rotation.from_quat(rotation).as_matrix() @ np.diag(scale)
        m[:3, 3] = translation
        return m

    def world(self, animation, node, t):
        parent = next((i for i, n in enumerate(self.gltf.nodes) if node in (n.children or [])), None)
        mine = self.local(animation, node, t)
        return mine if parent is None else self.world(animation, parent, t) @ mine

    def skinned_vertex(self, clip, vertex, t):
        animation = next(a for a in self.gltf.animations if a.name == clip)
        node = next(i for i, n in enumerate(self.gltf.nodes) if n.mesh is not None)
        skin = self.gltf.skins[self.gltf.nodes[node].skin]
        attributes = self.gltf.meshes[0].primitives[0].attributes
        p = np.append(self.accessor(attributes.POSITION)[vertex], 1.0)
        joints, weights = self.accessor(attributes.JOINTS_0)[vertex], self.accessor(attributes.WEIGHTS_0)[vertex]
        inverse = self.accessor(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
        total = np.zeros(4)
        for j, w in zip(joints.astype(int), weights):
            total += w * (self.world(animation, skin.joints[j], t) @ inverse[j] @ p)
        return total[:3] / weights.sum()

    def morphed_vertex(self, clip, primitive, vertex, t):
        animation = next(a for a in self.gltf.animations if a.name == clip)
        weights = self.channel(animation, 0, "weights", t)
        prim = self.gltf.meshes[0].primitives[primitive]
        p = self.accessor(prim.attributes.POSITION)[vertex].copy()
        for k, target in enumerate(prim.targets):
            p += weights[k] * self.accessor(target["POSITION"])[vertex]
        return p


def test_fox_is_skinned_as_the_spec_says(shared_data):
    mesh = flockkit.io.read_mesh_animation(fox(shared_data), clip="Survey", fps=FPS)
    assert mesh.motion.positions.shape == (int(3.4166667 * FPS) + 1, 1728, 3) and mesh.motion.dt == 1 / FPS
    assert mesh.faces.shape == (576, 3) and mesh.name == "Fox:Survey"
    reference = Independent(fox(shared_data))
    for frame in (0, 41, 102):
        for vertex in (0, 500, 1727):
            expected = reference.skinned_vertex("Survey", vertex, frame / FPS)
            np.testing.assert_allclose(mesh.motion.positions[frame, vertex], expected, rtol=1e-5, atol=1e-4)
    assert 140 < np.ptp(mesh.motion.positions[0, :, 2]) < 170  # about 150 units nose to tail


def test_morph_targets_are_weighted_as_the_spec_says(shared_data):
    mesh = flockkit.io.read_mesh_animation(morph(shared_data), clip="Individuals", fps=FPS)
    assert mesh.motion.n_agents == 1528
    reference = Independent(morph(shared_data))
    first = len(reference.accessor(reference.gltf.meshes[0].primitives[0].attributes.POSITION))
    for frame in (0, 70, 200):
        for primitive, vertex in ((0, 10), (0, first - 1), (1, 5)):
            expected = reference.morphed_vertex("Individuals", primitive, vertex, frame / FPS)
            got = mesh.motion.positions[frame, vertex + (first if primitive else 0)]
            np.testing.assert_allclose(got, expected, atol=1e-6)


def test_clips_are_listed_and_chosen(shared_data):
    assert flockkit.io.list_clips(fox(shared_data)) == pytest.approx(
        {"Survey": 3.4166667, "Walk": 0.7083333, "Run": 1.1583333}
    )
    walk = flockkit.io.read_mesh_animation(fox(shared_data), clip="Walk")
    assert walk.motion.n_frames == int(0.7083333 * 30) + 1
    assert flockkit.io.read_mesh_animation(fox(shared_data)).name == "Fox:Survey"  # the first
    assert flockkit.io.read_mesh_animation(fox(shared_data), clip=2).name == "Fox:Run"
    with pytest.raises(ValidationError, match="no clip 'Trot'; its clips are 'Survey', 'Walk', 'Run'"):
        flockkit.io.read_mesh_animation(fox(shared_data), clip="Trot")


def test_robot_every_mesh_of_the_scene(shared_data):
    path = shared_data / "robot-expressive-gltf" / "RobotExpressive.glb"
    assert len(flockkit.io.list_clips(path)) == 14
    mesh = flockkit.io.read_mesh_animation(path, clip="Idle", fps=15)
    assert mesh.motion.n_agents == 7214 and np.isfinite(mesh.motion.positions).all()
    assert mesh.faces.max() < 7214 and len(mesh.edges()) > 7214


def _gltf_document(tmp_path, *, mime="application/gltf-buffer", animate=True):
    """A one-triangle glTF whose node moves from x = 0 to x = 2 in 1 s, its buffer a data URI."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype="<f4").tobytes()
    times = np.array([0.0, 1.0], dtype="<f4").tobytes()
    moves = np.array([[0, 0, 0], [2, 0, 0]], dtype="<f4").tobytes()
    blob = positions + times + moves
    document = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "buffers": [{"byteLength": len(blob), "uri": f"data:{mime};base64," + base64.b64encode(blob).decode()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 8},
            {"buffer": 0, "byteOffset": 44, "byteLength": 24},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]},
            {"bufferView": 2, "componentType": 5126, "count": 2, "type": "VEC3"},
        ],
    }
    if animate:
        document["animations"] = [
            {
                "name": "slide",
                "samplers": [{"input": 1, "output": 2}],
                "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
            }
        ]
    path = tmp_path / "triangle.gltf"
    path.write_text(json.dumps(document))
    return path


@pytest.mark.parametrize("mime", ["application/gltf-buffer", "application/octet-stream"])
def test_a_small_gltf_with_a_data_uri_of_either_type(tmp_path, mime):
    mesh = flockkit.io.read_mesh_animation(_gltf_document(tmp_path, mime=mime), fps=4)
    assert mesh.motion.n_frames == 5 and mesh.faces.tolist() == [[0, 1, 2]]
    np.testing.assert_allclose(mesh.motion.positions[:, 0, 0], [0, 0.5, 1, 1.5, 2])


def test_a_gltf_with_an_external_buffer(tmp_path):
    path = _gltf_document(tmp_path)
    document = json.loads(path.read_text())
    (tmp_path / "triangle data.bin").write_bytes(base64.b64decode(document["buffers"][0]["uri"].split(",", 1)[1]))
    document["buffers"][0]["uri"] = "triangle%20data.bin"  # a URI: spaces escaped
    path.write_text(json.dumps(document))
    mesh = flockkit.io.read_mesh_animation(path, fps=2)
    np.testing.assert_allclose(mesh.motion.positions[:, 1, 0], [1, 2, 3])
    (tmp_path / "triangle data.bin").write_bytes(b"\0" * 10)
    with pytest.raises(FileFormatError, match="holds 10 bytes"):
        flockkit.io.read_mesh_animation(path)


def test_bad_mesh_files_are_refused_naming_the_file(tmp_path, shared_data):
    junk = tmp_path / "junk.glb"
    junk.write_bytes(b"glTF" + b"\x02\x00\x00\x00" + b"\xff\x00\x00\x00" + b"nonsense")
    with pytest.raises(FileFormatError, match="junk.glb"):
        flockkit.io.read_mesh_animation(junk)
    truncated = tmp_path / "Fox.glb"
    truncated.write_bytes(fox(shared_data).read_bytes()[:100_000])
    with pytest.raises(FileFormatError, match="Fox.glb.*truncated"):
        flockkit.io.read_mesh_animation(truncated)
    text = tmp_path / "text.gltf"
    text.write_text("not json")
    with pytest.raises(FileFormatError, match="text.gltf: not a glTF 2.0 file"):
        flockkit.io.read_mesh_animation(text)
    with pytest.raises(ValidationError, match="has no animation"):
        flockkit.io.read_mesh_animation(_gltf_document(tmp_path, animate=False))
    with pytest.raises(ValidationError, match="unknown mesh animation format '.fbx'"):
        flockkit.io.read_mesh_animation(tmp_path / "model.fbx")
    with pytest.raises(ValidationError, match="fps"):
        flockkit.io.read_mesh_animation(fox(shared_data), fps=0)


def _write_obj(path, points, faces):
    lines = [f"v {x} {y} {z}" for x, y, z in points] + ["f " + " ".join(f"{i + 1}/1/1" for i in face) for face in faces]
    path.write_text("# a frame\n" + "\n".join(lines) + "\n")


def test_obj_sequences_in_natural_order(tmp_path):
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    for frame in (1, 2, 10):  # frame10 comes after frame2
        _write_obj(tmp_path / f"frame{frame}.obj", quad + [0, 0, frame], [[0, 1, 2, 3]])
    for source in (tmp_path, tmp_path / "frame*.obj"):
        mesh = flockkit.io.read_mesh_animation(source, fps=24)
        assert mesh.motion.n_frames == 3 and mesh.faces.tolist() == [[0, 1, 2, 3]] and mesh.motion.dt == 1 / 24
        np.testing.assert_array_equal(mesh.motion.positions[:, 0, 2], [1, 2, 10])
    _write_obj(tmp_path / "frame11.obj", quad[:3], [[0, 1, 2]])
    with pytest.raises(FileFormatError, match="frame11.obj: its topology differs from .*frame1.obj"):
        flockkit.io.read_mesh_animation(tmp_path)
    with pytest.raises(FileNotFoundError, match="no .obj files"):
        flockkit.io.read_mesh_animation(tmp_path / "none*.obj")


def test_usd_meshes_with_time_sampled_points(tmp_path):
    pxr = pytest.importorskip("pxr", reason="USD meshes need usd-core (flockkit[usd])")
    from pxr import Usd, UsdGeom

    path = tmp_path / "wave.usda"
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(24)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(24)
    xform = UsdGeom.Xform.Define(stage, "/World")
    xform.AddTranslateOp().Set((10.0, 0.0, 0.0))
    mesh = UsdGeom.Mesh.Define(stage, "/World/Sheet")
    mesh.GetFaceVertexCountsAttr().Set([4])
    mesh.GetFaceVertexIndicesAttr().Set([0, 1, 2, 3])
    for code in (0, 24):
        mesh.GetPointsAttr().Set([(0, 0, code / 24), (1, 0, 0), (1, 1, 0), (0, 1, 0)], Usd.TimeCode(code))
    stage.Save()
    assert pxr and flockkit.io.list_clips(path) == {"wave": 1.0}
    read = flockkit.io.read_mesh_animation(path, fps=4)
    assert read.motion.n_frames == 5 and read.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    np.testing.assert_allclose(read.motion.positions[:, 0], [[10, 0, z] for z in (0, 0.25, 0.5, 0.75, 1)])


def test_an_animated_mesh_saves_and_loads(tmp_path, shared_data):
    mesh = flockkit.io.read_mesh_animation(fox(shared_data), clip="Walk")
    mesh.save(tmp_path / "fox.npz")
    assert flockkit.AnimatedMesh.load(tmp_path / "fox.npz") == mesh
    with pytest.raises(FileFormatError, match="fox-motion.npz"):
        mesh.motion.save(tmp_path / "fox-motion.npz")
        flockkit.AnimatedMesh.load(tmp_path / "fox-motion.npz")
    with pytest.raises(ValidationError, match="faces must index vertices"):
        flockkit.AnimatedMesh(motion=mesh.motion, faces=[[0, 1, 5000]])
    nan = np.array(mesh.motion.positions)
    nan[3, 7] = np.nan
    with pytest.raises(ValidationError, match="finite"):
        flockkit.AnimatedMesh(motion=flockkit.Motion(positions=nan, dt=mesh.motion.dt), faces=mesh.faces)
