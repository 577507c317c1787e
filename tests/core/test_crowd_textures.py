"""Baked animation textures (flockkit.crowd.textures) on the real characters: the textures read back
give Crowd.poses and skin the mesh as linear blend skinning from those poses does, in every case
the runtime makes (whole frames, time dilation between frames, blends); the skinned mesh reader
agrees with the glTF reader's own skinning; the file layout is what an engine parses; the shader
compiles, and where software OpenGL runs, computes what the reference computes."""

import itertools
import json
import shutil
import struct
import subprocess

import numpy as np
import pytest

import flockkit
from flockkit.crowd import (
    TEXTURE_INSTANCE,
    AnimationTextures,
    Crowd,
    SkinnedMesh,
    Stream,
    StreamPool,
    UniquePool,
    bake_textures,
    instance_buffer,
    instances,
    read_skin,
    shader_source,
    skin,
    skinning_matrices,
)
from flockkit.crowd.textures import LOOP_TOLERANCE
from flockkit.errors import FileFormatError, ValidationError
from flockkit.io import read_clips, read_mesh_animation

FOX, ROBOT = "fox-gltf/Fox.glb", "robot-expressive-gltf/RobotExpressive.glb"
FPS = 24.0
# float32 precision, relative to the skeleton's size (the widest extent of its joints): what the
# textures' positions and skinned vertices may differ by from Crowd.poses and direct skinning
# (measured: at most 9e-7 for the Fox, 7e-7 for the robot)
TOLERANCE = 2e-6
# the rotation and scale part of world joint matrices, relative to its largest entry: Crowd.poses
# composes them in float32 down chains 8 (Fox) and 13 (robot) joints deep (measured: 3e-6)
LINEAR_TOLERANCE = 1e-5


def player(clip, **params):
    return flockkit.get("controller", "clip", clip=clip, **params)


@pytest.fixture(scope="module")
def characters(shared_data):
    found = {}
    for name, path in (("fox", FOX), ("robot", ROBOT)):
        clips = read_clips(shared_data / path)
        found[name] = (shared_data / path, clips, read_skin(shared_data / path))
    return found


def size_of(skeleton, world):
    return float(np.ptp(np.asarray(world)[..., :3, 3], axis=-2).max())


# (stream clips, their defaults) and the transitions a run makes: (frame, agents, stream,
# blend seconds, time_to_dilate)
SCENARIOS = {
    "fox": (
        [("Walk", "Running"), ("Run", "Running"), ("Survey", "Stopped")],
        [(12, slice(0, 30), 1, 0.5, None), (30, slice(30, 60), 2, 1.0, 1.5), (50, slice(0, 90, 4), 0, 0.75, None)],
    ),
    "robot": (
        [("Idle", "Running"), ("Walking", "Running"), ("Wave", "Stopped"), ("Dance", "Stopped")],
        [(10, slice(0, 20), 2, 0.5, 1.5), (30, slice(10, 40), 3, 1.0, None), (45, slice(0, 60, 3), 1, 0.75, None)],
    ),
}


def run_crowd(clips, mesh, scenario, n_agents, frames, seconds):
    streams, transitions = scenario
    pool = StreamPool(
        [Stream(controller=player(clips[name]), history=36, name=name, default=default) for name, default in streams],
        fps=FPS,
    )
    textures = bake_textures(pool, seconds=seconds, inverse_bind=mesh)
    crowd = Crowd(pool, n_agents=n_agents, clusters={"body": np.arange(n_agents) % 2}, seed=4)
    for frame in range(frames):
        for at, agents, stream, blend, dilate in transitions:
            if frame == at:
                crowd.transition_to_streamed(np.arange(n_agents)[agents], "body", stream, blend, time_to_dilate=dilate)
        crowd.update()
        yield crowd, textures


