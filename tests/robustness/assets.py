"""A tiny skinned, morphing, animated glTF asset written from the spec by hand, and its positions
worked out by hand: the base every damaged-asset case mutates, and a check that a correct file is
read as the spec says (LINEAR rotations by slerp, STEP translations, CUBICSPLINE morph weights).

The asset: an "Armature" node holding a two-joint skin ("root" at the origin, "tip" one unit along
x) and a one-triangle mesh ("Body"). Vertex 0 follows the root, vertices 1 and 2 the tip; a morph
target lifts vertex 2 by one unit along z. One animation, "wave", keyed at 0, 0.5 and 1 s: the tip
turns about z by 0, 90 and 180 degrees (LINEAR), the root steps to y = 0, 2, 4 (STEP), and the morph
weight goes 0, 1, 0 with zero tangents (CUBICSPLINE).
"""

from __future__ import annotations

import base64
import copy
import json
import math
import struct

import numpy as np

FPS = 4  # the frame rate EXPECTED is worked out at


def _expected() -> np.ndarray:
    """Positions (5, 3, 3) at 0, 0.25, 0.5, 0.75 and 1 s, from the asset's description:
    root translation T(t) (a step), tip angle 180 t degrees, morph weight w(t) (Hermite with zero
    tangents: 3u^2 - 2u^3 up, then down). Vertex 2 sits at (-1, 1, w) in the tip's bind space."""
    out = []
    for t in (0.0, 0.25, 0.5, 0.75, 1.0):
        lift = 0.0 if t < 0.5 else (2.0 if t < 1.0 else 4.0)
        u = (t % 0.5) / 0.5 if t < 1.0 else 1.0
        w = 3 * u * u - 2 * u**3 if t < 0.5 else (1 - (3 * u * u - 2 * u**3) if t < 1.0 else 0.0)
        angle = math.radians(180 * t)
        c, s = math.cos(angle), math.sin(angle)
        tip = (1 + (-1 * c - 1 * s), -1 * s + 1 * c + lift, w)
        out.append([(0.0, lift, 0.0), (1.0, lift, 0.0), tip])
    return np.array(out)


EXPECTED = _expected()


def tiny() -> tuple[dict, bytearray]:
    """(document, buffer) of the asset; the buffer is embedded by :func:`write`."""
    half = math.sqrt(0.5)
    parts = [
        ("<f4", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "VEC3", 5126),  # 0 POSITION
        ("<u2", [0, 1, 2, 0], "SCALAR", 5123),  # 1 indices (3, padded to 4 bytes)
        ("<u1", [[0, 0, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]], "VEC4", 5121),  # 2 JOINTS_0
        ("<f4", [[1, 0, 0, 0]] * 3, "VEC4", 5126),  # 3 WEIGHTS_0
        ("<f4", [[0, 0, 0], [0, 0, 0], [0, 0, 1]], "VEC3", 5126),  # 4 morph target
        (
            "<f4",
            [np.eye(4).T.ravel(), np.array([[1, 0, 0, -1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]).T.ravel()],
            "MAT4",
            5126,
        ),  # 5 inverse bind matrices, column-major  # fmt: skip
        ("<f4", [0.0, 0.5, 1.0], "SCALAR", 5126),  # 6 key times
        ("<f4", [[0, 0, 0, 1], [0, 0, half, half], [0, 0, 1, 0]], "VEC4", 5126),  # 7 tip rotations
        ("<f4", [[0, 0, 0], [0, 2, 0], [0, 4, 0]], "VEC3", 5126),  # 8 root translations
        ("<f4", [0, 0, 0, 0, 1, 0, 0, 0, 0], "SCALAR", 5126),  # 9 weights: (in, value, out) per key
    ]
    buffer, views, accessors = bytearray(), [], []
    for dtype, values, kind, component in parts:
        data = np.asarray(values, dtype=dtype).tobytes()
        views.append({"buffer": 0, "byteOffset": len(buffer), "byteLength": len(data)})
        count = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[kind]
        n = np.asarray(values).size // count - (1 if component == 5123 else 0)  # the index pad is not an element
        accessors.append({"bufferView": len(views) - 1, "componentType": component, "count": n, "type": kind})
        buffer += data + b"\0" * (-len(data) % 4)
    document = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"name": "Armature", "children": [1, 3]},
            {"name": "root", "children": [2]},
            {"name": "tip", "translation": [1.0, 0.0, 0.0]},
            {"name": "Body", "mesh": 0, "skin": 0},
        ],
        "meshes": [
            {
                "primitives": [
                    {
                        "attributes": {"POSITION": 0, "JOINTS_0": 2, "WEIGHTS_0": 3},
                        "indices": 1,
                        "targets": [{"POSITION": 4}],
                    }
                ]
            }
        ],  # fmt: skip
        "skins": [{"joints": [1, 2], "inverseBindMatrices": 5}],
        "animations": [
            {
                "name": "wave",
                "samplers": [
                    {"input": 6, "output": 7},
                    {"input": 6, "output": 8, "interpolation": "STEP"},
                    {"input": 6, "output": 9, "interpolation": "CUBICSPLINE"},
                ],
                "channels": [
                    {"sampler": 0, "target": {"node": 2, "path": "rotation"}},
                    {"sampler": 1, "target": {"node": 1, "path": "translation"}},
                    {"sampler": 2, "target": {"node": 3, "path": "weights"}},
                ],
            }
        ],  # fmt: skip
        "buffers": [{"byteLength": len(buffer)}],
        "bufferViews": views,
        "accessors": accessors,
    }
    return document, buffer


def offset(document: dict, accessor: int) -> int:
    """The byte offset in the buffer where accessor `accessor`'s data starts."""
    return document["bufferViews"][document["accessors"][accessor]["bufferView"]]["byteOffset"]


def write(path, document: dict, buffer: bytes, *, uri: str | None = None) -> None:
    """Write `document` to `path`: a .glb with `buffer` as its binary chunk, or a .gltf with the
    buffer as a data URI (or as `uri`, when given, leaving the file there to the caller)."""
    from flockkit.io.gltf import glb_bytes

    document = copy.deepcopy(document)
    if str(path).endswith(".glb"):
        path.write_bytes(glb_bytes(document, buffer))
        return
    if isinstance(document.get("buffers"), list) and document["buffers"] and isinstance(document["buffers"][0], dict):
        document["buffers"][0].setdefault(
            "uri", uri or "data:application/octet-stream;base64," + base64.b64encode(bytes(buffer)).decode()
        )
    path.write_text(json.dumps(document))


def floats(values) -> bytes:
    return struct.pack(f"<{len(values)}f", *values)
