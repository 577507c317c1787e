"""Skeletal animation evaluated from the file formats' own definitions, sharing no code with
flockkit: the reference its clips are checked against.

glTF 2.0 (the Khronos specification, section 5.9 "Animations" and Appendix C "Animation Sampler
Interpolation Modes"): a sampler's output before its first and after its last key is clamped to
that key; at a key's own time its value is used as it is; between keys t_k < t_c < t_k+1, with
t_d = t_k+1 - t_k and t = (t_c - t_k) / t_d,

- STEP: v_k;
- LINEAR, not a rotation: (1 - t) v_k + t v_k+1;
- LINEAR rotation: a = arccos(|v_k . v_k+1|), s the sign of v_k . v_k+1,
  sin(a (1 - t)) / sin(a) v_k + s sin(a t) / sin(a) v_k+1 (linear when a is close to zero);
- CUBICSPLINE, keys stored as (in-tangent a_k, value v_k, out-tangent b_k):
  (2t^3 - 3t^2 + 1) v_k + t_d (t^3 - 2t^2 + t) b_k + (-2t^3 + 3t^2) v_k+1 + t_d (t^3 - t^2) a_k+1,
  a rotation normalized afterwards.

A node's local matrix is T R S (or its `matrix`), its world matrix its parent's world times its
local one. Each time is evaluated on its own, key by key, in plain Python: slow, and simple
enough to read against the text.

BVH (Biovision): each joint's rotation is its rotation channels applied in the order listed
(intrinsic Euler angles in degrees), its translation its OFFSET plus its position channels; frame
k is at time k / rate. Between frames flockkit defines the motion as each joint's rotation
interpolated spherically (slerp, the shorter way) and its translation linearly; scipy's Rotation
and Slerp compute both here.

Also a writer of small glTF files whose clips use every interpolation, keys at uneven times.
"""

from __future__ import annotations

import base64
import bisect
import json
import math
import struct
from pathlib import Path

import numpy as np

_KINDS = {5120: ("<i1", 127.0), 5121: ("<u1", 255.0), 5122: ("<i2", 32767.0), 5123: ("<u2", 65535.0),
          5125: ("<u4", None), 5126: ("<f4", None)}  # fmt: skip
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