@pytest.mark.parametrize("name", ["fox", "robot"])
def test_textures_read_back_give_the_crowds_poses_and_skin_its_mesh(characters, name):
    _, clips, mesh = characters[name]
    inverse = None
    seen = {"steady": 0, "dilating": 0, "blending": 0}
    worst = {"linear": 0.0, "translation": 0.0, "mesh": 0.0}
    for frame, (crowd, textures) in enumerate(run_crowd(clips, mesh, SCENARIOS[name], 60, 100, seconds=100 / FPS)):
        if frame % 3:
            continue
        inverse = np.linalg.inv(textures.inverse_bind) if inverse is None else inverse
        records = instance_buffer(crowd, textures)
        assert records.dtype == TEXTURE_INSTANCE and len(records) == 60 and records["visible"].all()
        world = crowd.poses(space="world").astype(np.float64)
        size = size_of(crowd.skeletons[0], world)
        matrices = skinning_matrices(textures, records)
        back = np.concatenate([matrices, np.broadcast_to([0.0, 0, 0, 1], matrices.shape[:2] + (1, 4))], axis=2)
        back = back @ inverse  # the parts' world joint matrices
        scale = np.abs(world[..., :3, :3]).max()
        worst["linear"] = max(worst["linear"], np.abs(back[..., :3, :3] - world[..., :3, :3]).max() / scale)
        worst["translation"] = max(worst["translation"], np.abs(back[..., :3, 3] - world[..., :3, 3]).max() / size)
        worst["mesh"] = max(worst["mesh"], np.abs(skin(textures, records, mesh) - mesh.skinned(world)).max() / size)
        blending = records["weight"] > 0
        between = records["fractions"][:, 0] > 0
        seen["blending"] += int(blending.sum())
        seen["dilating"] += int((between & ~blending).sum())
        seen["steady"] += int((~between & ~blending).sum())
    assert min(seen.values()) > 50, seen  # every path of the shader was taken, many times
    assert worst["linear"] < LINEAR_TOLERANCE and max(worst["translation"], worst["mesh"]) < TOLERANCE, worst


def test_steady_records_read_the_stream_frame_the_pool_wrote(characters):
    _, clips, mesh = characters["fox"]
    *_, (crowd, textures) = run_crowd(clips, mesh, (SCENARIOS["fox"][0], []), 20, 30, seconds=2)
    records = instance_buffer(crowd, textures)
    buffer = crowd.instance_buffer()[:, 0]
    frame = crowd.pool.clock[buffer["stream"]] - 1 - buffer["offset"]
    period = textures.periods[buffer["stream"]]
    np.testing.assert_allclose(records["frame"], np.where(period > 0, frame % np.maximum(period, 1), frame))
    assert np.array_equal(records["texture"], buffer["stream"]) and (records["target"] == -1).all()
    np.testing.assert_array_equal(records["rows"][:, 0], textures.starts[records["texture"]] + records["frame"])


def test_streams_that_repeat_keep_one_loop_and_others_the_whole_run(characters):
    _, clips, mesh = characters["fox"]
    pool = StreamPool(
        [
            Stream(controller=player(clips["Walk"]), history=30),  # 0.7083 s: 17 frames at 24 fps
            Stream(controller=player(clips["Walk"], rate=0.5), history=30),  # 34 frames
            Stream(controller=player(clips["Run"]), history=30),  # 1.1583 s: 27.8 frames, no loop
        ],
        fps=FPS,
    )
    textures = bake_textures(pool, seconds=10, inverse_bind=mesh)
    assert textures.periods.tolist() == [17, 34, 0]
    assert textures.lengths.tolist() == [18, 35, 30 + 240]
    # over 60 s the walk's float32 length drifts it past LOOP_TOLERANCE: baked whole, unless asked
    assert bake_textures(pool, seconds=60, inverse_bind=mesh).periods.tolist() == [0, 0, 0]
    assert bake_textures(pool, seconds=60, inverse_bind=mesh, loop_tolerance=1e-4).periods.tolist() == [17, 34, 139]
    # a loop's frame k + P is its frame k: the pool writes the same pose there
    walk = pool.streams[0].controller.pose(np.arange(200) / FPS)
    kept = textures.rotations[textures.starts[0] + np.arange(200) % 17]
    assert np.abs(np.abs(np.sum(kept * walk.rotations, axis=-1)) - 1).max() < LOOP_TOLERANCE


def test_clip_textures_are_the_gltf_readers_skinning_at_every_frame(characters):
    path, clips, mesh = characters["fox"]
    for fps in (24.0, 30.0):  # the keys' rate, and one between them
        textures = bake_textures([clips["Survey"], clips["Walk"]], fps=fps, inverse_bind=mesh)
        assert textures.names == ("Survey", "Walk")
        reference = read_mesh_animation(path, clip="Walk", fps=fps).motion.positions
        frames = np.arange(len(reference))
        positions = skin(textures, instances(textures, np.ones(len(frames), int), frames), mesh)
        size = np.ptp(reference, axis=1).max()
        assert np.abs(positions - reference).max() < TOLERANCE * size


