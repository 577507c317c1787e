"""A small glTF 2.0 reader: the container (.glb, or .gltf with external, data-URI or GLB buffers),
accessors as numpy arrays, the node hierarchy, animation sampling, morph targets and linear blend
skinning, vectorized over frames.

Our own rather than a library's: pygltflib (the well-kept Python glTF library) parses the JSON and
the GLB container only; accessors, sparse storage, animation interpolation, morphing and skinning,
which are most of the work, would still be ours. The spec sections cited are those of glTF 2.0.
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from . import rigid
from .errors import FileFormatError, ValidationError

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_GLB_MAGIC, _JSON_CHUNK, _BIN_CHUNK = b"glTF", 0x4E4F534A, 0x004E4942
FLOAT, UNSIGNED_SHORT = 5126, 5123  # componentType codes, for writers


def glb_bytes(document: dict, buffer: bytes) -> bytes:
    """A .glb file: the header, `document` as the JSON chunk and `buffer` as the binary chunk,
    each padded to 4 bytes (spec 4.4)."""
    text = json.dumps(document, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    buffer = bytes(buffer) + b"\0" * (-len(buffer) % 4)
    header = struct.pack("<4sII", _GLB_MAGIC, 2, 12 + 8 + len(text) + 8 + len(buffer))
    return (
        header
        + struct.pack("<II", len(text), _JSON_CHUNK)
        + text
        + struct.pack("<II", len(buffer), _BIN_CHUNK)
        + buffer
    )


class Document:
    """A parsed glTF file: its JSON (`json`), its buffers, and decoded accessors."""

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"{self.path}: no such file")
        data = self.path.read_bytes()
        glb = None
        try:
            if data[:4] == _GLB_MAGIC:
                self.json, glb = _read_glb(data)
            else:
                self.json = json.loads(data.decode("utf-8-sig"))
        except (ValueError, UnicodeDecodeError, struct.error) as exc:
            raise FileFormatError(f"{self.path}: not a glTF 2.0 file: {exc}") from None
        if not isinstance(self.json, dict) or not str(self.json.get("asset", {}).get("version", "")).startswith("2"):
            raise FileFormatError(f"{self.path}: not a glTF 2.0 file (no asset.version 2.x)")
        self.buffers = [self._buffer(i, b, glb) for i, b in enumerate(self.json.get("buffers", []))]
        self._accessors: dict[int, np.ndarray] = {}

    def _buffer(self, index: int, buffer: dict, glb: bytes | None) -> bytes:
        uri = buffer.get("uri")
        if uri is None:
            if glb is None:
                raise FileFormatError(f"{self.path}: buffer {index} has no uri and the file has no binary chunk")
            data = glb
        elif uri.startswith("data:"):
            header, _, payload = uri.partition(",")
            # application/octet-stream and application/gltf-buffer are both valid (spec 3.6.1.1)
            if not header.endswith(";base64"):
                raise FileFormatError(f"{self.path}: buffer {index} is a data URI that is not base64")
            try:
                data = base64.b64decode(payload, validate=False)
            except ValueError as exc:
                raise FileFormatError(f"{self.path}: buffer {index}: bad base64: {exc}") from None
        else:
            file = self.path.parent / unquote(uri)
            if not file.is_file():
                raise FileFormatError(f"{self.path}: buffer {index} refers to {file}, which does not exist")
            data = file.read_bytes()
        if len(data) < buffer.get("byteLength", 0):
            raise FileFormatError(
                f"{self.path}: buffer {index} holds {len(data)} bytes, not the {buffer['byteLength']} it should "
                "(truncated?)"
            )
        return data

    def accessor(self, index: int) -> np.ndarray:
        """Accessor `index` as an array (count, width) (float64 where normalized or float)."""
        if index not in self._accessors:
            self._accessors[index] = self._decode(index)
        return self._accessors[index]

    def _decode(self, index: int) -> np.ndarray:
        try:
            spec = self.json["accessors"][index]
            dtype = np.dtype(_COMPONENTS[spec["componentType"]]).newbyteorder("<")
            width, count = _WIDTH[spec["type"]], int(spec["count"])
            if "bufferView" in spec:
                values = self._view(spec["bufferView"], spec.get("byteOffset", 0), dtype, width, count)
            else:
                values = np.zeros((count, width), dtype=dtype)
            if "sparse" in spec:  # spec 3.6.2.3: a few replaced elements
                sparse = spec["sparse"]
                n = int(sparse["count"])
                idx = sparse["indices"]
                where = self._view(
                    idx["bufferView"],
                    idx.get("byteOffset", 0),
                    np.dtype(_COMPONENTS[idx["componentType"]]).newbyteorder("<"),
                    1,
                    n,
                )[:, 0]
                replaced = self._view(
                    sparse["values"]["bufferView"], sparse["values"].get("byteOffset", 0), dtype, width, n
                )
                values = values.copy()
                values[where.astype(np.int64)] = replaced
        except (KeyError, IndexError, TypeError) as exc:
            raise FileFormatError(f"{self.path}: accessor {index} is invalid: {type(exc).__name__}: {exc}") from None
        if spec.get("normalized") and dtype.kind in "iu":  # spec 3.11: normalized integers to [-1, 1] or [0, 1]
            info = np.iinfo(dtype)
            return np.maximum(values.astype(np.float64) / info.max, -1.0)
        return values.astype(np.float64) if dtype.kind == "f" else values.astype(np.int64)

    def _view(self, view_index: int, offset: int, dtype: np.dtype, width: int, count: int) -> np.ndarray:
        view = self.json["bufferViews"][view_index]
        data = self.buffers[view["buffer"]]
        start = view.get("byteOffset", 0) + offset
        element = dtype.itemsize * width
        stride = view.get("byteStride") or element
        end = start + stride * (count - 1) + element if count else start
        if end > len(data) or end - view.get("byteOffset", 0) > view["byteLength"]:
            raise FileFormatError(f"{self.path}: buffer view {view_index} is shorter than its accessor (truncated?)")
        if count == 0:
            return np.zeros((0, width), dtype=dtype)
        raw = np.frombuffer(data, dtype=np.uint8, count=end - start, offset=start)
        rows = np.lib.stride_tricks.as_strided(raw, shape=(count, element), strides=(stride, 1))
        return np.ascontiguousarray(rows).view(dtype).reshape(count, width)

    # -- scene ----------------------------------------------------------------------------------

    def scene_nodes(self) -> list[int]:
        """Every node of the default scene (or all root nodes), parents before children."""
        nodes = self.json.get("nodes", [])
        scenes = self.json.get("scenes")
        if scenes:
            roots = scenes[self.json.get("scene", 0)].get("nodes", [])
        else:
            children = {c for n in nodes for c in n.get("children", [])}
            roots = [i for i in range(len(nodes)) if i not in children]
        order, stack = [], list(reversed(roots))
        while stack:
            node = stack.pop()
            if node in order:
                raise FileFormatError(f"{self.path}: node {node} appears twice in the scene (a cycle?)")
            order.append(node)
            stack.extend(reversed(nodes[node].get("children", [])))
        return order

    def parents(self) -> dict[int, int]:
        return {c: i for i, n in enumerate(self.json.get("nodes", [])) for c in n.get("children", [])}

    def clips(self) -> dict[str, float]:
        """Animation names (unnamed ones as "animation K") and their durations in seconds."""
        found = {}
        for k, animation in enumerate(self.json.get("animations", [])):
            times = [self.accessor(s["input"]) for s in animation.get("samplers", [])]
            found[animation.get("name") or f"animation {k}"] = float(
                max((t.max() for t in times if len(t)), default=0.0)
            )
        return found

    def animation(self, clip) -> tuple[str, dict]:
        """(name, the animation's JSON) for `clip`: a name, an index, or None for the first."""
        animations = self.json.get("animations", [])
        if not animations:
            raise ValidationError(f"{self.path}: has no animation; a mesh animation needs one")
        names = list(self.clips())
        if clip is None:
            return names[0], animations[0]
        if isinstance(clip, (int, np.integer)) and not isinstance(clip, bool) and 0 <= clip < len(animations):
            return names[clip], animations[clip]
        if clip in names:
            return clip, animations[names.index(clip)]
        raise ValidationError(f"{self.path}: no clip {clip!r}; its clips are {', '.join(map(repr, names))}")

    def pose(self, animation: dict, times: np.ndarray):
        """Local transforms (T, nodes, 4, 4) and morph weights {node: (T, W)} at `times`."""
        translation, rotation, scale, weights, matrices, fixed = self.trs(animation, times)
        trs = rigid.trs(translation, rotation / np.linalg.norm(rotation, axis=-1, keepdims=True), scale)
        matrices[:, ~fixed] = trs[:, ~fixed]
        return matrices, weights

    def trs(self, animation: dict, times: np.ndarray):
        """Every node's local translation (T, nodes, 3), rotation (T, nodes, 4), scale (T, nodes,
        3) at `times`, morph weights {node: (T, W)}, and the nodes given as a matrix instead
        (T, nodes, 4, 4) with a mask of them."""
        nodes = self.json.get("nodes", [])
        t = len(times)
        translation = np.zeros((t, len(nodes), 3))
        rotation = np.zeros((t, len(nodes), 4))
        rotation[..., 3] = 1.0
        scale = np.ones((t, len(nodes), 3))
        fixed = np.zeros(len(nodes), dtype=bool)
        matrices = np.tile(np.eye(4), (t, len(nodes), 1, 1))
        weights = {}
        for i, node in enumerate(nodes):
            if "matrix" in node:  # column-major (spec 5.25)
                matrices[:, i] = np.asarray(node["matrix"], dtype=float).reshape(4, 4).T
                fixed[i] = True
            translation[:, i] = node.get("translation", (0, 0, 0))
            rotation[:, i] = node.get("rotation", (0, 0, 0, 1))
            scale[:, i] = node.get("scale", (1, 1, 1))
            mesh_weights = self.json["meshes"][node["mesh"]].get("weights") if "mesh" in node else None
            if node.get("weights", mesh_weights) is not None:
                weights[i] = np.tile(np.asarray(node.get("weights", mesh_weights), dtype=float), (t, 1))
        for channel in animation.get("channels", []):
            target = channel.get("target", {})
            if "node" not in target:
                continue
            sampler = animation["samplers"][channel["sampler"]]
            path, node = target["path"], target["node"]
            values = _sample(self.accessor(sampler["input"])[:, 0], self.accessor(sampler["output"]), times,
                             sampler.get("interpolation", "LINEAR"), path)  # fmt: skip
            if path == "translation":
                translation[:, node] = values
            elif path == "rotation":
                rotation[:, node] = values
            elif path == "scale":
                scale[:, node] = values
            elif path == "weights":
                weights[node] = values
        return translation, rotation, scale, weights, matrices, fixed

    def world(self, local: np.ndarray) -> np.ndarray:
        """World matrices (T, nodes, 4, 4) from local ones, through the hierarchy."""
        world = local.copy()
        parents = self.parents()
        for node in self.scene_nodes():
            if node in parents:
                world[:, node] = world[:, parents[node]] @ local[:, node]
        return world


def _read_glb(data: bytes):
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    if version != 2:
        raise ValueError(f"GLB version {version}, not 2")
    if length > len(data):
        raise ValueError(f"the header says {length} bytes, the file has {len(data)} (truncated?)")
    offset, document, binary = 12, None, None
    while offset < length:
        size, kind = struct.unpack_from("<II", data, offset)
        chunk = data[offset + 8 : offset + 8 + size]
        if len(chunk) < size:
            raise ValueError("a chunk runs past the end of the file (truncated?)")
        if kind == _JSON_CHUNK:
            document = json.loads(chunk.decode("utf-8"))
        elif kind == _BIN_CHUNK and binary is None:
            binary = chunk
        offset += 8 + size
    if document is None:
        raise ValueError("no JSON chunk")
    return document, binary


def _sample(inputs, outputs, times, interpolation, path):
    """Channel values at `times` (spec 3.11.3): LINEAR (spherical for rotations), STEP or
    CUBICSPLINE; held before the first and after the last key."""
    keys = len(inputs)
    width = outputs.size // (keys * (3 if interpolation == "CUBICSPLINE" else 1))
    outputs = outputs.reshape(keys, -1, width) if interpolation == "CUBICSPLINE" else outputs.reshape(keys, width)
    if interpolation == "CUBICSPLINE":
        tangent_in, values, tangent_out = outputs[:, 0], outputs[:, 1], outputs[:, 2]
    else:
        values = outputs
    if keys == 1:
        return np.repeat(values[:1], len(times), axis=0)
    clipped = np.clip(times, inputs[0], inputs[-1])
    k = np.clip(np.searchsorted(inputs, clipped, side="right") - 1, 0, keys - 2)
    span = inputs[k + 1] - inputs[k]
    u = np.where(span > 0, (clipped - inputs[k]) / np.where(span > 0, span, 1), 0.0)[:, None]
    if interpolation == "STEP":
        result = np.where(u >= 1, values[k + 1], values[k])
    elif interpolation == "CUBICSPLINE":
        u2, u3 = u * u, u * u * u
        dt = span[:, None]
        result = ((2 * u3 - 3 * u2 + 1) * values[k] + (u3 - 2 * u2 + u) * dt * tangent_out[k]
                  + (-2 * u3 + 3 * u2) * values[k + 1] + (u3 - u2) * dt * tangent_in[k + 1])  # fmt: skip
    elif path == "rotation":
        result = rigid.slerp(values[k], values[k + 1], u)
    else:
        result = (1 - u) * values[k] + u * values[k + 1]
    if path == "rotation":
        result = result / np.linalg.norm(result, axis=1, keepdims=True)
    return result


def mesh_animation(path, clip, fps):
    """(name, positions (T, V, 3), faces (F, 3), clip name) of every mesh in the default scene,
    animated by `clip` and sampled at `fps`: morph targets weighted, then skinned (linear blend
    skinning, spec 3.7.3) or placed by the node's world transform."""
    document = Document(path)
    name, animation = document.animation(clip)
    duration = document.clips()[name]
    times = np.arange(0.0, duration + 1e-9, 1.0 / fps)
    local, weights = document.pose(animation, times)
    world = document.world(local)
    positions, faces, count = [], [], 0
    for node in document.scene_nodes():
        spec = document.json["nodes"][node]
        if "mesh" not in spec:
            continue
        mesh = document.json["meshes"][spec["mesh"]]
        for primitive in mesh.get("primitives", []):
            points, triangles = _primitive(document, primitive, weights.get(node), len(times))
            if "skin" in spec:
                points = _skinned(document, document.json["skins"][spec["skin"]], primitive, points, world)
            else:
                points = points @ world[:, node, :3, :3].transpose(0, 2, 1) + world[:, node, None, :3, 3]
            positions.append(points)
            faces.append(triangles + count)
            count += points.shape[1]
    if not positions:
        raise ValidationError(f"{path}: the default scene has no mesh")
    positions = np.concatenate(positions, axis=1)
    if not np.all(np.isfinite(positions)):
        raise ValidationError(f"{path}: clip {name!r} gives vertex positions that are not finite")
    return (
        document.json.get("asset", {}).get("extras", {}).get("title") or Path(path).stem,
        positions,
        np.concatenate(faces),
        name,
    )


def _primitive(document, primitive, weights, frames):
    """Positions (T, V, 3) of a primitive with its morph targets applied, and its triangles."""
    attributes = primitive.get("attributes", {})
    if "POSITION" not in attributes:
        raise FileFormatError(f"{document.path}: a mesh primitive has no POSITION")
    base = document.accessor(attributes["POSITION"])
    points = np.broadcast_to(base, (frames, *base.shape)).copy()
    targets = primitive.get("targets", [])
    if targets and weights is not None:
        offsets = np.stack(
            [document.accessor(t["POSITION"]) if "POSITION" in t else np.zeros_like(base) for t in targets]
        )
        points += np.einsum("tk,kvd->tvd", weights[:, : len(targets)], offsets[: weights.shape[1]])
    mode = primitive.get("mode", 4)
    indices = document.accessor(primitive["indices"])[:, 0] if "indices" in primitive else np.arange(len(base))
    if mode == 4:  # triangles
        triangles = indices[: len(indices) // 3 * 3].reshape(-1, 3)
    elif mode == 5:  # triangle strip
        triangles = np.array(
            [indices[i : i + 3] if i % 2 == 0 else indices[[i + 1, i, i + 2]] for i in range(len(indices) - 2)]
        ).reshape(-1, 3)
    elif mode == 6:  # triangle fan
        triangles = np.column_stack([np.full(len(indices) - 2, indices[0]), indices[1:-1], indices[2:]])
    else:  # points and lines have no faces
        triangles = np.zeros((0, 3), dtype=np.int64)
    return points, triangles.astype(np.int64)


def _skinned(document, skin, primitive, points, world):
    """Linear blend skinning: sum over the vertex's joints of weight * (joint world @ inverse bind)."""
    attributes = primitive["attributes"]
    joints = np.concatenate(
        [document.accessor(attributes[k]) for k in sorted(attributes) if k.startswith("JOINTS_")], axis=1
    )
    weights = np.concatenate(
        [document.accessor(attributes[k]) for k in sorted(attributes) if k.startswith("WEIGHTS_")], axis=1
    )
    nodes = np.asarray(skin["joints"])
    inverse = (
        document.accessor(skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
        if "inverseBindMatrices" in skin
        else np.tile(np.eye(4), (len(nodes), 1, 1))
    )
    joint_matrices = world[:, nodes] @ inverse  # (T, J, 4, 4)
    total = weights.sum(axis=1, keepdims=True)
    weights = weights / np.where(total > 0, total, 1.0)
    homogeneous = np.concatenate([points, np.ones(points.shape[:2] + (1,))], axis=2)  # (T, V, 4)
    result = np.zeros(points.shape)
    for slot in range(joints.shape[1]):
        m = joint_matrices[:, joints[:, slot]]  # (T, V, 4, 4)
        moved = np.einsum("tvij,tvj->tvi", m[..., :3, :], homogeneous)
        result += weights[None, :, slot, None] * moved
    return result


def skin_clips(path, fps):
    """Per distinct skin, the skeleton (its joints and their ancestors, which carry the model's
    placement, parents first) and every animation that moves it, sampled at `fps` (None: each
    animation's key rate): yields (skin name, names, parents, rest translations (J, 3), rest
    rotations (J, 4), scales (J, 3), {clip name: (fps, rotations (T, J, 4), translations
    (T, J, 3))})."""
    document = Document(path)
    skins = document.json.get("skins", [])
    if not skins:
        raise ValidationError(f"{path}: has no skin; skeletal clips need one")
    if not document.json.get("animations"):
        raise ValidationError(f"{path}: has no animation")
    nodes = document.json.get("nodes", [])
    parents = document.parents()
    order = {node: k for k, node in enumerate(document.scene_nodes())}
    seen = set()
    for s, skin in enumerate(skins):
        joints = frozenset(skin.get("joints", []))
        if not joints or joints in seen:
            continue
        seen.add(joints)
        members = set(joints)
        for joint in joints:
            while joint in parents:
                joint = parents[joint]
                members.add(joint)
        if any(m not in order for m in members):
            raise FileFormatError(f"{path}: skin {s} has joints outside the default scene")
        chosen = sorted(members, key=order.__getitem__)
        index = {node: k for k, node in enumerate(chosen)}
        names = [nodes[n].get("name") or f"node {n}" for n in chosen]
        names = [name if names.count(name) == 1 else f"{name} ({n})" for name, n in zip(names, chosen)]
        zero = np.zeros(1)
        translation, rotation, scale, _, matrices, fixed = document.trs({}, zero)
        if fixed[chosen].any():
            raise FileFormatError(
                f"{path}: skin {s} has joints placed by a matrix; flockkit skeletons need translation/rotation/scale"
            )
        clips = {}
        for name, animation in zip(document.clips(), document.json["animations"]):
            targets = {c.get("target", {}).get("node") for c in animation.get("channels", [])}
            if not targets & members:
                continue
            inputs = [
                document.accessor(animation["samplers"][c["sampler"]]["input"])[:, 0]
                for c in animation.get("channels", [])
                if c.get("target", {}).get("node") in members
            ]
            duration = max(float(i.max()) for i in inputs if len(i))
            rate = fps
            if rate is None:
                steps = np.concatenate([np.diff(i) for i in inputs])
                steps = steps[steps > 1e-6]
                rate = float(np.round(1.0 / np.median(steps), 3)) if len(steps) else 30.0
            times = np.arange(int(round(duration * rate)) + 1) / rate
            t, r, sc, _, _, _ = document.trs(animation, times)
            if not np.allclose(sc[:, chosen], scale[0, chosen], atol=1e-6):
                raise ValidationError(f"{path}: clip {name!r} animates joint scales, which flockkit clips do not hold")
            clips[name] = (rate, r[:, chosen], t[:, chosen])
        parent = np.array([index.get(parents.get(n), -1) for n in chosen])
        yield (
            skin.get("name") or f"skin {s}",
            names,
            parent,
            translation[0, chosen],
            rotation[0, chosen],
            scale[0, chosen],
            clips,
        )
