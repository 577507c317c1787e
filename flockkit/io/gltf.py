"""A glTF 2.0 reader: the container (.glb, or .gltf with external, data-URI or GLB buffers), one
validated view of the document, accessors as numpy arrays, the node hierarchy, animation
sampling, morph targets and linear blend skinning, vectorized over frames.

Our own rather than a library's: pygltflib (the well-kept Python glTF library) parses the JSON and
the GLB container only; accessors, sparse storage, animation interpolation, morphing and skinning,
which are most of the work, would still be ours. The spec sections cited are those of glTF 2.0.

Files are untrusted. The whole document is checked when it is opened, before any array is built:
every index, count, offset, stride, type and component type against the spec and against the
buffers' real lengths, the node hierarchy for cycles and shared children, samplers for their
interpolation. Errors are FileFormatError naming the file and the JSON path (``accessors[3].count``).
An external buffer is read only from inside the file's folder (``flockkit._files.confined``).
Work grows linearly with the nodes, joints and frames, and only the nodes that place a mesh or a
skeleton are sampled.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import re
import struct
from collections import Counter
from pathlib import Path

import numpy as np

from .. import _files, rigid, validate
from .._atomic import atomic_path
from .._version import __version__
from ..errors import FileFormatError, ValidationError
from ..mesh import conversion_matrix
from ..motion import Motion
from ..skeleton import Channel, sample_keys

# glTF 2.0, section 3.4: "glTF uses a right-handed coordinate system ... +Y is up ... The units
# for all linear distances are meters." What every glTF file says of itself, whatever scale its
# asset was modelled at; a reader's caller states otherwise.
UP_AXIS = "y"
METERS_PER_UNIT = 1.0

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_GLB_MAGIC, _JSON_CHUNK, _BIN_CHUNK = b"glTF", 0x4E4F534A, 0x004E4942
FLOAT, UNSIGNED_SHORT = 5126, 5123  # componentType codes, for writers
_UNSIGNED = (5121, 5123, 5125)
_NORMALIZED_OR_FLOAT = (5120, 5121, 5122, 5123, 5126)  # float, or integers read as normalized
_INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
_PATH_WIDTH = {"translation": 3, "rotation": 4, "scale": 3, "weights": 1}
# Required extensions flockkit reads (KHR_mesh_quantization: integer positions, decoded as the
# spec says) or may ignore because they only change how a mesh is shaded or lit.
_READ_EXTENSIONS = {"KHR_mesh_quantization"}
_IGNORED_EXTENSION = re.compile(r"^(KHR_materials_|KHR_texture_|EXT_texture_|KHR_lights_)")
# The mesh primitive modes (spec 5.24.2): 4 triangles, 5 a strip, 6 a fan; below 4, points and
# lines, which have vertices but no faces.
_TRIANGLES, _STRIP, _FAN = 4, 5, 6
# The fastest key rate a clip is sampled at by default: 1 000 keys a second, above any capture
# rate in use (motion capture runs at 60-480 Hz); closer keys are what a broken exporter writes.
MAX_KEY_RATE = 1000.0
# Skinning works on blocks of frames whose per-vertex matrices take about this many bytes.
_SKIN_BLOCK_BYTES = 64 * 1024**2


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


def _element_bytes(component: int, kind: str) -> int:
    """Bytes of one element: matrices of 1- and 2-byte components pad each column to 4 bytes
    (spec 3.6.2.4)."""
    size = np.dtype(_COMPONENTS[component]).itemsize
    if kind in ("MAT2", "MAT3") and size < 4:
        rows = 2 if kind == "MAT2" else 3
        return rows * (-(-rows * size // 4) * 4)
    return size * _WIDTH[kind]


class Document:
    """A parsed and validated glTF file: its JSON (`json`), its buffers, decoded accessors, and
    the node hierarchy (`parent` of every node, `order`: the default scene's nodes, parents first).

    `allow_outside`: let external buffers live outside the file's folder (absolute paths and
    ``..``); by default they must lie inside it."""

    def __init__(self, path, *, allow_outside: bool = False):
        self.path = Path(path)
        data = _files.read_bytes(self.path)
        glb = None
        try:
            if data[:4] == _GLB_MAGIC:
                document, glb = _read_glb(data)
            else:
                document = json.loads(data.decode("utf-8-sig"))
        except (ValueError, UnicodeDecodeError, struct.error, RecursionError) as exc:
            raise FileFormatError(f"{self.path}: not a glTF 2.0 file: {type(exc).__name__}: {exc}") from None
        if not isinstance(document, dict):
            raise FileFormatError(f"{self.path}: not a glTF 2.0 file (the JSON is not an object)")
        asset = document.get("asset")
        version = asset.get("version") if isinstance(asset, dict) else None
        if not isinstance(version, str) or not re.fullmatch(r"2\.\d+", version):
            raise FileFormatError(f'{self.path}: not a glTF 2.0 file (asset.version must be "2.x"; got {version!r})')
        self.json = document
        self._check_extensions()
        for name in ("buffers", "bufferViews", "accessors", "nodes", "meshes", "skins", "animations", "scenes"):
            self._objects(name)
        self._check_buffers_and_views()
        self._check_accessors()
        self._check_meshes()
        self.parent = self._check_nodes()
        self._check_skins()
        self._check_animations()
        self.order = self._scene_order()
        self.buffers = [self._buffer(i, b, glb, allow_outside) for i, b in enumerate(self.json.get("buffers", []))]
        self._accessors: dict[int, np.ndarray] = {}

    # -- checks ---------------------------------------------------------------------------------

    def fail(self, where: str, what: str):
        raise FileFormatError(f"{self.path}: {where} {what}")

    def _objects(self, name: str) -> list:
        value = self.json.get(name, [])
        if not isinstance(value, list):
            self.fail(name, f"must be an array; got {type(value).__name__}")
        for i, item in enumerate(value):
            if not isinstance(item, dict):
                self.fail(f"{name}[{i}]", f"must be an object; got {type(item).__name__}")
        return value

    def _list(self, name: str) -> list:
        return self.json.get(name, [])

    def _int(self, value, where: str, *, minimum: int = 0, maximum: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(where, f"must be an integer; got {value!r:.60}")
        if value < minimum or (maximum is not None and value > maximum):
            high = "" if maximum is None else f" and <= {maximum}"
            self.fail(where, f"must be >= {minimum}{high}; got {value}")
        return value

    def _index(self, value, where: str, array: str) -> int:
        count = len(self._list(array))
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < count:
            self.fail(where, f"must index {array} (0..{count - 1}); got {value!r:.60}")
        return value

    def _numbers(self, value, where: str, count: int | None = None) -> list[float]:
        ok = isinstance(value, list) and (count is None or len(value) == count)
        # abs() < 1e308 before isfinite: JSON integers have no bound, and float() of a huge one overflows
        ok = ok and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and abs(v) < 1e308 and math.isfinite(v)
            for v in value
        )
        if not ok:
            size = "" if count is None else f"{count} "
            self.fail(where, f"must be an array of {size}finite numbers; got {value!r:.80}")
        return [float(v) for v in value]

    def _name(self, value, where: str):
        if value is not None and not isinstance(value, str):
            self.fail(where, f"must be a string; got {value!r:.60}")
        return value

    def _dict(self, value, where: str) -> dict:
        if not isinstance(value, dict):
            self.fail(where, f"must be an object; got {type(value).__name__}")
        return value

    def _check_extensions(self) -> None:
        required = self.json.get("extensionsRequired", [])
        if not isinstance(required, list) or not all(isinstance(e, str) for e in required):
            self.fail("extensionsRequired", "must be an array of strings")
        unknown = [e for e in required if e not in _READ_EXTENSIONS and not _IGNORED_EXTENSION.match(e)]
        if unknown:
            self.fail("extensionsRequired", f"names {', '.join(unknown)}, which flockkit cannot read (decompress the "
                      "file first, for example with gltf-transform)")  # fmt: skip

    def _check_buffers_and_views(self) -> None:
        for i, buffer in enumerate(self._list("buffers")):
            self._int(buffer.get("byteLength"), f"buffers[{i}].byteLength", minimum=1)
            if "uri" in buffer and (not isinstance(buffer["uri"], str) or not buffer["uri"]):
                self.fail(f"buffers[{i}].uri", f"must be a non-empty string; got {buffer['uri']!r:.60}")
        for i, view in enumerate(self._list("bufferViews")):
            where = f"bufferViews[{i}]"
            b = self._index(view.get("buffer"), f"{where}.buffer", "buffers")
            offset = self._int(view.get("byteOffset", 0), f"{where}.byteOffset")
            length = self._int(view.get("byteLength"), f"{where}.byteLength", minimum=1)
            if offset + length > self._list("buffers")[b]["byteLength"]:
                self.fail(where, f"runs to byte {offset + length}, past the end of buffer {b} "
                                 f"({self._list('buffers')[b]['byteLength']} bytes)")  # fmt: skip
            if "byteStride" in view:
                stride = self._int(view["byteStride"], f"{where}.byteStride", minimum=4, maximum=252)
                if stride % 4:
                    self.fail(f"{where}.byteStride", f"must be a multiple of 4; got {stride}")

    def _fits(self, where: str, view_index, offset, element: int, count: int, *, packed: bool = False) -> None:
        """That `count` elements of `element` bytes from `offset` lie inside buffer view `view_index`."""
        view = self._list("bufferViews")[self._index(view_index, f"{where}.bufferView", "bufferViews")]
        offset = self._int(offset, f"{where}.byteOffset")
        stride = element if packed else view.get("byteStride", element)
        if stride < element:
            self.fail(where, f"has elements of {element} bytes, wider than the view's byteStride {stride} (they "
                             "would overlap)")  # fmt: skip
        end = offset + stride * (count - 1) + element
        if end > view["byteLength"]:
            self.fail(where, f"needs {end} bytes of bufferView {view_index}, which holds {view['byteLength']}")

    def _check_accessors(self) -> None:
        for i, accessor in enumerate(self._list("accessors")):
            where = f"accessors[{i}]"
            component = accessor.get("componentType")
            if type(component) is not int or component not in _COMPONENTS:
                self.fail(f"{where}.componentType", f"must be one of {sorted(_COMPONENTS)}; got {component!r:.60}")
            kind = accessor.get("type")
            if not isinstance(kind, str) or kind not in _WIDTH:
                self.fail(f"{where}.type", f"must be one of {', '.join(_WIDTH)}; got {kind!r:.60}")
            count = self._int(accessor.get("count"), f"{where}.count", minimum=1)
            if not isinstance(accessor.get("normalized", False), bool):
                self.fail(f"{where}.normalized", "must be true or false")
            if accessor.get("normalized") and component in (5125, 5126):
                self.fail(f"{where}.normalized", "may be true only for 8- and 16-bit integers")
            element = _element_bytes(component, kind)
            if "bufferView" in accessor:
                self._fits(where, accessor["bufferView"], accessor.get("byteOffset", 0), element, count)
            elif "byteOffset" in accessor:
                self.fail(f"{where}.byteOffset", "is given without a bufferView")
            else:  # zeros, perhaps with sparse values: memory from a number alone
                validate.allocation(count * _WIDTH[kind], f"{self.path}: {where} ({count} elements without data)")
            if "sparse" in accessor:
                sparse = self._dict(accessor["sparse"], f"{where}.sparse")
                n = self._int(sparse.get("count"), f"{where}.sparse.count", minimum=1, maximum=count)
                indices = self._dict(sparse.get("indices"), f"{where}.sparse.indices")
                if type(indices.get("componentType")) is not int or indices["componentType"] not in _UNSIGNED:
                    self.fail(f"{where}.sparse.indices.componentType", f"must be one of {_UNSIGNED}")
                size = np.dtype(_COMPONENTS[indices["componentType"]]).itemsize
                self._fits(f"{where}.sparse.indices", indices.get("bufferView"), indices.get("byteOffset", 0), size, n,
                           packed=True)  # fmt: skip
                values = self._dict(sparse.get("values"), f"{where}.sparse.values")
                self._fits(f"{where}.sparse.values", values.get("bufferView"), values.get("byteOffset", 0), element,
                           n, packed=True)  # fmt: skip

    def _accessor_count(self, index) -> int:
        return self._list("accessors")[index]["count"]

    def _check_meshes(self) -> None:
        for m, mesh in enumerate(self._list("meshes")):
            primitives = mesh.get("primitives")
            if not isinstance(primitives, list) or not primitives:
                self.fail(f"meshes[{m}].primitives", "must be a non-empty array")
            targets = None
            for p, primitive in enumerate(primitives):
                where = f"meshes[{m}].primitives[{p}]"
                self._dict(primitive, where)
                attributes = self._dict(primitive.get("attributes"), f"{where}.attributes")
                counts = {name: self._accessor_count(self._index(a, f"{where}.attributes.{name}", "accessors"))
                          for name, a in attributes.items()}  # fmt: skip
                if len(set(counts.values())) > 1:
                    self.fail(f"{where}.attributes", f"have different counts {counts}; a primitive's attributes "
                              "describe the same vertices")  # fmt: skip
                if "indices" in primitive:
                    self._index(primitive["indices"], f"{where}.indices", "accessors")
                self._int(primitive.get("mode", _TRIANGLES), f"{where}.mode", maximum=6)
                found = primitive.get("targets", [])
                if not isinstance(found, list):
                    self.fail(f"{where}.targets", "must be an array")
                for t, target in enumerate(found):
                    for name, a in self._dict(target, f"{where}.targets[{t}]").items():
                        a = self._index(a, f"{where}.targets[{t}].{name}", "accessors")
                        if counts and self._accessor_count(a) != next(iter(counts.values())):
                            self.fail(f"{where}.targets[{t}].{name}", "has a count unlike the primitive's vertices")
                if targets is not None and len(found) != targets:
                    self.fail(f"{where}.targets", f"number {len(found)}; the mesh's other primitives have {targets}")
                targets = len(found)
            if "weights" in mesh and len(self._numbers(mesh["weights"], f"meshes[{m}].weights")) != targets:
                self.fail(f"meshes[{m}].weights", f"must give one weight per morph target ({targets})")

    def targets(self, mesh: int) -> int:
        """The number of morph targets of mesh `mesh`."""
        return len(self._list("meshes")[mesh]["primitives"][0].get("targets", []))

    def _check_nodes(self) -> np.ndarray:
        nodes = self._list("nodes")
        parent = np.full(len(nodes), -1, dtype=np.int64)
        for i, node in enumerate(nodes):
            where = f"nodes[{i}]"
            self._name(node.get("name"), f"{where}.name")
            children = node.get("children", [])
            if not isinstance(children, list):
                self.fail(f"{where}.children", "must be an array")
            for k, child in enumerate(children):
                child = self._index(child, f"{where}.children[{k}]", "nodes")
                if parent[child] >= 0 or child == i:
                    self.fail(f"{where}.children[{k}]", f"is node {child}, which already has a parent (node "
                              f"{parent[child] if child != i else i}); nodes form trees")  # fmt: skip
                parent[child] = i
            if "matrix" in node:
                self._numbers(node["matrix"], f"{where}.matrix", 16)
                if any(key in node for key in ("translation", "rotation", "scale")):
                    self.fail(where, "has both a matrix and translation, rotation or scale")
            for key, width in (("translation", 3), ("rotation", 4), ("scale", 3)):
                if key in node:
                    self._numbers(node[key], f"{where}.{key}", width)
            if "rotation" in node and abs(np.linalg.norm(node["rotation"]) - 1) > 1e-3:
                self.fail(f"{where}.rotation", f"must be a unit quaternion; got {node['rotation']}")
            if "mesh" in node:
                mesh = self._index(node["mesh"], f"{where}.mesh", "meshes")
                if "weights" in node and len(self._numbers(node["weights"], f"{where}.weights")) != self.targets(mesh):
                    self.fail(f"{where}.weights", f"must give one weight per morph target ({self.targets(mesh)})")
            if "skin" in node:
                self._index(node["skin"], f"{where}.skin", "skins")
                if "mesh" not in node:
                    self.fail(f"{where}.skin", "is given without a mesh")
        # every node must reach a root: jump to the ancestor 1, 2, 4, ... levels up (log n passes)
        up = np.where(parent >= 0, parent, np.arange(len(nodes)))
        for _ in range(len(nodes).bit_length() + 1):
            up = up[up]
        if len(nodes) and np.any(parent[up] >= 0):
            stuck = int(np.flatnonzero(parent[up] >= 0)[0])
            self.fail(f"nodes[{stuck}]", "is its own ancestor (the hierarchy has a cycle)")
        return parent

    def _check_skins(self) -> None:
        for s, skin in enumerate(self._list("skins")):
            joints = skin.get("joints")
            if not isinstance(joints, list) or not joints:
                self.fail(f"skins[{s}].joints", "must be a non-empty array")
            for k, joint in enumerate(joints):
                self._index(joint, f"skins[{s}].joints[{k}]", "nodes")
            if len(set(joints)) != len(joints):
                self.fail(f"skins[{s}].joints", "name a node twice")
            if "inverseBindMatrices" in skin:
                a = self._index(skin["inverseBindMatrices"], f"skins[{s}].inverseBindMatrices", "accessors")
                accessor = self._list("accessors")[a]
                if accessor["type"] != "MAT4" or accessor["componentType"] != FLOAT or accessor["count"] < len(joints):
                    self.fail(f"skins[{s}].inverseBindMatrices", f"must be a float MAT4 accessor of {len(joints)} "
                              "matrices, one per joint")  # fmt: skip
            if "skeleton" in skin:
                self._index(skin["skeleton"], f"skins[{s}].skeleton", "nodes")

    def _check_animations(self) -> None:
        nodes = self._list("nodes")
        for a, animation in enumerate(self._list("animations")):
            where = f"animations[{a}]"
            self._name(animation.get("name"), f"{where}.name")
            samplers, channels = animation.get("samplers"), animation.get("channels")
            for name, value in (("samplers", samplers), ("channels", channels)):
                if not isinstance(value, list) or not value:
                    self.fail(f"{where}.{name}", "must be a non-empty array")
            for k, sampler in enumerate(samplers):
                here = f"{where}.samplers[{k}]"
                self._dict(sampler, here)
                self._index(sampler.get("input"), f"{here}.input", "accessors")
                self._index(sampler.get("output"), f"{here}.output", "accessors")
                if sampler.get("interpolation", "LINEAR") not in _INTERPOLATIONS:
                    self.fail(f"{here}.interpolation", f"must be one of {', '.join(_INTERPOLATIONS)}; got "
                              f"{sampler.get('interpolation')!r:.60}")  # fmt: skip
            targeted = set()
            for k, channel in enumerate(channels):
                here = f"{where}.channels[{k}]"
                self._dict(channel, here)
                s = self._int(channel.get("sampler"), f"{here}.sampler", maximum=len(samplers) - 1)
                target = self._dict(channel.get("target"), f"{here}.target")
                if "node" not in target:
                    continue  # a target given by an extension (KHR_animation_pointer): not ours to move
                node = self._index(target["node"], f"{here}.target.node", "nodes")
                path = target.get("path")
                if not isinstance(path, str) or path not in _PATH_WIDTH:
                    self.fail(f"{here}.target.path", f"must be one of {', '.join(_PATH_WIDTH)}; got {path!r:.60}")
                if (node, path) in targeted:
                    self.fail(here, f"animates node {node}'s {path} a second time in one animation")
                targeted.add((node, path))
                if path != "weights" and "matrix" in nodes[node]:
                    self.fail(here, f"animates node {node}, which is placed by a matrix")
                if path == "weights" and ("mesh" not in nodes[node] or not self.targets(nodes[node]["mesh"])):
                    self.fail(here, f"animates the morph weights of node {node}, which has no morph targets")
                self._check_sampler_output(f"{where}.samplers[{s}]", samplers[s], path, nodes[node])

    def _check_sampler_output(self, where: str, sampler: dict, path: str, node: dict) -> None:
        accessors = self._list("accessors")
        keys, out = accessors[sampler["input"]], accessors[sampler["output"]]
        if keys["type"] != "SCALAR" or keys["componentType"] != FLOAT:
            self.fail(f"{where}.input", "must be a float SCALAR accessor (key times in seconds)")
        cubic = sampler.get("interpolation") == "CUBICSPLINE"
        if cubic and keys["count"] < 2:
            self.fail(where, "is a CUBICSPLINE with fewer than 2 keys")
        width = _PATH_WIDTH[path]
        components = (FLOAT,) if path in ("translation", "scale") else _NORMALIZED_OR_FLOAT
        floats = out["componentType"] == FLOAT or out.get("normalized", False)
        if out["type"] != ("SCALAR", "VEC2", "VEC3", "VEC4")[width - 1] or out["componentType"] not in components \
                or not floats:  # fmt: skip
            self.fail(
                f"{where}.output",
                f"must be a {('SCALAR', 'VEC2', 'VEC3', 'VEC4')[width - 1]} accessor of "
                f"floats{'' if len(components) == 1 else ' or normalized integers'} for a {path} channel",
            )
        per_key = (3 if cubic else 1) * (self.targets(node["mesh"]) if path == "weights" else 1)
        if out["count"] != keys["count"] * per_key:
            self.fail(f"{where}.output", f"has {out['count']} elements; {keys['count']} keys of a {path} channel "
                      f"need {keys['count'] * per_key}")  # fmt: skip

    def _scene_order(self) -> list[int]:
        nodes, scenes = self._list("nodes"), self._list("scenes")
        if scenes:
            index = self._index(self.json.get("scene", 0), "scene", "scenes")
            roots = scenes[index].get("nodes", [])
            if not isinstance(roots, list):
                self.fail(f"scenes[{index}].nodes", "must be an array")
            for k, root in enumerate(roots):
                self._index(root, f"scenes[{index}].nodes[{k}]", "nodes")
                if self.parent[root] >= 0:
                    self.fail(f"scenes[{index}].nodes[{k}]", f"is node {root}, which is not a root (its parent is "
                              f"node {self.parent[root]})")  # fmt: skip
            if len(set(roots)) != len(roots):
                self.fail(f"scenes[{index}].nodes", "name a node twice")
        else:
            roots = [i for i in range(len(nodes)) if self.parent[i] < 0]
        order, stack = [], list(reversed(roots))
        while stack:  # depth first, parents before children, as the scene lists them
            node = stack.pop()
            order.append(node)
            stack.extend(reversed(nodes[node].get("children", [])))
        return order

    # -- buffers and accessors ------------------------------------------------------------------

    def _buffer(self, index: int, buffer: dict, glb: bytes | None, allow_outside: bool) -> bytes:
        length, uri = buffer["byteLength"], buffer.get("uri")
        where = f"buffers[{index}]"
        if uri is None:
            if glb is None or index != 0:
                self.fail(where, "has no uri, and only buffer 0 of a .glb may use its binary chunk")
            data = glb
        elif uri.startswith("data:"):
            header, _, payload = uri.partition(",")
            # application/octet-stream and application/gltf-buffer are both valid (spec 3.6.1.1)
            if not header.endswith(";base64"):
                self.fail(f"{where}.uri", "is a data URI that is not base64")
            try:
                data = base64.b64decode(payload, validate=False)
            except (ValueError, binascii.Error) as exc:
                self.fail(f"{where}.uri", f"holds bad base64: {exc}")
        else:
            file = _files.confined(self.path.parent, uri, source=self.path, where=f"{where}.uri",
                                   allow_outside=allow_outside)  # fmt: skip
            try:
                data = _files.read_bytes(file, size=length)
            except FileNotFoundError:
                self.fail(f"{where}.uri", f"refers to {file}, which does not exist")
            except FileFormatError as exc:
                self.fail(f"{where}.uri", f"refers to a file flockkit cannot read: {exc}")
        if len(data) < length:
            self.fail(where, f"holds {len(data)} bytes, not the {length} it should (truncated?)")
        return data

    def accessor(self, index: int) -> np.ndarray:
        """Accessor `index` as an array (count, width): float64 where floats or normalized
        integers (spec 3.11), else int64. Matrices of 1- and 2-byte components are not read."""
        if index not in self._accessors:
            self._accessors[index] = self._decode(index)
        return self._accessors[index]

    def _decode(self, index: int) -> np.ndarray:
        spec = self._list("accessors")[index]
        where = f"accessors[{index}]"
        component, kind, count = spec["componentType"], spec["type"], spec["count"]
        dtype = np.dtype(_COMPONENTS[component]).newbyteorder("<")
        width = _WIDTH[kind]
        if _element_bytes(component, kind) != dtype.itemsize * width:
            self.fail(where, f"is a {kind} of {dtype.itemsize}-byte components with padded columns, which flockkit "
                      "does not read")  # fmt: skip
        if "bufferView" in spec:
            values = self._view(spec["bufferView"], spec.get("byteOffset", 0), dtype, width, count)
        else:
            values = np.zeros((count, width), dtype=dtype)
        if "sparse" in spec:  # spec 3.6.2.3: a few replaced elements
            sparse = spec["sparse"]
            n, indices = sparse["count"], sparse["indices"]
            where_dtype = np.dtype(_COMPONENTS[indices["componentType"]]).newbyteorder("<")
            at = self._view(indices["bufferView"], indices.get("byteOffset", 0), where_dtype, 1, n, packed=True)[:, 0]
            at = at.astype(np.int64)
            if np.any(np.diff(at) <= 0) or at[-1] >= count:
                self.fail(f"{where}.sparse.indices", f"must increase strictly and stay below count {count}")
            values = values.copy()
            values[at] = self._view(sparse["values"]["bufferView"], sparse["values"].get("byteOffset", 0), dtype,
                                    width, n, packed=True)  # fmt: skip
        if spec.get("normalized"):  # spec 3.11: normalized integers to [-1, 1] or [0, 1]
            return np.maximum(values.astype(np.float64) / np.iinfo(dtype).max, -1.0)
        if dtype.kind == "f":
            values = values.astype(np.float64)
            if not np.all(np.isfinite(values)):
                self.fail(where, "holds values that are not finite")
            return values
        return values.astype(np.int64)

    def _view(self, view_index: int, offset: int, dtype: np.dtype, width: int, count: int, *, packed=False):
        """`count` elements of `width` values of `dtype` from buffer view `view_index`, `offset`
        bytes in (bounds checked when the document was opened; numpy checks them again)."""
        view = self._list("bufferViews")[view_index]
        data = self.buffers[view["buffer"]]
        element = dtype.itemsize * width
        stride = element if packed else view.get("byteStride", element)
        rows = np.ndarray((count, element), dtype=np.uint8, buffer=data, offset=view.get("byteOffset", 0) + offset,
                          strides=(stride, 1))  # fmt: skip
        return np.ascontiguousarray(rows).view(dtype).reshape(count, width)

    def typed(self, index: int, where: str, kinds: tuple, components: tuple) -> np.ndarray:
        """Accessor `index` if its type is one of `kinds` and its componentType one of
        `components`; else a FileFormatError naming `where`, the property that refers to it."""
        spec = self._list("accessors")[index]
        if spec["type"] not in kinds or spec["componentType"] not in components:
            self.fail(where, f"must refer to a {' or '.join(kinds)} accessor of component types {components}; "
                      f"accessors[{index}] is a {spec['type']} of {spec['componentType']}")  # fmt: skip
        return self.accessor(index)

    # -- the scene --------------------------------------------------------------------------------

    def scene_nodes(self) -> list[int]:
        """Every node of the default scene (or all root nodes), parents before children."""
        return self.order

    def key_times(self, animation: int, sampler: int) -> np.ndarray:
        """The key times (K,) of a sampler: finite seconds >= 0, strictly increasing (spec 3.11)."""
        index = self._list("animations")[animation]["samplers"][sampler]["input"]
        times = self.accessor(index)[:, 0]
        if times[0] < 0 or np.any(np.diff(times) <= 0):
            self.fail(f"animations[{animation}].samplers[{sampler}].input",
                      "must hold key times >= 0 that increase strictly")  # fmt: skip
        return times

    def keys(self, animation: int, sampler: int, path: str) -> np.ndarray:
        """The output of a sampler (its values, with tangents for CUBICSPLINE), rotations checked
        for keys of length zero (which no interpolation can turn into a rotation)."""
        output = self.accessor(self._list("animations")[animation]["samplers"][sampler]["output"])
        if path == "rotation" and not np.all(np.linalg.norm(output, axis=1) > 1e-12):
            cubic = self._list("animations")[animation]["samplers"][sampler].get("interpolation") == "CUBICSPLINE"
            if not cubic or not np.all(np.linalg.norm(output[1::3], axis=1) > 1e-12):  # tangents may be zero
                self.fail(f"animations[{animation}].samplers[{sampler}].output", "holds a rotation of length zero")
        return output

    def clip_names(self) -> list[str]:
        """Animation names (unnamed ones as "animation K", repeated ones with " (K)" added)."""
        names = [a.get("name") or f"animation {k}" for k, a in enumerate(self._list("animations"))]
        counts = Counter(names)
        return [name if counts[name] == 1 else f"{name} ({k})" for k, name in enumerate(names)]

    def duration(self, animation: int) -> float:
        """Seconds to the last key of animation `animation`."""
        samplers = self._list("animations")[animation]["samplers"]
        return max(float(self.key_times(animation, s)[-1]) for s in range(len(samplers)))

    def clips(self) -> dict[str, float]:
        """Animation names (see :meth:`clip_names`) and their durations in seconds."""
        return {name: self.duration(k) for k, name in enumerate(self.clip_names())}

    def animation(self, clip) -> int:
        """The index of `clip`: a name, an index, or None for the first."""
        animations = self._list("animations")
        if not animations:
            raise ValidationError(f"{self.path}: has no animation; a mesh animation needs one")
        names = self.clip_names()
        if clip is None:
            return 0
        if isinstance(clip, (int, np.integer)) and not isinstance(clip, bool) and 0 <= clip < len(animations):
            return int(clip)
        if clip in names:
            return names.index(clip)
        raise ValidationError(f"{self.path}: no clip {clip!r}; its clips are {', '.join(map(repr, names))}")

    def with_ancestors(self, nodes) -> list[int]:
        """`nodes` and every ancestor of them, parents before children."""
        found = set()
        for node in nodes:
            while node >= 0 and node not in found:
                found.add(node)
                node = int(self.parent[node])
        depth = {}
        for node in found:  # depth by climbing; memoized, so linear in the nodes
            chain = []
            while node not in depth and node >= 0:
                chain.append(node)
                node = int(self.parent[node])
            base = depth.get(node, -1)
            for k, n in enumerate(reversed(chain)):
                depth[n] = base + 1 + k
        return sorted(found, key=lambda n: (depth[n], n))

    def trs(self, animation: int | None, times: np.ndarray, nodes: list[int]):
        """The local translation (T, n, 3), rotation (T, n, 4) and scale (T, n, 3) of `nodes` at
        `times` (animation None: the rest pose), their morph weights {node: (T, W)}, and the
        nodes placed by a matrix instead: (T, n, 4, 4) with a mask (n,)."""
        all_nodes = self._list("nodes")
        t, n = len(times), len(nodes)
        validate.allocation(t * n * 30, f"{self.path}: {n} nodes over {t} frames")
        column = {node: k for k, node in enumerate(nodes)}
        translation = np.zeros((t, n, 3))
        rotation = np.zeros((t, n, 4))
        rotation[..., 3] = 1.0
        scale = np.ones((t, n, 3))
        fixed = np.zeros(n, dtype=bool)
        matrices = np.tile(np.eye(4), (t, n, 1, 1))
        weights = {}
        for k, i in enumerate(nodes):
            node = all_nodes[i]
            if "matrix" in node:  # column-major (spec 5.25)
                matrices[:, k] = np.asarray(node["matrix"], dtype=float).reshape(4, 4).T
                fixed[k] = True
            translation[:, k] = node.get("translation", (0, 0, 0))
            rotation[:, k] = node.get("rotation", (0, 0, 0, 1))
            scale[:, k] = node.get("scale", (1, 1, 1))
            if "mesh" in node and self.targets(node["mesh"]):
                default = node.get("weights", self._list("meshes")[node["mesh"]].get("weights"))
                if default is None:  # spec 3.7.2.2: weights default to zero
                    default = np.zeros(self.targets(node["mesh"]))
                weights[i] = np.tile(np.asarray(default, dtype=float), (t, 1))
        rotation[:] /= np.linalg.norm(rotation, axis=-1, keepdims=True)
        if animation is not None:
            spec = self._list("animations")[animation]
            for channel in spec["channels"]:
                target = channel["target"]
                if target.get("node") not in column:
                    continue
                sampler = spec["samplers"][channel["sampler"]]
                path, node = target["path"], target["node"]
                output = self.keys(animation, channel["sampler"], path)
                values = _sample(self.key_times(animation, channel["sampler"]), output, times,
                                 sampler.get("interpolation", "LINEAR"), path)  # fmt: skip
                if path == "rotation":
                    rotation[:, column[node]] = values
                elif path == "weights":
                    weights[node] = values
                else:
                    (translation if path == "translation" else scale)[:, column[node]] = values
        return translation, rotation, scale, weights, matrices, fixed

    def world(self, animation: int | None, times: np.ndarray, nodes: list[int]):
        """World matrices (T, n, 4, 4) of `nodes` (closed under parents, parents first; see
        :meth:`with_ancestors`) at `times`, and their morph weights."""
        translation, rotation, scale, weights, matrices, fixed = self.trs(animation, times, nodes)
        local = rigid.trs(translation, rotation, scale)
        local[:, fixed] = matrices[:, fixed]
        column = {node: k for k, node in enumerate(nodes)}
        for k, node in enumerate(nodes):
            parent = int(self.parent[node])
            if parent >= 0:
                local[:, k] = local[:, column[parent]] @ local[:, k]
        return local, weights


def _read_glb(data: bytes):
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    if version != 2:
        raise ValueError(f"GLB version {version}, not 2")
    if length > len(data):
        raise ValueError(f"the header says {length} bytes, the file has {len(data)} (truncated?)")
    offset, document, binary = 12, None, None
    while offset + 8 <= length:
        size, kind = struct.unpack_from("<II", data, offset)
        chunk = data[offset + 8 : offset + 8 + size]
        if len(chunk) < size or offset + 8 + size > length:
            raise ValueError("a chunk runs past the end of the file (truncated?)")
        if kind == _JSON_CHUNK and document is None:
            if offset != 12:
                raise ValueError("the JSON chunk must come first")
            document = json.loads(chunk.decode("utf-8"))
        elif kind == _BIN_CHUNK and binary is None:
            binary = chunk
        offset += 8 + size
    if document is None:
        raise ValueError("no JSON chunk")
    return document, binary


def _sample(inputs, outputs, times, interpolation, path):
    """Channel values at `times` (spec Appendix C, :func:`flockkit.skeleton.sample_keys`): LINEAR
    (spherical for rotations, whose keys are normalized first), STEP or CUBICSPLINE; held before
    the first and after the last key."""
    keys = len(inputs)
    cubic = interpolation == "CUBICSPLINE"
    width = outputs.size // (keys * (3 if cubic else 1))
    tangent_in = tangent_out = None
    if cubic:
        outputs = outputs.reshape(keys, 3, width)
        tangent_in, values, tangent_out = outputs[:, 0], outputs[:, 1], outputs[:, 2]
    else:
        values = outputs.reshape(keys, width)
    rotation = path == "rotation"
    if rotation and not cubic:
        values = values / np.linalg.norm(values, axis=1, keepdims=True)
    return sample_keys(inputs, values, times, interpolation, rotation=rotation, in_tangents=tangent_in,
                       out_tangents=tangent_out)  # fmt: skip


def _frames(duration: float, fps: float, per_frame: float, what: str) -> int:
    """Frames of ``numpy.arange(0, duration + 1e-9, 1 / fps)``, counted, and their `per_frame`
    numbers checked against the memory budget, before any is made."""
    count = (duration + 1e-9) / (1.0 / fps)
    validate.allocation(count * per_frame, what)
    return max(math.ceil(count), 1)


def mesh_animation(path, clip, fps, *, allow_outside: bool = False, document: Document | None = None):
    """(name, positions (T, V, 3), faces (F, 3), clip name) of every mesh in the default scene,
    animated by `clip` and sampled at `fps`: morph targets weighted, then skinned (linear blend
    skinning, spec 3.7.3) or placed by the node's world transform. The vertices are each mesh
    node's primitives' in the scene's order (``flockkit.io.skin.mesh_skin`` gives their skin).
    `document`: the file already opened (and checked) as a Document, read instead of `path`."""
    document = Document(path, allow_outside=allow_outside) if document is None else document
    animation = document.animation(clip)
    name = document.clip_names()[animation]
    nodes, meshes, skins = document._list("nodes"), document._list("meshes"), document._list("skins")
    placed = [n for n in document.order if "mesh" in nodes[n]]
    if not placed:
        raise ValidationError(f"{path}: the default scene has no mesh")
    vertices = 0
    for n in placed:
        for p, primitive in enumerate(meshes[nodes[n]["mesh"]]["primitives"]):
            if "POSITION" not in primitive["attributes"]:
                document.fail(f"meshes[{nodes[n]['mesh']}].primitives[{p}].attributes", "have no POSITION")
            vertices += document._accessor_count(primitive["attributes"]["POSITION"])
    needed = document.with_ancestors(placed + [j for n in placed if "skin" in nodes[n]
                                               for j in skins[nodes[n]["skin"]]["joints"]])  # fmt: skip
    duration = document.duration(animation)
    _frames(duration, fps, vertices * 3 * 3 + len(needed) * 16 * 3,
            f"{path}: clip {name!r} ({duration:g} s) at {fps:g} fps, {vertices} vertices")  # fmt: skip
    times = np.arange(0.0, duration + 1e-9, 1.0 / fps)
    world, weights = document.world(animation, times, needed)
    column = {node: k for k, node in enumerate(needed)}
    positions, faces, count = [], [], 0
    for node in placed:
        spec = nodes[node]
        for p, primitive in enumerate(meshes[spec["mesh"]]["primitives"]):
            where = f"meshes[{spec['mesh']}].primitives[{p}]"
            points, triangles = _primitive(document, where, primitive, weights.get(node), len(times))
            if "skin" in spec:
                skin = skins[spec["skin"]]
                joints = world[:, [column[j] for j in skin["joints"]]]
                points = _skinned(document, where, skin, spec["skin"], primitive, points, joints)
            else:
                matrix = world[:, column[node]]
                points = points @ matrix[:, :3, :3].transpose(0, 2, 1) + matrix[:, None, :3, 3]
            positions.append(points)
            faces.append(triangles + count)
            count += points.shape[1]
    positions = np.concatenate(positions, axis=1)
    if not np.all(np.isfinite(positions)):
        raise FileFormatError(f"{path}: clip {name!r} gives vertex positions that are not finite")
    asset = document.json["asset"]
    title = asset.get("extras", {}).get("title") if isinstance(asset.get("extras"), dict) else None
    return (title if isinstance(title, str) and title else Path(path).stem, positions, np.concatenate(faces), name)


def _primitive(document, where, primitive, weights, frames):
    """Positions (T, V, 3) of a primitive with its morph targets applied, and its triangles."""
    attributes = primitive["attributes"]
    # integer positions (KHR_mesh_quantization) are numbers like any other once read
    base = document.typed(attributes["POSITION"], f"{where}.attributes.POSITION", ("VEC3",), tuple(_COMPONENTS))
    base = base.astype(np.float64, copy=False)
    points = np.broadcast_to(base, (frames, *base.shape)).copy()
    targets = primitive.get("targets", [])
    if targets and weights is not None:
        offsets = np.stack([
            document.typed(t["POSITION"], f"{where}.targets[{k}].POSITION", ("VEC3",), tuple(_COMPONENTS))
            if "POSITION" in t else np.zeros_like(base) for k, t in enumerate(targets)
        ])  # fmt: skip
        points += np.einsum("tk,kvd->tvd", weights, offsets)
    mode = primitive.get("mode", _TRIANGLES)
    if "indices" in primitive:
        indices = document.typed(primitive["indices"], f"{where}.indices", ("SCALAR",), _UNSIGNED)[:, 0]
        if len(indices) and indices.max() >= len(base):
            document.fail(f"{where}.indices", f"refer to vertex {indices.max()}; the primitive has {len(base)}")
    else:
        indices = np.arange(len(base))
    if mode == _TRIANGLES:
        triangles = indices[: len(indices) // 3 * 3].reshape(-1, 3)
    elif mode == _STRIP:  # every other triangle turned over, so that all face one way
        i = np.arange(max(len(indices) - 2, 0))
        odd = (i % 2).astype(bool)
        triangles = np.column_stack([indices[np.where(odd, i + 1, i)], indices[np.where(odd, i, i + 1)],
                                     indices[i + 2]])  # fmt: skip
    elif mode == _FAN:
        triangles = np.column_stack([np.full(max(len(indices) - 2, 0), indices[0]), indices[1:-1], indices[2:]])
    else:  # points and lines have no faces
        triangles = np.zeros((0, 3), dtype=np.int64)
    return points, triangles.reshape(-1, 3).astype(np.int64)


def _skin_attributes(document, where: str, attributes: dict, n: int, s: int):
    """A skinned primitive's JOINTS_n and WEIGHTS_n, read in pairs and concatenated: joints (V, K)
    checked to index skins[s]'s `n` joints, weights (V, K) as stored."""
    sets = sorted(k for k in attributes if k.startswith("JOINTS_"))
    if not sets or sorted(k for k in attributes if k.startswith("WEIGHTS_")) != [k.replace("JOINTS", "WEIGHTS")
                                                                                   for k in sets]:  # fmt: skip
        document.fail(f"{where}.attributes", "of a skinned mesh need JOINTS_n and WEIGHTS_n in pairs")
    joints = np.concatenate([document.typed(attributes[k], f"{where}.attributes.{k}", ("VEC4",), (5121, 5123))
                             for k in sets], axis=1)  # fmt: skip
    weights = np.concatenate([document.typed(attributes[k.replace("JOINTS", "WEIGHTS")],
                                             f"{where}.attributes.{k.replace('JOINTS', 'WEIGHTS')}", ("VEC4",),
                                             (5121, 5123, FLOAT)) for k in sets], axis=1)  # fmt: skip
    if joints.max() >= n:
        document.fail(f"{where}.attributes.{sets[0]}", f"refer to joint {joints.max()}; skins[{s}] has {n}")
    return joints, weights