def test_skinned_mesh_agrees_with_the_gltf_readers_own_skinning(characters):
    for name, clip in (("fox", "Walk"), ("robot", "Walking")):
        path, clips, mesh = characters[name]
        mesh.check_skeleton(clips[clip].skeleton)
        reference = read_mesh_animation(path, clip=clip, fps=FPS)
        world = clips[clip].skeleton.world(clips[clip].sample(np.arange(len(reference.motion.positions)) / FPS))
        assert np.abs(mesh.skinned(world) - reference.motion.positions).max() < 1e-9
        assert np.array_equal(mesh.faces, reference.faces)
    fox, robot = characters["fox"][2], characters["robot"][2]
    assert (fox.n_vertices, fox.joints.shape[1], fox.normals) == (1728, 4, None)
    assert robot.n_vertices == 7214 and robot.normals.shape == (7214, 3)
    assert (robot.weights[:, 1:] == 0).mean() > 0.5  # the robot's rigid parts follow one joint


def test_save_writes_the_documented_layout_and_load_reads_it_back(characters, tmp_path):
    _, clips, mesh = characters["robot"]
    textures = bake_textures([clips["Idle"], clips["Wave"]], inverse_bind=mesh)
    path = tmp_path / "robot.bin"
    textures.save(path)
    assert [p.name for p in tmp_path.iterdir()] == ["robot.bin"]  # nothing half-written beside it
    data = path.read_bytes()
    # what an engine does: magic, version, header length, JSON, then the arrays where it says
    assert data[:8] == b"FKANIMTX"
    version, size = struct.unpack_from("<II", data, 8)
    header = json.loads(data[16 : 16 + size])
    assert (version, header["version"], (16 + size) % 16) == (1, 1, 0)
    assert [t["name"] for t in header["textures"]] == ["Idle", "Wave"] and header["fps"] == textures.fps
    for name, expected in (("texels", textures.texels), ("skeleton", textures.skeleton_texels)):
        entry = header["arrays"][name]
        raw = np.frombuffer(data, "<f4", count=int(np.prod(entry["shape"])), offset=entry["offset"])
        assert entry["offset"] % 16 == 0 and np.array_equal(raw.reshape(entry["shape"]), expected)
    loaded = AnimationTextures.load(path)
    for field in ("texels", "starts", "lengths", "periods", "inverse_bind"):
        assert np.array_equal(getattr(loaded, field), getattr(textures, field)), field
    assert loaded.skeleton.matches(textures.skeleton) and loaded.names == textures.names
    np.testing.assert_array_equal(loaded.skeleton.scales, textures.skeleton.scales)
    records = instances(loaded, [0, 1], [3.25, 7.0], target=[1, -1], target_frame=[2.5, 0], weight=[0.4, 0])
    np.testing.assert_array_equal(skin(loaded, records, mesh), skin(textures, records, mesh))


def test_load_refuses_what_is_not_a_whole_textures_file(characters, tmp_path):
    _, clips, mesh = characters["fox"]
    good = tmp_path / "fox.bin"
    bake_textures([clips["Walk"]], inverse_bind=mesh).save(good)
    data = good.read_bytes()
    size = struct.unpack_from("<I", data, 12)[0]
    header = json.loads(data[16 : 16 + size])

    def broken(payload: bytes, match: str):
        bad = tmp_path / "bad.bin"
        bad.write_bytes(payload)
        with pytest.raises(FileFormatError, match=match):
            AnimationTextures.load(bad)

    def with_header(change) -> bytes:
        edited = json.loads(json.dumps(header))
        change(edited)
        text = json.dumps(edited).encode().ljust(size)
        assert len(text) == size
        return data[:16] + text + data[16 + size :]

    broken(data[:-100], "runs past the end of the file")
    broken(b"PK\x03\x04" + data[4:], "not a flockkit animation textures file")
    broken(data[:8] + struct.pack("<I", 9) + data[12:], "version 9 is not supported")
    broken(data[:12] + struct.pack("<I", 10**9) + data[16:], "header length")
    broken(data[:16] + b"x" + data[17:], "corrupt header")
    broken(with_header(lambda h: h["arrays"]["texels"].update(offset=-16)), "arrays.texels.offset")
    broken(with_header(lambda h: h["arrays"]["texels"].update(dtype="<f8")), "dtype")
    broken(with_header(lambda h: h["textures"][0].update(start=0.5)), "starts must be an array of integers")
    broken(with_header(lambda h: h["textures"][0].update(length=10**6)), "starts and lengths")
    broken(with_header(lambda h: h["skeleton"].update(parents=[5] * len(h["skeleton"]["parents"]))), "parents")
    broken(with_header(lambda h: h.pop("fps")), "fps")