class GltfAnimation:
    """A glTF 2.0 file (.gltf or .glb): its nodes, and every animation's channels evaluated at any
    time as the specification defines."""

    def __init__(self, path):
        path = Path(path)
        data = path.read_bytes()
        binary = None
        if data[:4] == b"glTF":
            offset, document = 12, None
            while offset < len(data):
                length, kind = struct.unpack_from("<II", data, offset)
                chunk = data[offset + 8 : offset + 8 + length]
                if kind == 0x4E4F534A:
                    document = json.loads(chunk)
                elif kind == 0x004E4942:
                    binary = chunk
                offset += 8 + length
        else:
            document = json.loads(data)
        self.json = document
        self.buffers = []
        for buffer in document.get("buffers", []):
            uri = buffer.get("uri")
            if uri is None:
                self.buffers.append(binary)
            elif uri.startswith("data:"):
                self.buffers.append(base64.b64decode(uri.split(",", 1)[1]))
            else:
                self.buffers.append((path.parent / uri).read_bytes())
        self.nodes = document.get("nodes", [])
        self.parent = {child: n for n, node in enumerate(self.nodes) for child in node.get("children", [])}
        self.names = [a.get("name") or f"animation {k}" for k, a in enumerate(document.get("animations", []))]

    def accessor(self, index) -> np.ndarray:
        """Accessor `index` as floats (count, width): normalized integers decoded as the
        specification's table says, sparse elements replaced."""
        spec = self.json["accessors"][index]
        dtype, scale = _KINDS[spec["componentType"]]
        dtype = np.dtype(dtype)
        width, count = _WIDTHS[spec["type"]], spec["count"]
        if "bufferView" in spec:
            view = self.json["bufferViews"][spec["bufferView"]]
            stride = view.get("byteStride", dtype.itemsize * width)
            start = view.get("byteOffset", 0) + spec.get("byteOffset", 0)
            buffer = self.buffers[view["buffer"]]
            values = np.array([np.frombuffer(buffer, dtype, width, start + i * stride) for i in range(count)])
        else:
            values = np.zeros((count, width), dtype)
        if "sparse" in spec:
            sparse = spec["sparse"]
            where = sparse["indices"]
            view = self.json["bufferViews"][where["bufferView"]]
            indices = np.frombuffer(self.buffers[view["buffer"]], _KINDS[where["componentType"]][0], sparse["count"],
                                    view.get("byteOffset", 0) + where.get("byteOffset", 0))  # fmt: skip
            what = sparse["values"]
            view = self.json["bufferViews"][what["bufferView"]]
            replaced = np.frombuffer(self.buffers[view["buffer"]], dtype, sparse["count"] * width,
                                     view.get("byteOffset", 0) + what.get("byteOffset", 0))  # fmt: skip
            values = values.copy()
            values[indices] = replaced.reshape(-1, width)
        values = values.astype(np.float64)
        if spec.get("normalized"):
            values = np.maximum(values / scale, -1.0)
        return values

    def channels(self, animation: int) -> list[dict]:
        """The node channels of `animation`: node, path, key times, values (K, W), in- and
        out-tangents (K, W) for CUBICSPLINE, interpolation."""
        spec = self.json["animations"][animation]
        found = []
        for channel in spec["channels"]:
            target = channel["target"]
            if "node" not in target or target["path"] == "weights":
                continue
            sampler = spec["samplers"][channel["sampler"]]
            times = self.accessor(sampler["input"])[:, 0]
            output = self.accessor(sampler["output"])
            interpolation = sampler.get("interpolation", "LINEAR")
            entry = {"node": target["node"], "path": target["path"], "times": times, "interpolation": interpolation}
            if interpolation == "CUBICSPLINE":
                entry.update(in_tangents=output[0::3], values=output[1::3], out_tangents=output[2::3])
            else:
                entry["values"] = output
            found.append(entry)
        return found

    def duration(self, animation: int) -> float:
        return max(float(c["times"][-1]) for c in self.channels(animation))

    def key_times(self, animation: int) -> np.ndarray:
        """Every key time of `animation`'s node channels, sorted, each once."""
        return np.unique(np.concatenate([c["times"] for c in self.channels(animation)]))

    def local(self, animation, times) -> tuple[dict, dict, dict]:
        """Per node, its translation (T, 3), rotation (T, 4, x y z w, unit) and scale (T, 3) at
        `times` under `animation` (None: the nodes' own values)."""
        n = len(times)
        translation = {k: np.tile(node.get("translation", [0.0, 0, 0]), (n, 1)) for k, node in enumerate(self.nodes)}
        rotation = {k: np.tile(node.get("rotation", [0.0, 0, 0, 1]), (n, 1)) for k, node in enumerate(self.nodes)}
        scale = {k: np.tile(node.get("scale", [1.0, 1, 1]), (n, 1)) for k, node in enumerate(self.nodes)}
        if animation is not None:
            for channel in self.channels(animation):
                values = np.array([channel_value(channel, t) for t in times])
                {"translation": translation, "rotation": rotation, "scale": scale}[channel["path"]][channel["node"]] = (
                    values
                )
        for k in rotation:
            rotation[k] = rotation[k] / np.linalg.norm(rotation[k], axis=1, keepdims=True)
        return translation, rotation, scale

    def world(self, animation, times) -> dict:
        """Per node, its world matrices (T, 4, 4) at `times`."""
        translation, rotation, scale = self.local(animation, times)
        local = {}
        for k, node in enumerate(self.nodes):
            if "matrix" in node:
                local[k] = np.tile(np.array(node["matrix"], dtype=float).reshape(4, 4).T, (len(times), 1, 1))
            else:
                m = np.zeros((len(times), 4, 4))
                m[:, :3, :3] = np.array([matrix_of(q) for q in rotation[k]]) * scale[k][:, None, :]
                m[:, :3, 3] = translation[k]
                m[:, 3, 3] = 1.0
                local[k] = m
        world = {}

        def place(k):
            if k not in world:
                world[k] = local[k] if k not in self.parent else place(self.parent[k]) @ local[k]
            return world[k]

        for k in range(len(self.nodes)):
            place(k)
        return world


