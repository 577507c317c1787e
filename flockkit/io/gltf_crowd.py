"""A crowd of skinned characters as one binary glTF 2.0 file (.glb), as engines load one: the
mesh and its inverse bind matrices stored once, every agent its own skeleton of nodes and skin
drawing that one mesh, and one animation, "crowd", moving every agent's joints and root.

Agents that read one stream at one whole offset for the whole file share that stream's key
values: their channels' outputs are accessors into the stream's frames, starting where the agent
reads, so such an agent adds only JSON. Others hold their own frames. See
``flockkit.crowd.export_gltf`` for what is exact.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._atomic import atomic_path
from ..errors import ValidationError
from .gltf import glb_bytes

__all__ = ["write_gltf_crowd", "GLTF_CROWD_LIMIT"]

# The largest crowd file written, in bytes (JSON and binary): a .glb holds every agent's nodes,
# skin and channels, which engines and Blender load at once; a larger crowd is refused (export
# fewer agents or seconds, or write USD, which shares more).
GLTF_CROWD_LIMIT = 256 * 1024**2
FLOAT, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
# JSON bytes an agent's joint takes (node, two channels, two samplers, two accessors), measured
# on the Fox: for the size estimate checked before anything is written
JSON_PER_JOINT = 700


class _Buffer:
    """The binary chunk, built as bufferViews aligned to 4 bytes, and the accessors into it."""

    def __init__(self):
        self.parts, self.size, self.views, self.accessors = [], 0, [], []

    def view(self, array: np.ndarray, target=None) -> int:
        data = np.ascontiguousarray(array).tobytes()
        pad = (-self.size) % 4
        if pad:
            self.parts.append(b"\0" * pad)
            self.size += pad
        view = {"buffer": 0, "byteOffset": self.size, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.parts.append(data)
        self.size += len(data)
        self.views.append(view)
        return len(self.views) - 1

    def accessor(self, view: int, component: int, kind: str, count: int, offset: int = 0, bounds=None) -> int:
        entry = {"bufferView": view, "componentType": component, "count": int(count), "type": kind}
        if offset:
            entry["byteOffset"] = int(offset)
        if bounds is not None:
            entry["min"], entry["max"] = [float(v) for v in bounds[0]], [float(v) for v in bounds[1]]
        self.accessors.append(entry)
        return len(self.accessors) - 1

    def data(self, array: np.ndarray, component: int, kind: str, target=None, bounds: bool = False) -> int:
        array = np.asarray(array)
        flat = array.reshape(len(array), -1)
        limits = (flat.min(axis=0), flat.max(axis=0)) if bounds else None
        return self.accessor(self.view(array, target), component, kind, len(array), bounds=limits)


def write_gltf_crowd(path, *, names, joints, parents, rest_translations, rest_rotations, scales, mesh, fps: float,
                     n_frames: int, rotations, translations, runs=(), windows=None, samples=None,
                     roots=None) -> int:  # fmt: skip
    """Write the crowd to `path` (.glb), atomically; returns its size in bytes.

    `joints` (names), `parents`, the rest pose (`rest_translations` (J, 3), `rest_rotations` (J,
    4) x, y, z, w) and `scales` (J, 3) make each agent's joint nodes; `mesh` (``points``,
    ``faces``, ``joint_indices``, ``joint_weights``, optional ``normals``, ``inverse_bind`` (J, 4,
    4) column vectors) is stored once. Poses are rows of `rotations` (M, J, 4) and `translations`
    (M, J, 3); `runs` are row ranges (first, stop) of stream frames in order; agent k (named
    names[k]) reads ``windows[k] = (run, start)`` (frame f is the run's row first + start + f)
    or ``samples[k]``, its (n_frames,) rows. `roots` (translations (F, N, 3), quaternions (F, N,
    4), uniform scales (F, N)) place the agents; frame f is at f / `fps` seconds.

    A ValidationError names GLTF_CROWD_LIMIT when the file would be larger."""
    windows, samples = dict(windows or {}), dict(samples or {})
    rotations = np.asarray(rotations, np.float32)
    translations = np.asarray(translations, np.float32)
    n_joints, agents = len(joints), len(names)
    used_runs = sorted({run for run, _ in windows.values()})
    estimate = (
        sum(7 * 4 * n_joints * (runs[r][1] - runs[r][0]) for r in used_runs)
        + len(samples) * n_frames * n_joints * 28
        + (agents * n_frames * 40 if roots is not None else 0)
        + agents * n_joints * JSON_PER_JOINT
        + len(mesh["points"]) * 64
        + len(mesh["faces"]) * 12
    )
    if estimate > GLTF_CROWD_LIMIT:
        raise ValidationError(
            f"{path}: a glTF crowd of {agents} agents x {n_frames} frames would take about {estimate / 2**20:.0f} "
            f"MiB; GLTF_CROWD_LIMIT is {GLTF_CROWD_LIMIT / 2**20:.0f} MiB (export fewer agents or seconds, or USD)"
        )
    buffer = _Buffer()
    points = np.asarray(mesh["points"], np.float32)
    attributes = {"POSITION": buffer.data(points, FLOAT, "VEC3", ARRAY_BUFFER, bounds=True)}
    if mesh.get("normals") is not None:
        normals = np.asarray(mesh["normals"], np.float64)
        normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        attributes["NORMAL"] = buffer.data(normals.astype(np.float32), FLOAT, "VEC3", ARRAY_BUFFER)
    influences = np.asarray(mesh["joint_indices"])
    weights = np.asarray(mesh["joint_weights"], np.float64)
    width = -(-influences.shape[1] // 4) * 4
    influences = np.pad(influences, ((0, 0), (0, width - influences.shape[1])))
    weights = np.pad(weights, ((0, 0), (0, width - weights.shape[1])))
    influences = np.where(weights > 0, influences, 0)  # an unweighted slot names joint 0
    weights = (weights / weights.sum(axis=1, keepdims=True)).astype(np.float32)
    for k in range(width // 4):
        attributes[f"JOINTS_{k}"] = buffer.data(influences[:, 4 * k : 4 * k + 4].astype(np.uint16), UNSIGNED_SHORT,
                                                "VEC4", ARRAY_BUFFER)  # fmt: skip
        attributes[f"WEIGHTS_{k}"] = buffer.data(weights[:, 4 * k : 4 * k + 4], FLOAT, "VEC4", ARRAY_BUFFER)
    faces = np.asarray(mesh["faces"]).ravel().astype(np.uint32)
    indices = buffer.data(faces, UNSIGNED_INT, "SCALAR", ELEMENT_ARRAY_BUFFER)
    inverse_bind = buffer.data(np.asarray(mesh["inverse_bind"], np.float32).transpose(0, 2, 1), FLOAT, "MAT4")
    times = (np.arange(n_frames) / fps).astype(np.float32)
    time = buffer.data(times, FLOAT, "SCALAR", bounds=True)

    # each run's frames joint by joint, so that a joint's frames from any start are one accessor
    blocks = {}
    for r in used_runs:
        first, stop = runs[r]
        blocks[r] = (buffer.view(rotations[first:stop].transpose(1, 0, 2)),
                     buffer.view(translations[first:stop].transpose(1, 0, 2)), stop - first)  # fmt: skip
    nodes, skins, channels, samplers, scene = [], [], [], [], []
    rest_t = np.asarray(rest_translations, np.float64)
    rest_r = np.asarray(rest_rotations, np.float64)
    scales = np.asarray(scales, np.float64)

    def animate(node: int, path: str, accessor: int) -> None:
        samplers.append({"input": time, "output": accessor, "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})

    for k, name in enumerate(names):
        root = len(nodes)
        nodes.append({"name": name, "children": []})
        first_joint = len(nodes)
        for j in range(n_joints):
            node = {"name": joints[j], "translation": rest_t[j].tolist(),
                    "rotation": (rest_r[j] / np.linalg.norm(rest_r[j])).tolist()}  # fmt: skip
            if not np.allclose(scales[j], 1):
                node["scale"] = scales[j].tolist()
            nodes.append(node)
            parent = root if parents[j] < 0 else first_joint + int(parents[j])
            nodes[parent].setdefault("children", []).append(first_joint + j)
        if k in windows:
            run, start = windows[k]
            turns, moves, length = blocks[run]
            for j in range(n_joints):
                animate(first_joint + j, "rotation",
                        buffer.accessor(turns, FLOAT, "VEC4", n_frames, offset=(j * length + start) * 16))  # fmt: skip
                animate(first_joint + j, "translation",
                        buffer.accessor(moves, FLOAT, "VEC3", n_frames, offset=(j * length + start) * 12))  # fmt: skip
        else:
            rows = np.asarray(samples[k])
            turns = buffer.view(rotations[rows].transpose(1, 0, 2))
            moves = buffer.view(translations[rows].transpose(1, 0, 2))
            for j in range(n_joints):
                animate(first_joint + j, "rotation",
                        buffer.accessor(turns, FLOAT, "VEC4", n_frames, offset=j * n_frames * 16))  # fmt: skip
                animate(first_joint + j, "translation",
                        buffer.accessor(moves, FLOAT, "VEC3", n_frames, offset=j * n_frames * 12))  # fmt: skip
        if roots is not None:
            _place(nodes[root], root, roots[0][:, k], roots[1][:, k], roots[2][:, k], buffer, animate)
        skins.append({"name": name, "joints": list(range(first_joint, first_joint + n_joints)),
                      "inverseBindMatrices": inverse_bind, "skeleton": root})  # fmt: skip
        scene += [root, len(nodes)]
        nodes.append({"name": f"{name} body", "mesh": 0, "skin": k})  # a root node: glTF skins ignore parents
    for node in nodes:
        if not node.get("children", True):
            del node["children"]
    document = {
        "asset": {"version": "2.0", "generator": "flockkit"},
        "scene": 0,
        "scenes": [{"name": "Crowd", "nodes": scene}],
        "nodes": nodes,
        "meshes": [
            {
                "name": mesh.get("name", "character"),
                "primitives": [{"attributes": attributes, "indices": indices, "mode": 4}],
            }
        ],  # fmt: skip
        "skins": skins,
        "animations": [{"name": "crowd", "channels": channels, "samplers": samplers}],
        "accessors": buffer.accessors,
        "bufferViews": buffer.views,
        "buffers": [{"byteLength": buffer.size}],
    }
    data = glb_bytes(document, b"".join(buffer.parts))
    with atomic_path(Path(path)) as tmp:
        Path(tmp).write_bytes(data)
    return len(data)


def _place(node: dict, index: int, moves, turns, sizes, buffer: _Buffer, animate) -> None:
    """An agent's root node: a fixed translation, rotation and scale where they never change,
    else a channel each."""
    for path, values, kind in (("translation", moves, "VEC3"), ("rotation", turns, "VEC4"),
                               ("scale", np.repeat(np.asarray(sizes)[:, None], 3, axis=1), "VEC3")):  # fmt: skip
        values = np.asarray(values, np.float64)
        if path == "rotation":
            values = values / np.linalg.norm(values, axis=1, keepdims=True)
        if np.all(values == values[0]):
            node[path] = values[0].tolist()
        else:
            animate(index, path, buffer.data(values.astype(np.float32), FLOAT, kind))