def test_refused_inputs_name_what_is_wrong(characters):
    _, clips, mesh = characters["fox"]
    _, robot_clips, robot_mesh = characters["robot"]
    walk = clips["Walk"]
    unique = UniquePool(1, max_bones=walk.skeleton.n_joints, fps=FPS)
    unique.set(0, player(walk))
    pool = StreamPool([Stream(controller=player(walk), history=10), Stream(controller=player(clips["Run"]),
                                                                          history=10)], fps=FPS)  # fmt: skip
    crowd = Crowd(pool, n_agents=4, clusters={"body": [0, 1, 1, 0]}, unique=unique, seed=0)
    short = bake_textures(pool, seconds=0.5, inverse_bind=mesh)
    with pytest.raises(ValidationError, match="seconds"):
        bake_textures(pool)
    with pytest.raises(ValidationError, match="another skeleton"):
        bake_textures([walk, robot_clips["Idle"]])
    with pytest.raises(ValidationError, match="inverse_bind must have shape"):
        bake_textures([walk], inverse_bind=np.eye(4))
    with pytest.raises(ValidationError, match="read both from one file"):
        bake_textures([walk], inverse_bind=robot_mesh)
    with pytest.raises(ValidationError, match="2 textures at 24 fps; the crowd's pool has 2 streams at 30"):
        other = StreamPool([Stream(controller=player(walk), history=10)] * 2, fps=30)
        instance_buffer(Crowd(other, n_agents=2, clusters={"body": 0}), short)
    for _ in range(24):  # 1 s: past the half second the Run stream was baked for
        crowd.update()
    with pytest.raises(ValidationError, match=r"stream \d is at frame .*: bake with more seconds"):
        instance_buffer(crowd, short)
    textures = bake_textures(pool, seconds=5, inverse_bind=mesh)
    crowd.transition_to_unique([2], "body", 0, 0.5)
    with pytest.raises(ValidationError, match="agent 2's part 'body' reads a unique slot"):
        instance_buffer(crowd, textures)
    with pytest.raises(ValidationError, match="skin: mesh"):
        skin(textures, instances(textures, [0], [0]), robot_mesh)
    with pytest.raises(ValidationError, match="TEXTURE_INSTANCE"):
        skin(textures, np.zeros(3), mesh)
    with pytest.raises(ValidationError, match="target must be texture indices"):
        instances(textures, [0], [0], target=[5])
    with pytest.raises(ValidationError, match="frame must be finite"):
        instances(textures, [0], [np.nan])
    with pytest.raises(ValidationError, match="has no normals"):
        skin(textures, instances(textures, [0], [0]), mesh, normals=True)
    with pytest.raises(ValidationError, match="SkinnedMesh.weights"):
        SkinnedMesh(joint_names=["a"], positions=[[0, 0, 0]], faces=np.zeros((0, 3), int), joints=[[0]],
                    weights=[[0.5]], inverse_bind=[np.eye(4)])  # fmt: skip
    with pytest.raises(ValidationError, match="no skin 'hands'"):
        read_skin(characters["robot"][0], skin="hands")


def test_instances_wrap_loops_and_hold_the_ends_of_clips_played_once(characters):
    _, clips, mesh = characters["fox"]
    pool = StreamPool([Stream(controller=player(clips["Walk"]), history=10),
                       Stream(controller=player(clips["Run"]), history=10)], fps=FPS)  # fmt: skip
    textures = bake_textures(pool, seconds=2, inverse_bind=mesh)
    records = instances(textures, [0, 0, 1, 1, -1], [17 * 3 + 2.5, -0.5, 100.0, -3.0, 0.0])
    np.testing.assert_allclose(records["frame"], [2.5, 16.5, 57.0, 0.0, 0.0])
    a, b = textures.starts
    assert records["rows"][:, :2].tolist() == [[a + 2, a + 3], [a + 16, a + 17], [b + 57, b + 57], [b, b + 1],
                                               [-1, -1]]  # fmt: skip
    np.testing.assert_allclose(records["fractions"][:, 0], [0.5, 0.5, 0, 0, 0])
    assert np.isnan(skin(textures, records, mesh)[4]).all()  # no part: nothing drawn