def channel_value(channel: dict, t: float) -> np.ndarray:
    """One channel's value at time `t`, by Appendix C."""
    times, values = channel["times"], channel["values"]
    rotation = channel["path"] == "rotation"
    if t <= times[0]:
        return values[0]
    if t >= times[-1]:
        return values[-1]
    k = bisect.bisect_right(times.tolist(), t) - 1  # times[k] <= t < times[k + 1]
    if t == times[k]:
        return values[k]
    td = times[k + 1] - times[k]
    u = (t - times[k]) / td
    interpolation = channel["interpolation"]
    if interpolation == "STEP":
        return values[k]
    if interpolation == "LINEAR" and not rotation:
        return (1 - u) * values[k] + u * values[k + 1]
    if interpolation == "LINEAR":
        dot = float(np.dot(values[k], values[k + 1]))
        a = math.acos(min(abs(dot), 1.0))
        s = 1.0 if dot >= 0 else -1.0
        if math.sin(a) < 1e-12:
            return (1 - u) * values[k] + s * u * values[k + 1]
        return math.sin(a * (1 - u)) / math.sin(a) * values[k] + s * math.sin(a * u) / math.sin(a) * values[k + 1]
    b_k, a_next = channel["out_tangents"][k], channel["in_tangents"][k + 1]
    value = ((2 * u**3 - 3 * u**2 + 1) * values[k] + td * (u**3 - 2 * u**2 + u) * b_k
             + (-2 * u**3 + 3 * u**2) * values[k + 1] + td * (u**3 - u**2) * a_next)  # fmt: skip
    return value / np.linalg.norm(value) if rotation else value


def matrix_of(q) -> np.ndarray:
    """The rotation matrix of the unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def node_of(gltf: GltfAnimation, name: str) -> int:
    """The node flockkit calls `name`: its own name where unique, "node k" for an unnamed one,
    "name (k)" for one of several nodes of one name."""
    names = [node.get("name") for node in gltf.nodes]
    if name.startswith("node ") and name[5:].isdigit():
        return int(name[5:])
    if names.count(name) == 1:
        return names.index(name)
    base, _, number = name.rpartition(" (")
    assert number.endswith(")") and names[int(number[:-1])] == base, name
    return int(number[:-1])


class BvhMotion:
    """A BVH file's joints (end sites too) and their world positions at any time."""

    def __init__(self, path, rate: float):
        text = Path(path).read_text()
        head, motion = text.split("MOTION")
        self.parents, offsets, self.channels, stack = [], [], [], []
        for line in head.splitlines():
            words = line.split()
            if not words:
                continue
            if words[0] in ("ROOT", "JOINT", "End"):
                self.parents.append(stack[-1] if stack else -1)
            elif words[0] == "{":
                stack.append(len(self.parents) - 1)
            elif words[0] == "}":
                stack.pop()
            elif words[0] == "OFFSET":
                offsets.append([float(w) for w in words[1:4]])
            elif words[0] == "CHANNELS":
                self.channels.append((len(self.parents) - 1, words[2:]))
        self.offsets = np.array(offsets)
        width = sum(len(c) for _, c in self.channels)
        self.frames = np.array(motion.split("\n", 3)[3].split(), dtype=float).reshape(-1, width)
        self.rate = rate

    def _frame_pose(self):
        """Per joint, rotations (scipy, one per frame) and translations (F, 3)."""
        from scipy.spatial.transform import Rotation

        n = len(self.frames)
        rotations = [Rotation.identity(n)] * len(self.parents)
        translations = [np.tile(o, (n, 1)) for o in self.offsets]
        column = 0
        for joint, names in self.channels:
            for k, name in enumerate(names):
                if name.lower().endswith("position"):
                    axis = np.eye(3)["XYZ".index(name[0].upper())]
                    translations[joint] = translations[joint] + np.outer(self.frames[:, column + k], axis)
            turns = [k for k, name in enumerate(names) if name.lower().endswith("rotation")]
            if turns:
                order = "".join(names[k][0].upper() for k in turns)  # upper case: intrinsic, as listed
                rotations[joint] = Rotation.from_euler(order, self.frames[:, [column + k for k in turns]], degrees=True)
            column += len(names)
        return rotations, translations

    def positions(self, times) -> np.ndarray:
        """World joint positions (T, J, 3) at `times` in seconds: each joint's rotation slerped and
        its translation interpolated linearly between the frames around it, held outside."""
        from scipy.spatial.transform import Slerp

        rotations, translations = self._frame_pose()
        keys = np.arange(len(self.frames)) / self.rate
        t = np.clip(np.asarray(times, dtype=float), 0, keys[-1])
        local_r = [Slerp(keys, r)(t) for r in rotations]
        local_t = [np.stack([np.interp(t, keys, tr[:, d]) for d in range(3)], axis=1) for tr in translations]
        world_r, world_p = [None] * len(self.parents), [None] * len(self.parents)
        for j, parent in enumerate(self.parents):
            if parent < 0:
                world_r[j], world_p[j] = local_r[j], local_t[j]
            else:
                world_r[j] = world_r[parent] * local_r[j]
                world_p[j] = world_p[parent] + world_r[parent].apply(local_t[j])
        return np.stack(world_p, axis=1)


