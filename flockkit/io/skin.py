"""A glTF character's skinned mesh in its bind pose, bound to the skeleton ``read_clips`` reads:
what a GPU skinning shader draws (``flockkit.crowd.skin`` is its reference).

glTF skins a vertex by linear blend skinning (spec 3.7.3): the sum over its joints of weight *
(joint world @ inverse bind matrix) @ position. The inverse bind matrices (one per skin joint),
the vertices' JOINTS_n / WEIGHTS_n and positions are read here from the validated document of
``flockkit.io.gltf``; joint indices are turned into the skeleton's (the skin's joints and their
ancestors, in the order ``read_clips`` gives them), so that a pose of that skeleton skins the mesh.

Characters built of rigid parts (a robot's limbs are meshes hung under its joints, not skinned)
are skinned too, as game engines bake them: each vertex of a mesh node that is not skinned but
hangs under a skeleton node follows the nearest such node with weight 1, its position moved into
that joint's bind space, so that joint world @ inverse bind @ position is where the node puts it.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import attrs
import numpy as np

from .. import validate
from .._arrays import readonly_float, readonly_int
from ..errors import ValidationError
from ..mesh import MeshSkin
from . import gltf

__all__ = ["SkinnedMesh", "read_skin", "mesh_skin", "BIND_TOLERANCE"]

# Two skins of one skeleton may give a joint different inverse bind matrices (each mesh bound in
# its own space); a vertex is then moved into the first skin's bind space, which needs the same
# change of space for every joint it follows: equal to this, relative to the matrices' size.
BIND_TOLERANCE = 1e-5
# Skinning works on blocks of instances whose blended matrices take about this many bytes.
_BLOCK_BYTES = 64 * 1024**2


def _positions(value):
    return readonly_float(value, field="SkinnedMesh.positions")


@attrs.frozen(kw_only=True, eq=False)
class SkinnedMesh:
    """A mesh in its bind pose and the joints that move it (linear blend skinning).

    Parameters
    ----------
    joint_names : sequence of str
        The skeleton's joints (``Skeleton.names`` of the clips ``read_clips`` reads from the same
        file), in its order: `joints` and `inverse_bind` index them.
    positions : (V, 3)
        Vertex positions in bind space (what the inverse bind matrices take to each joint's
        space).
    faces : (F, 3) int
        Triangles, vertex indices.
    joints : (V, K) int
        Each vertex's joints (skeleton indices), K influences a vertex (4 for JOINTS_0).
    weights : (V, K)
        Their weights, >= 0, each row summing to 1.
    inverse_bind : (J, 4, 4)
        Every skeleton joint's inverse bind matrix (column vectors): the skin's, or for a joint
        no skin lists (an armature above the skin) the inverse of its rest world transform.
    normals : (V, 3), optional
        Unit vertex normals in bind space, where every mesh has them.
    name : str

    A vertex skinned by a pose of world joint matrices W lies at
    ``sum_k weights[v, k] * (W[j] @ inverse_bind[j] @ (positions[v], 1))``, j = joints[v, k].
    """

    joint_names: tuple = attrs.field(converter=tuple)
    positions: np.ndarray = attrs.field(converter=_positions)
    faces: np.ndarray = attrs.field(converter=lambda v: readonly_int(v, field="SkinnedMesh.faces"))
    joints: np.ndarray = attrs.field(converter=lambda v: readonly_int(v, field="SkinnedMesh.joints"))
    weights: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="SkinnedMesh.weights"))
    inverse_bind: np.ndarray = attrs.field(converter=lambda v: readonly_float(v, field="SkinnedMesh.inverse_bind"))
    normals: np.ndarray | None = attrs.field(
        default=None, converter=lambda v: None if v is None else readonly_float(v, field="SkinnedMesh.normals")
    )
    name: str = attrs.field(default="mesh")

    def __attrs_post_init__(self):
        j = len(self.joint_names)
        if not j or not all(isinstance(n, str) and n for n in self.joint_names):
            raise ValidationError("SkinnedMesh.joint_names must be non-empty strings, one per skeleton joint")
        v = len(self.positions)
        if self.positions.ndim != 2 or self.positions.shape[1] != 3 or v == 0:
            raise ValidationError(f"SkinnedMesh.positions must have shape (V, 3), V >= 1; got {self.positions.shape}")
        for name in ("positions", "weights", "inverse_bind") + (("normals",) if self.normals is not None else ()):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValidationError(f"SkinnedMesh.{name} must be finite")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise ValidationError(f"SkinnedMesh.faces must have shape (F, 3); got {self.faces.shape}")
        if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= v):
            raise ValidationError(f"SkinnedMesh.faces must index the {v} vertices")
        if self.joints.ndim != 2 or self.joints.shape[0] != v or self.joints.shape[1] < 1:
            raise ValidationError(f"SkinnedMesh.joints must have shape ({v}, K), K >= 1; got {self.joints.shape}")
        if self.joints.min() < 0 or self.joints.max() >= j:
            raise ValidationError(f"SkinnedMesh.joints must index the {j} joints of joint_names")
        if self.weights.shape != self.joints.shape:
            raise ValidationError(f"SkinnedMesh.weights must have the shape of joints {self.joints.shape}; got "
                                  f"{self.weights.shape}")  # fmt: skip
        if self.weights.min() < 0 or np.abs(self.weights.sum(axis=1) - 1).max() > 1e-6:
            raise ValidationError("SkinnedMesh.weights must be >= 0 and each vertex's must sum to 1")
        if self.inverse_bind.shape != (j, 4, 4):
            raise ValidationError(f"SkinnedMesh.inverse_bind must have shape ({j}, 4, 4); got "
                                  f"{self.inverse_bind.shape}")  # fmt: skip
        if self.normals is not None and self.normals.shape != (v, 3):
            raise ValidationError(f"SkinnedMesh.normals must have shape ({v}, 3); got {self.normals.shape}")

    @property
    def n_vertices(self) -> int:
        """V, the number of vertices."""
        return len(self.positions)

    def check_skeleton(self, skeleton, *, field: str = "skeleton") -> None:
        """ValidationError naming `field` unless `skeleton` (a ``flockkit.Skeleton``) has this
        mesh's joints, in its order."""
        names = getattr(skeleton, "names", None)
        if names != self.joint_names:
            raise ValidationError(
                f"{field}: the mesh {self.name!r} is bound to {len(self.joint_names)} joints "
                f"({', '.join(self.joint_names[:3])}, ...) and the skeleton has others; read both from one file"
            )

    def weight_matrix(self) -> np.ndarray:
        """Each vertex's weight per joint (V, J), zero where it does not follow the joint: linear
        blend skinning as one matrix product."""
        j = len(self.joint_names)
        flat = np.arange(self.n_vertices)[:, None] * j + self.joints
        return np.bincount(flat.ravel(), self.weights.ravel(), minlength=self.n_vertices * j).reshape(-1, j)

    def skin_with(self, matrices, *, normals: bool = False):
        """Positions (n, V, 3) of the mesh skinned by skinning matrices `matrices` (n, J, 3, 4)
        (rows 0-2 of joint world @ inverse bind), and with `normals` also the normals (n, V, 3)
        turned by each vertex's blended 3 x 3 part and normalized: each vertex's matrices blended
        by its weights, then applied (what a skinning shader does), in blocks of instances."""
        matrices = np.asarray(matrices, dtype=np.float64)
        j = len(self.joint_names)
        if matrices.ndim != 4 or matrices.shape[1:] != (j, 3, 4):
            raise ValidationError(f"skin_with: matrices must have shape (n, {j}, 3, 4); got {matrices.shape}")
        if normals and self.normals is None:
            raise ValidationError(f"skin_with: the mesh {self.name!r} has no normals")
        n, v = len(matrices), self.n_vertices
        validate.allocation(n * v * (6 if normals else 3), f"skinning {n} instances of {v} vertices")
        weights = self.weight_matrix()
        points = np.concatenate([self.positions, np.ones((v, 1))], axis=1)[:, :, None]
        positions = np.empty((n, v, 3))
        turned = np.empty((n, v, 3)) if normals else None
        block = max(1, _BLOCK_BYTES // (v * 12 * 8))
        for start in range(0, n, block):
            stop = min(start + block, n)
            mixed = np.matmul(weights, matrices[start:stop].reshape(stop - start, j, 12)).reshape(-1, v, 3, 4)
            positions[start:stop] = (mixed @ points)[..., 0]
            if normals:
                turned[start:stop] = (mixed[..., :3] @ self.normals[:, :, None])[..., 0]
        if not normals:
            return positions
        turned /= np.linalg.norm(turned, axis=-1, keepdims=True)
        return positions, turned

    def skinned(self, world) -> np.ndarray:
        """Positions (..., V, 3) of the mesh skinned by world joint matrices `world` (..., J, 4, 4):
        linear blend skinning, directly from the poses (the check of every faster skinning)."""
        world = np.asarray(world, dtype=np.float64)
        if world.shape[-3:] != (len(self.joint_names), 4, 4):
            raise ValidationError(f"skinned: world must have shape (..., {len(self.joint_names)}, 4, 4); "
                                  f"got {world.shape}")  # fmt: skip
        matrices = (world @ self.inverse_bind)[..., :3, :]
        flat = matrices.reshape((-1,) + matrices.shape[-3:])
        return self.skin_with(flat).reshape(world.shape[:-3] + (self.n_vertices, 3))


def _skeleton_nodes(document, s: int):
    """The nodes of skin `s`'s skeleton (its joints and their ancestors, in the default scene's
    order) and their names, exactly as ``gltf.skin_clips`` (and so ``read_clips``) makes them."""
    nodes = document._list("nodes")
    order = {node: k for k, node in enumerate(document.order)}
    members = document.with_ancestors(frozenset(document._list("skins")[s]["joints"]))
    if any(m not in order for m in members):
        document.fail(f"skins[{s}].joints", "name nodes outside the default scene")
    chosen = sorted(members, key=order.__getitem__)
    names = [nodes[n].get("name") or f"node {n}" for n in chosen]
    counts = Counter(names)
    return chosen, [name if counts[name] == 1 else f"{name} ({n})" for name, n in zip(names, chosen)]


def _skin_index(document, skin) -> int:
    skins = document._list("skins")
    if not skins:
        raise ValidationError(f"{document.path}: has no skin")
    if skin is None:
        return 0
    if isinstance(skin, (int, np.integer)) and not isinstance(skin, bool) and 0 <= skin < len(skins):
        return int(skin)
    names = [s.get("name") if isinstance(s.get("name"), str) and s.get("name") else f"skin {k}"
             for k, s in enumerate(skins)]  # fmt: skip
    if skin in names:
        return names.index(skin)
    raise ValidationError(f"{document.path}: read_skin: no skin {skin!r}; its skins are {', '.join(map(repr, names))}")


def _unit(vectors: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(vectors, axis=1, keepdims=True)
    return vectors / np.where(length > 0, length, 1.0)


def read_skin(path, *, skin=None, allow_outside: bool = False) -> SkinnedMesh:
    """The skinned mesh of a glTF character (.glb, .gltf) in its bind pose, bound to the skeleton
    of skin `skin` (an index or a name; default the first), as ``read_clips`` reads it.

    Every mesh of the default scene that moves with that skeleton is taken, in the scene's order:
    meshes skinned by a skin of the same joints (JOINTS_n / WEIGHTS_n, weights normalized to sum
    1, inverse bind matrices from the skin), and meshes that are not skinned but hang under one of
    its nodes (weight 1 on that node; see the module). Morph targets keep their default weights
    (animated morph weights are not skinning). Normals are kept where every mesh has them.

    Raises FileNotFoundError, FileFormatError (a malformed file, naming it and the JSON path) and
    ValidationError (no skin, no mesh that the skeleton moves, or two skins binding a joint in
    spaces that no vertex can be moved between).
    """
    document = gltf.Document(Path(path), allow_outside=allow_outside)
    s = _skin_index(document, skin)
    skins, nodes, meshes = document._list("skins"), document._list("nodes"), document._list("meshes")
    chosen, names = _skeleton_nodes(document, s)
    column = {node: k for k, node in enumerate(chosen)}
    group = [k for k, other in enumerate(skins) if frozenset(other["joints"]) == frozenset(skins[s]["joints"])]
    placed = document.with_ancestors([n for n in document.order if "mesh" in nodes[n]] + chosen)
    rest, weights_at_rest = document.world(None, np.zeros(1), placed)
    world = {node: rest[0, k] for k, node in enumerate(placed)}  # rest world transforms

    def ibm_of(k: int) -> np.ndarray:
        spec = skins[k]
        n = len(spec["joints"])
        if "inverseBindMatrices" not in spec:
            return np.tile(np.eye(4), (n, 1, 1))
        return document.accessor(spec["inverseBindMatrices"])[:n].reshape(-1, 4, 4).transpose(0, 2, 1)

    def invertible(node: int, matrix: np.ndarray, what: str) -> np.ndarray:
        if abs(np.linalg.det(matrix[:3, :3])) <= 1e-12 * max(1e-300, float(np.abs(matrix[:3, :3]).max()) ** 3):
            document.fail(f"nodes[{node}]", f"has {what} that cannot be inverted (a zero scale): no bind space")
        return matrix

    def inverted(node: int, matrix: np.ndarray, what: str = "a rest transform") -> np.ndarray:
        return np.linalg.inv(invertible(node, matrix, what))

    # each joint's inverse bind matrix: from the first skin of the group that lists it, else the
    # inverse of its rest world transform (an armature node above the skin)
    inverse = np.zeros((len(chosen), 4, 4))
    given = np.zeros(len(chosen), dtype=bool)
    for k in group:
        for joint, matrix in zip(skins[k]["joints"], ibm_of(k)):
            if not given[column[joint]]:
                inverse[column[joint]] = invertible(joint, matrix, f"an inverse bind matrix in skins[{k}]")
                given[column[joint]] = True
    for j in np.flatnonzero(~given):
        inverse[j] = inverted(chosen[j], world[chosen[j]])
    positions, normals, faces, joints, weights = [], [], [], [], []
    count, every_normal, width = 0, True, 1
    for node in document.order:
        spec = nodes[node]
        if "mesh" not in spec:
            continue
        if "skin" in spec and spec["skin"] not in group:
            continue
        anchor = node
        while "skin" not in spec and anchor >= 0 and anchor not in column:
            anchor = int(document.parent[anchor])
        if anchor < 0:
            continue  # neither skinned by this skeleton nor hung under it
        for p, primitive in enumerate(meshes[spec["mesh"]]["primitives"]):
            where = f"meshes[{spec['mesh']}].primitives[{p}]"
            attributes = primitive["attributes"]
            if "POSITION" not in attributes:
                document.fail(f"{where}.attributes", "have no POSITION")
            points, triangles = gltf._primitive(document, where, primitive, weights_at_rest.get(node), 1)
            points = points[0]
            normal = None
            if "NORMAL" in attributes:
                normal = document.typed(attributes["NORMAL"], f"{where}.attributes.NORMAL", ("VEC3",),
                                        tuple(gltf._COMPONENTS))  # fmt: skip
            if "skin" in spec:
                k = spec["skin"]
                local, vw = _influences(document, where, attributes, len(skins[k]["joints"]), k)
                vj = np.array([column[j] for j in skins[k]["joints"]])[local]
                points, normal = _into_bind_space(inverse[vj], ibm_of(k)[local], vw, points, normal,
                                                  f"{path}: skins[{k}]", names)  # fmt: skip
            else:
                j = column[anchor]
                move = np.linalg.inv(inverse[j]) @ inverted(anchor, world[anchor]) @ world[node]
                points = points @ move[:3, :3].T + move[:3, 3]
                if normal is not None:
                    normal = _unit(normal @ np.linalg.inv(move[:3, :3]))
                vj = np.full((len(points), 1), j)
                vw = np.ones((len(points), 1))
            width = max(width, vj.shape[1])
            positions.append(points)
            normals.append(normal)
            every_normal &= normal is not None
            faces.append(triangles + count)
            joints.append(vj)
            weights.append(vw)
            count += len(points)
    if not positions:
        raise ValidationError(f"{path}: read_skin: no mesh of the default scene moves with skin {s}'s skeleton")
    pad = lambda arrays: np.concatenate([np.pad(a, ((0, 0), (0, width - a.shape[1]))) for a in arrays])  # noqa: E731
    asset = document.json["asset"]
    title = asset.get("extras", {}).get("title") if isinstance(asset.get("extras"), dict) else None
    return SkinnedMesh(
        joint_names=names,
        positions=np.concatenate(positions),
        faces=np.concatenate(faces),
        joints=pad(joints),
        weights=pad(weights),
        inverse_bind=inverse,
        normals=np.concatenate(normals) if every_normal else None,
        name=title if isinstance(title, str) and title else Path(path).stem,
    )


def mesh_skin(document) -> MeshSkin | None:
    """The skin (a ``flockkit.MeshSkin``) of the vertices ``gltf.mesh_animation`` reads from the
    opened, checked `document` (every mesh node of the default scene, in its order): the joints of
    the first skeleton (in the order of the skins) that moves every one of those meshes (skinned
    by a skin of its joints, or hung under one of its nodes, weight 1 on that node: see the
    module), with their parents, as ``read_clips`` names and orders them. None where the file
    has no skin, or no one skeleton moves every mesh (a prop no joint carries).

    Every joint index is checked against its skin's joints and every weight read and normalized as
    :func:`read_skin` does (FileFormatError naming the file and the JSON path)."""
    skins, nodes = document._list("skins"), document._list("nodes")
    placed = [n for n in document.order if "mesh" in nodes[n]]
    seen = set()
    for s, spec in enumerate(skins):
        joints = frozenset(spec["joints"])
        if joints in seen or not placed:
            continue
        seen.add(joints)
        chosen, names = _skeleton_nodes(document, s)
        column = {node: k for k, node in enumerate(chosen)}
        group = {k for k, other in enumerate(skins) if frozenset(other["joints"]) == joints}
        found = _influences_of(document, placed, column, group)
        if found is None:
            continue
        if len(set(names)) != len(names):  # a node named like another's "name (index)"
            names = [f"node {n}" for n in chosen]
        parents = [column.get(int(document.parent[n]), -1) for n in chosen]
        return MeshSkin(joint_names=names, parents=parents, joints=found[0], weights=found[1])
    return None


def _influences_of(document, placed: list, column: dict, group: set):
    """(joints (V, K), weights (V, K)) of the primitives of the mesh nodes `placed`, in order,
    each vertex's joints as indices of the skeleton `column` (node -> joint) whose skins are
    `group`; None where some mesh is neither skinned by one of them nor hung under the skeleton."""
    skins, nodes, meshes = document._list("skins"), document._list("nodes"), document._list("meshes")
    joints, weights, width = [], [], 1
    for node in placed:
        spec = nodes[node]
        anchor = node
        if "skin" in spec:
            if spec["skin"] not in group:
                return None
        else:
            while anchor >= 0 and anchor not in column:
                anchor = int(document.parent[anchor])
            if anchor < 0:
                return None
        for p, primitive in enumerate(meshes[spec["mesh"]]["primitives"]):
            where = f"meshes[{spec['mesh']}].primitives[{p}]"
            attributes = primitive["attributes"]
            if "POSITION" not in attributes:
                document.fail(f"{where}.attributes", "have no POSITION")
            count = document._accessor_count(attributes["POSITION"])
            if "skin" in spec:
                k = spec["skin"]
                local, vw = _influences(document, where, attributes, len(skins[k]["joints"]), k)
                vj = np.array([column[j] for j in skins[k]["joints"]])[local]
            else:
                vj, vw = np.full((count, 1), column[anchor]), np.ones((count, 1))
            width = max(width, vj.shape[1])
            joints.append(vj)
            weights.append(vw)
    pad = lambda arrays: np.concatenate([np.pad(a, ((0, 0), (0, width - a.shape[1]))) for a in arrays])  # noqa: E731
    return pad(joints), pad(weights)


def _influences(document, where: str, attributes: dict, n: int, s: int):
    """Each vertex's skin joints (V, K) (indices into skins[s].joints) and weights (V, K), the
    weights normalized to sum 1 (spec 3.7.3.1: they should; exporters round)."""
    joints, weights = gltf._skin_attributes(document, where, attributes, n, s)
    if weights.min() < 0:
        document.fail(f"{where}.attributes.WEIGHTS_0", "hold negative weights")
    total = weights.sum(axis=1, keepdims=True)
    if np.any(total <= 0):
        document.fail(f"{where}.attributes.WEIGHTS_0", f"give vertex {int(np.argmax(total[:, 0] <= 0))} no weight")
    weights = weights / total
    joints = np.where(weights > 0, joints, joints[:, :1])  # an unweighted slot's joint never matters
    return joints, weights


def _into_bind_space(chosen, own, weights, points, normals, what: str, names):
    """Vertices of a skin whose inverse bind matrices `own` (V, K, 4, 4) differ from the
    skeleton's `chosen` (V, K, 4, 4), moved into the skeleton's bind space: chosen^-1 @ own,
    which must be one matrix for all of a vertex's weighted joints."""
    change = np.linalg.solve(chosen, own)  # (V, K, 4, 4)
    first = change[:, 0]
    scale = max(1.0, float(np.abs(change).max()))
    off = np.abs(change - first[:, None]).max(axis=(2, 3)) * (weights > 0)
    if off.max() > BIND_TOLERANCE * scale:
        v = int(np.argmax(off.max(axis=1)))
        raise ValidationError(
            f"{what} binds vertex {v}'s joints in other spaces than the first skin of the skeleton does "
            f"(joint {names[int(np.argmax(off[v]))]!r} differs by {off.max():.3g}); skin it with that skin's "
            "skeleton alone"
        )
    if np.abs(first - np.eye(4)).max() <= BIND_TOLERANCE * scale:
        return points, normals
    points = np.einsum("vij,vj->vi", first[:, :3, :3], points) + first[:, :3, 3]
    if normals is not None:
        normals = _unit(np.einsum("vji,vj->vi", np.linalg.inv(first[:, :3, :3]), normals))
    return points, normals