def test_the_shader_compiles_as_glsl_330():
    validator = shutil.which("glslangValidator")
    if validator is None:
        pytest.skip("glslangValidator is not installed (Debian: apt-get install glslang-tools)")
    source = shader_source()
    assert source.startswith("#version 330 core")
    done = subprocess.run([validator, "--stdin", "-S", "vert"], input=source, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def _software_gl():
    """A headless OpenGL context (Mesa's llvmpipe through EGL, by moderngl), or a skip."""
    moderngl = pytest.importorskip("moderngl", reason="moderngl runs the shader in software OpenGL")
    try:
        context = moderngl.create_context(standalone=True, backend="egl")
    except Exception as exc:  # noqa: BLE001 - no EGL, no GPU driver, no Mesa: the reason is in the message
        pytest.skip(f"no headless OpenGL context: {exc}")
    context.simple_framebuffer((4, 4)).use()  # transform feedback still needs a framebuffer bound
    return moderngl, context


def run_shader(textures, records, mesh):
    """The shader's gl_Position and v_normal for every instance and vertex, by transform feedback,
    with identity roots and view-projection: model-space positions, as skin gives them."""
    moderngl, context = _software_gl()
    try:
        program = context.program(vertex_shader=shader_source(), varyings=["gl_Position", "v_normal"])
        frames, joints = textures.texels.shape[:2]
        context.texture((5 * joints, frames), 4, np.ascontiguousarray(textures.texels).tobytes(), dtype="f4").use(0)
        context.texture((4 * joints, 1), 4, textures.skeleton_texels.tobytes(), dtype="f4").use(1)
        program["u_animation"], program["u_skeleton"] = 0, 1
        program["u_view_projection"].write(np.eye(4, dtype="f4").tobytes())
        vertices = np.zeros(mesh.n_vertices, dtype=[("p", "f4", 3), ("n", "f4", 3), ("j", "i4", 4), ("w", "f4", 4)])
        vertices["p"], vertices["n"], vertices["j"], vertices["w"] = (
            mesh.positions, mesh.normals, mesh.joints, mesh.weights)  # fmt: skip
        parts = np.zeros(len(records), dtype=[("rows", "i4", 4), ("blend", "f4", 3), ("root", "f4", 16)])
        parts["rows"] = records["rows"]
        parts["blend"] = np.column_stack([records["fractions"], records["weight"]])
        parts["root"] = np.eye(4, dtype="f4").reshape(-1)
        array = context.vertex_array(program, [
            (context.buffer(vertices.tobytes()), "3f 3f 4i 4f", "a_position", "a_normal", "a_joints", "a_weights"),
            (context.buffer(parts.tobytes()), "4i 3f 16f/i", "a_rows", "a_blend", "a_root"),
        ])  # fmt: skip
        out = context.buffer(reserve=len(records) * mesh.n_vertices * 7 * 4)
        array.transform(out, mode=moderngl.POINTS, vertices=mesh.n_vertices, instances=len(records))
        data = np.frombuffer(out.read(), dtype="f4").reshape(len(records), mesh.n_vertices, 7).astype(np.float64)
    finally:
        context.release()
    return data[..., :3] / data[..., 3:4], data[..., 4:]


def test_the_shader_computes_what_the_reference_computes(characters):
    """The GLSL run by Mesa's software OpenGL (float32) against skin (float64), on the robot (46
    joints, 13 deep, rigid and skinned meshes, normals) mid-run: whole frames, dilation, blends."""
    _, clips, mesh = characters["robot"]
    crowd, textures = next(itertools.islice(run_crowd(clips, mesh, SCENARIOS["robot"], 48, 40, seconds=2), 34, None))
    records = instance_buffer(crowd, textures)
    kinds = (records["weight"] > 0, (records["fractions"][:, 0] > 0) & (records["weight"] == 0))
    assert all(k.any() for k in kinds) and (~kinds[0] & ~kinds[1]).any()
    positions, normals = run_shader(textures, records, mesh)
    expected, expected_normals = skin(textures, records, mesh, normals=True)
    size = np.ptp(expected, axis=1).max()
    assert np.abs(positions - expected).max() < TOLERANCE * size
    assert np.abs(normals - expected_normals).max() < 1e-4
    hidden = records.copy()
    hidden["rows"][0] = -1
    assert (run_shader(textures, hidden, mesh)[0][0] == [0, 0, 2]).all()  # moved out of the clip volume