def write_clips(path, clips: dict, *, joints: int = 4, length: float = 1.0) -> None:
    """A .glb of a chain of `joints` nodes ("j0" the root, each `length` above its parent along
    y), a skin over them, and one animation per entry of `clips`: name -> list of channels
    (joint, path, times, values (K, W), interpolation, and for CUBICSPLINE in- and out-tangents
    (K, W)), stored as float32."""
    blob, views, accessors = bytearray(), [], []

    def add(array, kind):
        array = np.ascontiguousarray(array, dtype="<f4")
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": array.nbytes})
        blob.extend(array.tobytes())
        entry = {"bufferView": len(views) - 1, "componentType": 5126, "count": len(array), "type": kind}
        if kind == "SCALAR":
            entry.update(min=[float(array.min())], max=[float(array.max())])
        accessors.append(entry)
        return len(accessors) - 1

    nodes = [{"name": f"j{k}", "translation": [0.0, length if k else 0.0, 0.0]} for k in range(joints)]
    for k in range(joints - 1):
        nodes[k]["children"] = [k + 1]
    animations = []
    for name, channels in clips.items():
        samplers, targets = [], []
        for c in channels:
            output = c["values"]
            if c["interpolation"] == "CUBICSPLINE":
                output = np.stack([c["in_tangents"], c["values"], c["out_tangents"]], axis=1).reshape(
                    -1, output.shape[1]
                )
            samplers.append({"input": add(c["times"], "SCALAR"), "output": add(output, _kind(output.shape[1])),
                             "interpolation": c["interpolation"]})  # fmt: skip
            targets.append({"sampler": len(samplers) - 1, "target": {"node": c["joint"], "path": c["path"]}})
        animations.append({"name": name, "samplers": samplers, "channels": targets})
    document = {
        "asset": {"version": "2.0", "generator": "tests/core/animation_spec.py"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": nodes,
        "skins": [{"name": "chain", "joints": list(range(joints))}],
        "animations": animations, "accessors": accessors, "bufferViews": views,
        "buffers": [{"byteLength": len(blob)}],
    }  # fmt: skip
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + bytes(blob)
    Path(path).write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)


def _kind(width: int) -> str:
    return {1: "SCALAR", 3: "VEC3", 4: "VEC4"}[width]


def generated_clips(seed: int = 0, joints: int = 4) -> dict:
    """Clips for :func:`write_clips` over a chain of `joints`: for each interpolation (LINEAR,
    STEP, CUBICSPLINE) one clip whose every joint turns (turns up to 170 degrees between keys, the
    quaternion's sign flipping at random) and moves, each channel on its own uneven key times, the
    first key after 0; and a clip mixing the three, with a single-key channel."""
    rng = np.random.default_rng(seed)

    def times(count):
        steps = rng.uniform(0.02, 0.4, count - 1)
        return rng.uniform(0.0, 0.2) + np.concatenate([[0.0], np.cumsum(steps)])

    def turns(count):
        axis = rng.normal(size=3)
        angles = np.cumsum(rng.uniform(-170, 170, count)) * np.pi / 180
        tilt = rng.normal(size=(count, 3)) * 0.3
        axes = axis / np.linalg.norm(axis) + tilt
        axes /= np.linalg.norm(axes, axis=1, keepdims=True)
        q = np.concatenate([axes * np.sin(angles / 2)[:, None], np.cos(angles / 2)[:, None]], axis=1)
        return q * rng.choice([-1.0, 1.0], size=(count, 1))

    def channel(joint, path, interpolation, count):
        keys = times(count)
        values = turns(count) if path == "rotation" else rng.normal(size=(count, 3))
        entry = {"joint": joint, "path": path, "times": keys, "values": values, "interpolation": interpolation}
        if interpolation == "CUBICSPLINE":
            width = values.shape[1]
            entry.update(
                in_tangents=rng.normal(size=(count, width)) * 2, out_tangents=rng.normal(size=(count, width)) * 2
            )
        return entry

    clips = {}
    for interpolation in ("LINEAR", "STEP", "CUBICSPLINE"):
        clips[interpolation.lower()] = [channel(j, path, interpolation, int(rng.integers(2, 9)))
                                        for j in range(joints) for path in ("rotation", "translation")]  # fmt: skip
    mixed = [channel(j, path, ("LINEAR", "STEP", "CUBICSPLINE")[(j + p) % 3], int(rng.integers(2, 7)))
             for j in range(joints) for p, path in enumerate(("rotation", "translation"))]  # fmt: skip
    single = channel(joints - 1, "rotation", "LINEAR", 2)
    mixed[-2] = {**single, "times": single["times"][:1], "values": single["values"][:1]}
    clips["mixed"] = mixed
    return clips