def _skinned(document, where, skin, s, primitive, points, joint_world):
    """Linear blend skinning: sum over the vertex's joints of weight * (joint world @ inverse
    bind), on blocks of frames so that the per-vertex matrices stay small."""
    n = len(skin["joints"])
    joints, weights = _skin_attributes(document, where, primitive["attributes"], n, s)
    inverse = (
        document.accessor(skin["inverseBindMatrices"])[:n].reshape(-1, 4, 4).transpose(0, 2, 1)
        if "inverseBindMatrices" in skin
        else np.tile(np.eye(4), (n, 1, 1))
    )
    joint_matrices = (joint_world @ inverse)[..., :3, :]  # (T, J, 3, 4)
    total = weights.sum(axis=1, keepdims=True)
    weights = weights / np.where(total > 0, total, 1.0)
    frames, vertices = points.shape[:2]
    block = max(1, _SKIN_BLOCK_BYTES // max(1, vertices * 12 * 8))
    result = np.empty(points.shape)
    for start in range(0, frames, block):
        stop = min(start + block, frames)
        blended = np.zeros((stop - start, vertices, 3, 4))
        for slot in range(joints.shape[1]):
            blended += weights[None, :, slot, None, None] * joint_matrices[start:stop, joints[:, slot]]
        result[start:stop] = np.einsum("tvij,tvj->tvi", blended[..., :3], points[start:stop]) + blended[..., 3]
    return result


def skin_clips(path, fps, *, allow_outside: bool = False):
    """Per distinct skin, the skeleton (its joints and their ancestors, which carry the model's
    placement, parents first) and every animation that moves it, as the file keys it: yields
    (skin name, names, parents, rest translations (J, 3), rest rotations (J, 4), scales (J, 3),
    {clip name: (fps, [flockkit.Channel, ...])}), each channel one of the animation's rotation or
    translation channels with its own key times and interpolation. `fps` is the rate of the
    clips' evenly spaced frames (None: each animation's key rate). Scale channels must hold the
    joints' rest scales (flockkit skeletons keep scales fixed)."""
    document = Document(path, allow_outside=allow_outside)
    skins = document._list("skins")
    if not skins:
        raise ValidationError(f"{path}: has no skin; skeletal clips need one")
    if not document._list("animations"):
        raise ValidationError(f"{path}: has no animation")
    nodes = document._list("nodes")
    order = {node: k for k, node in enumerate(document.order)}
    seen = set()
    for s, skin in enumerate(skins):
        joints = frozenset(skin["joints"])
        if joints in seen:
            continue
        seen.add(joints)
        members = document.with_ancestors(joints)
        if any(m not in order for m in members):
            document.fail(f"skins[{s}].joints", "name nodes outside the default scene")
        chosen = sorted(members, key=order.__getitem__)
        index = {node: k for k, node in enumerate(chosen)}
        names = [nodes[n].get("name") or f"node {n}" for n in chosen]
        counts = Counter(names)
        names = [name if counts[name] == 1 else f"{name} ({n})" for name, n in zip(names, chosen)]
        translation, rotation, scale, _, _, fixed = document.trs(None, np.zeros(1), chosen)
        if fixed.any():
            document.fail(f"skins[{s}].joints", "name nodes placed by a matrix; flockkit skeletons need translation, "
                          "rotation and scale")  # fmt: skip
        clips = {}
        for a, name in enumerate(document.clip_names()):
            channels = _joint_channels(document, a, index, scale[0], f"{path}: clip {name!r}")
            if not channels:
                continue
            duration = max(c.duration for c in channels)
            rate = fps
            if rate is None:
                steps = np.concatenate([np.diff(c.times) for c in channels])
                steps = steps[steps > 1e-6]
                rate = float(np.round(1.0 / np.median(steps), 3)) if len(steps) else 30.0
                if rate > MAX_KEY_RATE:
                    document.fail(f"animations[{a}]", f"has keys {1 / rate:.3g} s apart ({rate:g} a second); read it "
                                  "with fps= to give its frames a rate of your choice")  # fmt: skip
            validate.allocation((duration * rate + 2) * len(chosen) * 30,
                                f"{path}: clip {name!r} ({duration:g} s) at {rate:g} fps")  # fmt: skip
            clips[name] = (rate, channels)
        parent = np.array([index.get(int(document.parent[n]), -1) for n in chosen])
        yield (
            skin.get("name") if isinstance(skin.get("name"), str) and skin.get("name") else f"skin {s}",
            names,
            parent,
            translation[0],
            rotation[0],
            scale[0],
            clips,
        )


def _joint_channels(document: Document, animation: int, index: dict, scales: np.ndarray, what: str) -> list:
    """The rotation and translation channels of `animation` that move the nodes of `index` (node
    -> joint), as flockkit Channels; LINEAR and STEP rotation keys normalized (the spec's slerp
    assumes unit quaternions; float32 and normalized integers round them)."""
    spec = document._list("animations")[animation]
    found = []
    for channel in spec["channels"]:
        node, path = channel["target"].get("node"), channel["target"].get("path")
        if node not in index or path == "weights":
            continue
        sampler = spec["samplers"][channel["sampler"]]
        interpolation = sampler.get("interpolation", "LINEAR")
        cubic = interpolation == "CUBICSPLINE"
        output = document.keys(animation, channel["sampler"], path)
        tangents = {"in_tangents": output[0::3], "out_tangents": output[2::3]} if cubic else {}
        values = output[1::3] if cubic else output
        if path == "scale":
            still = np.allclose(values, scales[index[node]], atol=1e-6) and all(
                np.allclose(t, 0, atol=1e-6) for t in tangents.values()
            )
            if not still:
                raise ValidationError(f"{what} animates joint scales, which flockkit clips do not hold")
            continue
        if path == "rotation" and not cubic:
            values = values / np.linalg.norm(values, axis=1, keepdims=True)
        found.append(Channel(joint=index[node], path=path, times=document.key_times(animation, channel["sampler"]),
                             values=values, interpolation=interpolation, **tangents))  # fmt: skip
    return found


# flockkit's axes (z up, metres) to glTF's (y up, metres): (x, y, z) -> (x, z, -y), the inverse
# of the conversion a glTF file is read into flockkit's axes with
_Y_UP = conversion_matrix(UP_AXIS, METERS_PER_UNIT).T
# the shared agent mesh: an arrow head 0.5 long and 0.3 wide pointing along +x (as the USD cone)
_ARROW = np.array([[0.25, 0, 0], [-0.25, 0.15, 0], [-0.25, -0.075, 0.13], [-0.25, -0.075, -0.13]], dtype=np.float32)
_ARROW_FACES = np.array([0, 1, 2, 0, 2, 3, 0, 3, 1, 1, 3, 2], dtype=np.uint16)


def write_gltf(motion: Motion, path) -> None:
    """A glTF 2.0 file (.glb binary, or .gltf with its buffer embedded as a data URI) that game
    engines, three.js and Blender read: a node "Flock" with one child node per agent ("Agent k",
    k the agent index) sharing a small arrow mesh that points along +x, and one animation,
    "flock", with a translation and a rotation channel per agent (linear, one key per frame at
    t = frame * dt seconds, the rotation facing the velocity). glTF is y up in meters: flockkit's
    (x, y, z) becomes (x, z, -y), so a 2D motion lies in the ground plane y = 0."""
    path = Path(path)
    positions = np.zeros((motion.n_frames, motion.n_agents, 3))
    positions[..., : motion.dims] = motion.positions
    velocities = np.zeros_like(positions)
    velocities[..., : motion.dims] = motion.velocities()
    quaternions = rigid.facing(velocities.reshape(-1, 3)).reshape(motion.n_frames, motion.n_agents, 4)  # w, x, y, z
    rotations = np.concatenate([quaternions[..., 1:] @ _Y_UP.T, quaternions[..., :1]], axis=2)  # x, y, z, w
    translations = positions @ _Y_UP.T
    times = (np.arange(motion.n_frames) * motion.dt).astype(np.float32)
    buffer, views, accessors = bytearray(), [], []

    def accessor(array, kind, component=FLOAT, bounds=False, target=None):
        array = np.ascontiguousarray(array)
        buffer.extend(b"\0" * (-len(buffer) % 4))
        views.append({"buffer": 0, "byteOffset": len(buffer), "byteLength": array.nbytes})
        if target is not None:
            views[-1]["target"] = target
        buffer.extend(array.tobytes())
        entry = {"bufferView": len(views) - 1, "componentType": component, "count": len(array), "type": kind}
        if bounds:
            flat = array.reshape(len(array), -1)
            entry["min"], entry["max"] = flat.min(axis=0).tolist(), flat.max(axis=0).tolist()
        accessors.append(entry)
        return len(accessors) - 1

    mesh = {
        "name": "agent",
        "primitives": [{"attributes": {"POSITION": accessor(_ARROW, "VEC3", bounds=True, target=34962)},
                        "indices": accessor(_ARROW_FACES, "SCALAR", UNSIGNED_SHORT, target=34963)}],
    }  # fmt: skip
    clock = accessor(times, "SCALAR", bounds=True)  # every sampler shares the key times
    nodes = [{"name": "Flock", "children": list(range(1, motion.n_agents + 1))}]
    samplers, channels = [], []
    for agent in range(motion.n_agents):
        nodes.append({
            "name": f"Agent {agent}", "mesh": 0,
            "translation": translations[0, agent].tolist(), "rotation": rotations[0, agent].tolist(),
        })  # fmt: skip
        for target, values, kind in (("translation", translations, "VEC3"), ("rotation", rotations, "VEC4")):
            samplers.append({"input": clock, "output": accessor(values[:, agent].astype(np.float32), kind)})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": agent + 1, "path": target}})
    buffer.extend(b"\0" * (-len(buffer) % 4))
    document = {
        "asset": {"version": "2.0", "generator": f"flockkit {__version__}"},
        "scene": 0, "scenes": [{"name": "flock", "nodes": [0]}], "nodes": nodes, "meshes": [mesh],
        "animations": [{"name": "flock", "samplers": samplers, "channels": channels}],
        "accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": len(buffer)}],
    }  # fmt: skip
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        if path.suffix.lower() == ".gltf":
            data = base64.b64encode(bytes(buffer)).decode("ascii")
            document["buffers"][0]["uri"] = f"data:application/octet-stream;base64,{data}"
            handle.write(json.dumps(document).encode("utf-8"))
            return
        handle.write(glb_bytes(document, buffer))
