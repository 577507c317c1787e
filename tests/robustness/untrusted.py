"""Files written to harm, and arguments that ask for the machine: every case of the untrusted-assets
review, as (area, name, call, expected). `expected` is "named" (a documented flockkit error; for
files, FileFormatError or ValidationError naming the file) or "ok" (a correct read). The tests run
each under a 10 s limit and watch the peak memory; ``python -m tests.robustness.tally`` counts them
per area."""

from __future__ import annotations

import json
import math
import os
import struct
import zipfile
from pathlib import Path

import numpy as np

import flockkit
from flockkit import io as fio

from . import assets

SECRET = [1234.5, 2345.5, 3456.5] * 3  # float32 positions no asset of ours holds


def plant_secret(folder: Path) -> Path:
    """A folder `asset` inside `folder`, and beside it `secret.bin`: 36 bytes that read as three
    vertices at 1234.5, 2345.5, 3456.5. Returns the asset folder."""
    (folder / "secret.bin").write_bytes(assets.floats(SECRET))
    (folder / "secret.obj").write_text("v 1234.5 2345.5 3456.5\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    asset = folder / "asset"
    asset.mkdir(exist_ok=True)
    return asset


def escape(asset: Path, uri: str) -> Path:
    """A glTF in `asset` whose positions come from buffer 1, at `uri`."""
    document, buffer = assets.tiny()
    document = {k: v for k, v in document.items() if k not in ("skins", "animations")}
    document["nodes"] = [{"mesh": 0}]
    document["scenes"] = [{"nodes": [0]}]
    document["meshes"] = [{"primitives": [{"attributes": {"POSITION": 0}}]}]
    document["buffers"].append({"byteLength": 36, "uri": uri})
    document["bufferViews"].append({"buffer": 1, "byteOffset": 0, "byteLength": 36})
    document["accessors"][0]["bufferView"] = len(document["bufferViews"]) - 1
    document["animations"] = [{"samplers": [{"input": 6, "output": 8}],
                               "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}]}]  # fmt: skip
    path = asset / f"escape{abs(hash(uri)) % 10**8}.gltf"
    assets.write(path, document, buffer)
    return path


ESCAPES = [
    "../secret.bin",
    "../../../../../../../../../etc/passwd",
    "..%2Fsecret.bin",
    "..%2fsecret.bin",
    "%2E%2E/secret.bin",
    "sub/../../secret.bin",
    "..\\secret.bin",
    "/proc/self/environ",
    "file:///etc/passwd",
    "link.bin",  # a symlink inside the folder to the secret
    "zero.bin",  # a symlink inside the folder to /dev/zero
    "fifo.bin",  # a FIFO
    "folder.bin",  # a folder
]


def escapes(folder: Path) -> list[tuple[str, Path]]:
    """(uri, glTF path) for every way out of an asset folder, made in `folder`."""
    asset = plant_secret(folder)
    (asset / "sub").mkdir(exist_ok=True)
    for name, target in (("link.bin", folder / "secret.bin"), ("zero.bin", Path("/dev/zero"))):
        if not (asset / name).is_symlink():
            (asset / name).symlink_to(target)
    if not (asset / "fifo.bin").exists():
        os.mkfifo(asset / "fifo.bin")
    (asset / "folder.bin").mkdir(exist_ok=True)
    found = [(uri, escape(asset, uri)) for uri in ESCAPES]
    found.append(("absolute", escape(asset, str((folder / "secret.bin").resolve()))))
    return found


def _gltf(folder: Path, name: str, change=None, *, suffix=".gltf", buffer_change=None) -> Path:
    document, buffer = assets.tiny()
    if change is not None:
        change(document)
    if buffer_change is not None:
        buffer_change(document, buffer)
    path = folder / f"{name}{suffix}"
    assets.write(path, document, buffer)
    return path


def _set(path: str, value):
    """A change to the document: the JSON value at `path` ("accessors[0].count") set to `value`."""

    def change(document):
        keys = [int(k) if k.isdigit() else k for k in path.replace("[", ".").replace("]", "").split(".")]
        target = document
        for key in keys[:-1]:
            target = target[key]
        target[keys[-1]] = value

    return change


def _drop(path: str):
    def change(document):
        keys = [int(k) if k.isdigit() else k for k in path.replace("[", ".").replace("]", "").split(".")]
        target = document
        for key in keys[:-1]:
            target = target[key]
        del target[keys[-1]]

    return change


def _keys(values):
    """A buffer change: the animation's key times (accessor 6) replaced by `values`."""

    def change(document, buffer):
        start = assets.offset(document, 6)
        buffer[start : start + 12] = assets.floats(values)

    return change


def _bytes(accessor: int, data: bytes):
    def change(document, buffer):
        start = assets.offset(document, accessor)
        buffer[start : start + len(data)] = data

    return change


# (name, change to the JSON) of a damaged tiny asset; each must be a FileFormatError naming it
JSON_DAMAGE = [
    ("asset is a list", _set("asset", [])),
    ("no asset", _drop("asset")),
    ("asset version 1.0", _set("asset.version", "1.0")),
    ("buffers is a string", _set("buffers", "x")),
    ("buffer uri 5", _set("buffers[0].uri", 5)),
    ("buffer byteLength -1", _set("buffers[0].byteLength", -1)),
    ("buffer byteLength 1.5", _set("buffers[0].byteLength", 1.5)),
    ("buffer byteLength 1e12", _set("buffers[0].byteLength", 10**12)),
    ("view buffer 7", _set("bufferViews[0].buffer", 7)),
    ("view buffer -1", _set("bufferViews[0].buffer", -1)),
    ("view byteOffset -4", _set("bufferViews[0].byteOffset", -4)),
    ("view byteLength 0", _set("bufferViews[0].byteLength", 0)),
    ("view byteLength 1e9", _set("bufferViews[0].byteLength", 10**9)),
    ("view byteStride -4096", _set("bufferViews[0].byteStride", -4096)),
    ("view byteStride -1000000", _set("bufferViews[0].byteStride", -1_000_000)),
    ("view byteStride 2", _set("bufferViews[0].byteStride", 2)),
    ("view byteStride 6", _set("bufferViews[0].byteStride", 6)),
    ("view byteStride 256", _set("bufferViews[0].byteStride", 256)),
    ("view byteStride 4 (overlapping)", _set("bufferViews[0].byteStride", 4)),
    ("accessor count 0", _set("accessors[0].count", 0)),
    ("accessor count -1", _set("accessors[0].count", -1)),
    ("accessor count 1.5", _set("accessors[0].count", 1.5)),
    ("accessor count '3'", _set("accessors[0].count", "3")),
    ("accessor count 1e9", _set("accessors[0].count", 10**9)),
    ("accessor componentType 5124", _set("accessors[0].componentType", 5124)),
    ("accessor componentType 5126.0", _set("accessors[0].componentType", 5126.0)),
    ("accessor componentType true", _set("accessors[0].componentType", True)),
    ("accessor type VEC5", _set("accessors[0].type", "VEC5")),
    ("accessor byteOffset -1", _set("accessors[0].byteOffset", -1)),
    ("accessor byteOffset 1e6", _set("accessors[0].byteOffset", 10**6)),
    ("accessor bufferView 99", _set("accessors[0].bufferView", 99)),
    ("accessor bufferView -1", _set("accessors[0].bufferView", -1)),
    ("accessor normalized 'yes'", _set("accessors[0].normalized", "yes")),
    ("normalized floats", _set("accessors[0].normalized", True)),
    (
        "POSITION of 4e8 zeros without data",
        lambda d: d["accessors"][0].update(count=400_000_000, bufferView=None) or d["accessors"][0].pop("bufferView"),
    ),  # fmt: skip
    (
        "sparse count 0",
        _set(
            "accessors[0].sparse",
            {"count": 0, "indices": {"bufferView": 1, "componentType": 5123}, "values": {"bufferView": 0}},
        ),
    ),  # fmt: skip
    (
        "sparse count above count",
        _set(
            "accessors[0].sparse",
            {"count": 9, "indices": {"bufferView": 1, "componentType": 5123}, "values": {"bufferView": 0}},
        ),
    ),  # fmt: skip
    (
        "sparse signed indices",
        _set(
            "accessors[0].sparse",
            {"count": 2, "indices": {"bufferView": 2, "componentType": 5120}, "values": {"bufferView": 0}},
        ),
    ),  # fmt: skip
    (
        "sparse float indices",
        _set(
            "accessors[0].sparse",
            {"count": 1, "indices": {"bufferView": 4, "componentType": 5126}, "values": {"bufferView": 0}},
        ),
    ),  # fmt: skip
    (
        "sparse indices out of order",
        _set(
            "accessors[0].sparse",
            {"count": 3, "indices": {"bufferView": 2, "componentType": 5121}, "values": {"bufferView": 0}},
        ),
    ),  # fmt: skip
    ("node child itself", _set("nodes[2].children", [2])),
    ("node child 99", _set("nodes[2].children", [99])),
    ("node child -1", _set("nodes[2].children", [-1])),
    ("node child twice", _set("nodes[0].children", [1, 3, 1])),
    ("node children 'x'", _set("nodes[0].children", "x")),
    ("a cycle of nodes", _set("nodes[2].children", [1])),
    ("a node with two parents", _set("nodes[2].children", [3])),
    ("node mesh 5", _set("nodes[3].mesh", 5)),
    ("node mesh -1", _set("nodes[3].mesh", -1)),
    ("node skin 9", _set("nodes[3].skin", 9)),
    ("node matrix of 15", _set("nodes[1].matrix", [1.0] * 15)),
    ("node matrix and translation", _set("nodes[2].matrix", np.eye(4).ravel().tolist())),
    ("node rotation of length 0", _set("nodes[1].rotation", [0, 0, 0, 0])),
    ("node translation of 2", _set("nodes[1].translation", [1, 2])),
    ("node translation 'a'", _set("nodes[1].translation", ["a", 0, 0])),
    ("node scale NaN", _set("nodes[1].scale", [float("nan"), 1, 1])),
    ("node translation a 400-digit integer", _set("nodes[1].translation", [10**400, 0, 0])),
    ("mesh weights a 400-digit integer", _set("meshes[0].weights", [10**400])),
    ("node name 5", _set("nodes[1].name", 5)),
    ("scene -1", _set("scene", -1)),
    ("scene 5", _set("scene", 5)),
    ("scene 1.5", _set("scene", 1.5)),
    ("scene nodes a child", _set("scenes[0].nodes", [3])),
    ("scene nodes -1", _set("scenes[0].nodes", [-1])),
    ("scene nodes 'x'", _set("scenes[0].nodes", "x")),
    ("no primitives", _set("meshes[0].primitives", [])),
    ("primitives 'x'", _set("meshes[0].primitives", "x")),
    ("POSITION 99", _set("meshes[0].primitives[0].attributes.POSITION", 99)),
    ("POSITION of VEC4", _set("meshes[0].primitives[0].attributes.POSITION", 3)),
    ("no POSITION", _drop("meshes[0].primitives[0].attributes.POSITION")),
    ("indices 99", _set("meshes[0].primitives[0].indices", 99)),
    ("indices of floats", _set("meshes[0].primitives[0].indices", 6)),
    ("mode 9", _set("meshes[0].primitives[0].mode", 9)),
    ("mode -1", _set("meshes[0].primitives[0].mode", -1)),
    ("targets 'x'", _set("meshes[0].primitives[0].targets", "x")),
    ("target POSITION 99", _set("meshes[0].primitives[0].targets", [{"POSITION": 99}])),
    ("mesh weights of 2", _set("meshes[0].weights", [0.5, 0.5])),
    ("skin joints empty", _set("skins[0].joints", [])),
    ("skin joint -1", _set("skins[0].joints", [-1, 2])),
    ("skin joint twice", _set("skins[0].joints", [1, 1])),
    ("skin joint 99", _set("skins[0].joints", [1, 99])),
    ("inverse bind matrices of VEC3", _set("skins[0].inverseBindMatrices", 0)),
    ("no WEIGHTS_0 on a skinned mesh", _drop("meshes[0].primitives[0].attributes.WEIGHTS_0")),
    ("JOINTS_0 of floats", _set("meshes[0].primitives[0].attributes.JOINTS_0", 3)),
    ("sampler input 99", _set("animations[0].samplers[0].input", 99)),
    ("sampler input -1", _set("animations[0].samplers[0].input", -1)),
    ("sampler input of VEC3", _set("animations[0].samplers[0].input", 0)),
    ("sampler output 99", _set("animations[0].samplers[0].output", 99)),
    ("interpolation FOO", _set("animations[0].samplers[0].interpolation", "FOO")),
    ("interpolation 5", _set("animations[0].samplers[0].interpolation", 5)),
    ("channel sampler 9", _set("animations[0].channels[0].sampler", 9)),
    ("channel sampler -1", _set("animations[0].channels[0].sampler", -1)),
    ("channel node 99", _set("animations[0].channels[0].target.node", 99)),
    ("channel node -1", _set("animations[0].channels[0].target.node", -1)),
    ("channel path color", _set("animations[0].channels[0].target.path", "color")),
    ("one target animated twice", _set("animations[0].channels[1].target", {"node": 2, "path": "rotation"})),
    ("a rotation channel of VEC3", _set("animations[0].samplers[0].output", 8)),
    (
        "a matrix node animated",
        lambda d: d["nodes"][2].update(matrix=np.eye(4).ravel().tolist()) or d["nodes"][2].pop("translation"),
    ),  # fmt: skip
    ("weights on a node without targets", _set("animations[0].channels[2].target.node", 2)),
    ("CUBICSPLINE with too few values", _set("animations[0].samplers[2].output", 6)),
    ("no samplers", _set("animations[0].samplers", [])),
    ("channels 'x'", _set("animations[0].channels", "x")),
    ("extension required: draco", _set("extensionsRequired", ["KHR_draco_mesh_compression"])),
]

# (name, change to the buffer): key times, indices and joints out of their ranges
BUFFER_DAMAGE = [
    ("key times decreasing", _keys([0.0, 1.0, 0.5])),
    ("key times repeated", _keys([0.0, 0.5, 0.5])),
    ("key time negative", _keys([-1.0, 0.5, 1.0])),
    ("key time NaN", _keys([0.0, float("nan"), 1.0])),
    ("key time inf", _keys([0.0, 0.5, float("inf")])),
    ("index 7 of 3 vertices", _bytes(1, struct.pack("<3H", 0, 1, 7))),
    ("joint 5 of 2", _bytes(2, bytes([5, 0, 0, 0]))),
    ("position NaN", _bytes(0, assets.floats([float("nan")]))),
]


def _deep_json(folder: Path) -> Path:
    path = folder / "deep.gltf"
    path.write_text('{"asset": {"version": "2.0"}, "extras": ' + "[" * 100_000 + "]" * 100_000 + "}")
    return path


def _bvh(folder: Path, name: str, text: str) -> Path:
    path = folder / f"{name}.bvh"
    path.write_text(text)
    return path


def _nested_bvh(joints: int) -> str:
    lines = ["HIERARCHY", "ROOT j0", "{", "OFFSET 0 0 0", "CHANNELS 3 Zrotation Yrotation Xrotation"]
    for k in range(1, joints):
        lines += [f"JOINT j{k}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Yrotation Xrotation"]
    lines += ["}"] * joints
    return "\n".join(lines + ["MOTION", "Frames: 2", "Frame Time: 0.0333", " ".join(["0"] * 6 * joints)]) + "\n"


def _many_nodes(folder: Path, extra: int) -> Path:
    def change(document):
        start = len(document["nodes"])
        document["nodes"] += [{"name": f"extra {k}", "children": [start + k + 1]} for k in range(extra - 1)]
        document["nodes"].append({"name": "last"})
        document["scenes"][0]["nodes"].append(start)

    return _gltf(folder, f"nodes{extra}", change, suffix=".glb")


def _npz_bomb(folder: Path, declared: int) -> Path:
    """An npz whose one array holds `declared` bytes of zeros, deflated to a few bytes each MiB."""
    path = folder / "bomb.npz"
    header = {"descr": "<f8", "fortran_order": False, "shape": (declared // 8,)}
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        with archive.open("positions.npy", "w", force_zip64=True) as handle:
            from numpy.lib import format as npy

            npy.write_array_header_1_0(handle, header)
            chunk = b"\0" * (1 << 24)
            for _ in range(declared // len(chunk)):
                handle.write(chunk)
            handle.write(b"\0" * (declared % len(chunk)))
        metadata = json.dumps({"format": "motion", "version": 1, "dt": 0.1}).encode()
        with archive.open("__metadata__.npy", "w") as handle:
            np.lib.format.write_array(handle, np.frombuffer(metadata, dtype=np.uint8))
    return path


def _flockkit_file(folder: Path, name: str, kind: str, arrays: dict, metadata: dict) -> Path:
    from flockkit import _npzfile

    path = folder / f"{name}.npz"
    _npzfile.write(path, kind=kind, version=1, arrays=arrays, metadata=metadata)
    return path


def _obj_folder(folder: Path, name: str, extra) -> Path:
    sequence = folder / name
    sequence.mkdir(exist_ok=True)
    (sequence / "frame0.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    extra(sequence)
    return sequence


def _obj(folder: Path, name: str, text: str) -> Path:
    path = folder / f"{name}.obj"
    path.write_text(text)
    return path


def _stream(history=4, default="Running"):
    from flockkit.crowd import Stream

    return Stream(controller=flockkit.get("controller", "clip", clip=_tiny_clip()), history=history, default=default)


def _tiny_clip():
    skeleton = flockkit.Skeleton(names=["root", "tip"], parents=[-1, 0])
    frames = 24
    angles = np.linspace(0, np.pi, frames)
    rotations = np.zeros((frames, 2, 4))
    rotations[:, :, 3] = 1.0
    rotations[:, 1, 2], rotations[:, 1, 3] = np.sin(angles / 2), np.cos(angles / 2)
    return flockkit.SkeletalClip(skeleton=skeleton, fps=24, rotations=rotations, translations=np.zeros((frames, 3)))


def cases(folder: Path) -> list[tuple[str, str, object, str]]:
    """(area, name, call, expected) for every case; files are made in `folder` as the list is."""
    from flockkit.crowd import Crowd, StreamPool, UniquePool

    folder.mkdir(parents=True, exist_ok=True)
    read = fio.read_mesh_animation
    found = []
    for uri, path in escapes(folder):
        found.append(("confinement", f"buffer uri {uri}", lambda p=path: read(p), "named"))
    outside = _obj_folder(folder, "obj-link-out", lambda s: (s / "frame1.obj").symlink_to(folder / "secret.obj"))
    found.append(("confinement", "OBJ folder with a link out", lambda: read(outside), "named"))

    for name, change in JSON_DAMAGE:
        path = _gltf(folder, f"json-{len(found)}", change)
        found.append(("damaged glTF JSON", name, lambda p=path: read(p, fps=4), "named"))
        found.append(("damaged glTF JSON", f"{name} (clips)", lambda p=path: fio.read_clips(p), "any"))
    for name, change in BUFFER_DAMAGE:
        path = _gltf(folder, f"buffer-{len(found)}", buffer_change=change, suffix=".glb")
        found.append(("damaged glTF buffers", name, lambda p=path: read(p, fps=4), "named"))
    deep = _deep_json(folder)
    found.append(("damaged glTF JSON", "100 000-deep JSON", lambda: read(deep), "named"))
    fox = Path(__file__).resolve().parents[3] / "shared" / "data" / "fox-gltf" / "Fox.glb"
    if fox.is_file():
        data = fox.read_bytes()
        for k, at in enumerate(np.random.default_rng(0).integers(0, len(data), 25)):
            flipped = folder / f"fox-flip{k}.glb"
            flipped.write_bytes(data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1 :])
            found.append(("byte flips of Fox.glb", f"byte {at} flipped", lambda p=flipped: read(p), "any"))
        found.append(("sizes before allocation", "Fox at 1e6 fps", lambda: read(fox, fps=1e6), "named"))
        found.append(("sizes before allocation", "Fox clips at 1e6 fps", lambda: fio.read_clips(fox, fps=1e6), "named"))

    late = _gltf(folder, "late-key", buffer_change=_keys([0.0, 0.5, 1e7]), suffix=".glb")
    close = _gltf(folder, "close-keys", buffer_change=_keys([0.0, 2e-6, 4e-6]), suffix=".glb")
    found += [
        ("sizes before allocation", "a key at 1e7 s", lambda: read(late), "named"),
        ("sizes before allocation", "keys 2e-6 s apart (clips)", lambda: fio.read_clips(close), "named"),
        ("sizes before allocation", "mesh fps 1e300", lambda: read(late, fps=1e300), "named"),
        ("sizes before allocation", "mesh fps inf", lambda: read(late, fps=math.inf), "named"),
    ]
    silent_bvh = _bvh(folder, "frames", "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n}\nMOTION\nFrames: 20000000\n"
                      "Frame Time: 0.01\n")  # fmt: skip
    found.append(("sizes before allocation", "BVH of 2e7 frames and no channels", lambda: fio.read_clips(silent_bvh),
                  "named"))  # fmt: skip
    found.append(("sizes before allocation", "BVH resampled at 1e9 fps",
                  lambda: fio.read_clips(_bvh(folder, "nested3", _nested_bvh(3)), fps=1e9), "named"))  # fmt: skip
    bomb = _npz_bomb(folder, 2_400_000_000)
    found.append(("sizes before allocation", "a 2.4 GB npz of zeros", lambda: flockkit.Motion.load(bomb), "named"))
    parts = _flockkit_file(folder, "parts", "segmentation", {"labels": np.zeros(5, dtype=np.int64)},
                           {"n_parts": 10**9})  # fmt: skip
    found.append(("sizes before allocation", "n_parts 1e9", lambda: flockkit.Segmentation.load(parts), "named"))
    found += [
        ("sizes before allocation", "Stream history 1e9", lambda: StreamPool([_stream(10**9)]), "named"),
        ("sizes before allocation", "Crowd of 1e9 agents",
         lambda: Crowd(StreamPool([_stream()]), n_agents=10**9, clusters={"body": 0}), "named"),
        ("sizes before allocation", "UniquePool of 1e9", lambda: UniquePool(10**9, max_bones=25), "named"),
        ("hangs", "StreamPool fps 1e-300", lambda: StreamPool([_stream()], fps=1e-300), "named"),
        ("hangs", "100 000 streams", lambda: StreamPool([_stream()] * 100_000), "ok"),
    ]  # fmt: skip

    nested = _bvh(folder, "nested", _nested_bvh(4000))
    found.append(("hangs", "BVH of 4 000 nested joints", lambda: fio.read_clips(nested), "ok"))
    many = _many_nodes(folder, 50_000)
    found.append(("hangs", "glTF with 50 000 extra nodes in a chain", lambda: read(many, fps=30), "ok"))
    found.append(("hangs", "glTF with 50 000 extra nodes (clips)", lambda: fio.read_clips(many), "ok"))
    fifo = _obj_folder(folder, "obj-fifo", lambda s: os.mkfifo(s / "frame1.obj"))
    zero = _obj_folder(folder, "obj-zero", lambda s: (s / "frame1.obj").symlink_to("/dev/zero"))
    inner = _obj_folder(folder, "obj-folder", lambda s: (s / "frame1.obj").mkdir())
    found += [
        ("hangs", "a FIFO named frame1.obj", lambda: read(fifo), "named"),
        ("hangs", "a link to /dev/zero named frame1.obj", lambda: read(zero), "named"),
        ("hangs", "a folder named frame1.obj", lambda: read(inner), "named"),
    ]

    bvh_damage = [
        ("CHANNELS count x", "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS x Xrotation\n}\nMOTION\nFrames: 1\n"
         "Frame Time: 0.1\n0\n"),
        ("CHANNELS count 1e9", "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1000000000 Xrotation\n}\nMOTION\n"),
        ("Frames -1", "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: -1\n"
         "Frame Time: 0.1\n"),
        ("frame time 0", "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 1\n"
         "Frame Time: 0\n0\n"),
        ("a value NaN", "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 1\n"
         "Frame Time: 0.1\nnan\n"),
        ("joint named twice", "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\nJOINT a\n{\nOFFSET 0 0 0\n}"
         "\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0\n"),
        ("not UTF-8", "HIERARCHY\nROOT \udcff\n"),
    ]  # fmt: skip
    for name, text in bvh_damage:
        path = folder / f"bvh-{len(found)}.bvh"
        path.write_bytes(text.encode("utf-8", errors="surrogateescape"))
        found.append(("damaged BVH, OBJ and npz", f"BVH {name}", lambda p=path: fio.read_clips(p), "named"))
    obj_damage = [
        ("a vertex of 2 coordinates", "v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
        ("face index 0", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"),
        ("a huge face index", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n"),
        ("a face of 2", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n"),
        ("a relative index before the first", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -9\n"),
        ("a coordinate inf", "v inf 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
    ]
    for name, text in obj_damage:
        path = _obj(folder, f"obj-{len(found)}", text)
        found.append(("damaged BVH, OBJ and npz", f"OBJ {name}", lambda p=path: read(p), "named"))
    motion = flockkit.simulate(n_agents=3, steps=4, seed=0)
    for dtype in (bool, np.int8):
        path = _flockkit_file(folder, f"mesh-{np.dtype(dtype).name}", "mesh",
                              {"positions": motion.positions.astype(dtype), "faces": np.array([[0, 1, 2]])},
                              {"dt": 0.1, "name": "m"})  # fmt: skip
        found.append(("damaged BVH, OBJ and npz", f"mesh npz of {np.dtype(dtype).name} positions",
                      lambda p=path: flockkit.AnimatedMesh.load(p), "named"))  # fmt: skip
    faces = _flockkit_file(folder, "mesh-faces", "mesh", {"positions": np.zeros((2, 3, 3)), "faces": [[0, 1, 5]]},
                           {"dt": 0.1})  # fmt: skip
    found.append(("damaged BVH, OBJ and npz", "mesh npz with face index 5 of 3",
                  lambda: flockkit.AnimatedMesh.load(faces), "named"))  # fmt: skip

    bracket = folder / "frame[1].obj"
    bracket.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    star = folder / "a*b.obj"
    star.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    found += [
        ("silent nonsense", "list_clips of /nonexistent/x.xyz", lambda: fio.list_clips("/nonexistent/x.xyz"), "named"),
        ("silent nonsense", "an OBJ file named frame[1].obj", lambda: read(bracket), "ok"),
        ("silent nonsense", "an OBJ file named a*b.obj", lambda: read(star), "ok"),
    ]
    return found


def stream_pool_restart_pose(frames: int):
    """The pose a default-Stopped stream reads at offset 0 right after it is stopped, run for
    `frames` frames stopped, and started again; and the clip's own first pose (what it must be)."""
    from flockkit.crowd import StreamPool

    stream = _stream(history=8, default="Stopped")
    pool = StreamPool([_stream(), stream], fps=24)
    pool.acquire(np.array([1]))
    for _ in range(frames):
        pool.advance()
    pool.release(np.array([1]))
    for _ in range(3):
        pool.advance()
    pool.acquire(np.array([1]))
    return pool.read(1, 0), stream.controller.pose([0.0])[0]
