"""Baked animation textures for GPU skinning: a crowd's streams (or a character's clips) written
once into one float32 texture, an instance buffer that says where each agent part reads it this
frame, a reference vertex shader (GLSL 330, ``shaders/crowd_skinning.vert``) and its numpy
reference (:func:`skin`). What Unity's Animation Instancing, Unreal's AnimToTexture and vertex
animation texture tools do, fitted to paper 003's streams, offsets, time dilation and blends.

The texture (:class:`AnimationTextures`) holds, for every frame of every stream and every joint,
five RGBA32F texels: the three rows of the joint's skinning matrix (joint world @ inverse bind,
what a vertex following that joint alone is multiplied by) and the joint's local rotation and
translation. A part that reads a whole frame and is not blending (every part of a settled crowd)
is skinned from the three matrix rows alone. A part between two frames (time dilation) or
blending to another stream reads the local transforms of both frames (and both streams), mixes
them as the crowd runtime does (rotations slerped between frames, blends nlerped; translations
linearly) and runs forward kinematics up the joint's chain: mixing skinning matrices instead
(what vertex animation textures do) would shrink limbs mid-blend, and would not be the pose
``Crowd.poses`` gives. So a part skinned from the textures is where ``Crowd.poses`` puts it, to
float32 precision, in every case.

A stream is baked by evaluating its controller (a function of its clock alone) at every frame a
crowd run of `seconds` can reach; a stream whose poses repeat (a looping clip whose length is a
whole number of frames) keeps one loop, checked against every frame of the run (within
`loop_tolerance`), so that its texture does not grow with the run.
"""

from __future__ import annotations

import json
import math
import struct
from importlib import resources
from pathlib import Path

import attrs
import numpy as np

from .. import _files, rigid, validate
from .._atomic import atomic_path
from ..errors import FileFormatError, ValidationError
from ..io.skin import SkinnedMesh
from ..skeleton import Pose, SkeletalClip, Skeleton
from .pool import StreamPool

__all__ = [
    "AnimationTextures",
    "bake_textures",
    "instances",
    "instance_buffer",
    "skin",
    "skinning_matrices",
    "shader_source",
    "TEXTURE_INSTANCE",
    "TEXELS_PER_JOINT",
    "SKELETON_TEXELS",
    "LOOP_TOLERANCE",
]

# Per joint and frame: skinning matrix rows 0, 1, 2; local rotation (x, y, z, w); local
# translation (x, y, z, 0). 80 bytes of RGBA32F.
TEXELS_PER_JOINT = 5
# Per joint, the skeleton texture: inverse bind matrix rows 0, 1, 2; (scale x, y, z, parent).
SKELETON_TEXELS = 4
# A stream is kept as a loop of P frames when every frame it plays in the run is within this of
# frame k mod P (bake_textures' loop_tolerance): rotations and the linear part of skinning matrices
# relative to their size, translations relative to the skeleton's. A looping clip drifts by the
# float32 rounding of its length each loop (the Fox's walk: 2e-8 s a loop at 24 fps, past 1e-5
# after about 40 s), so a long run bakes it whole unless a looser tolerance is asked for.
LOOP_TOLERANCE = 1e-5
FORMAT, FORMAT_VERSION, MAGIC = "flockkit-animation-textures", 1, b"FKANIMTX"
SHADER = "crowd_skinning.vert"

# What the vertex shader reads per agent part (one instance), little-endian, 48 bytes.
TEXTURE_INSTANCE = np.dtype(
    [
        ("texture", "<i4"),  # the texture (stream) read; -1: no part to draw
        ("frame", "<f4"),  # where in it: frames from its start, wrapped round its loop
        ("target", "<i4"),  # the texture blended to; -1: not blending
        ("target_frame", "<f4"),
        ("weight", "<f4"),  # blend weight α: 0 the source alone, 1 the target
        ("rows", "<i4", (4,)),  # texture rows: source frame a, b; target frame a, b (-1: none)
        ("fractions", "<f4", (2,)),  # how far from row a to row b: source, target
        ("visible", "<u4"),  # 1 where the part is shown (the crowd's visibility mask)
    ]
)


def _inverse_bind(value, j: int, field: str = "AnimationTextures.inverse_bind") -> np.ndarray:
    """`value` (J, 4, 4) affine matrices, rounded to float32 as the GPU holds them."""
    try:
        matrices = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{field} must be an array of numbers: {exc}") from None
    if matrices.shape != (j, 4, 4):
        raise ValidationError(f"{field} must have shape ({j}, 4, 4); got {matrices.shape}")
    if not np.all(np.isfinite(matrices)):
        raise ValidationError(f"{field} must be finite")
    if np.abs(matrices[:, 3] - [0, 0, 0, 1]).max() > 1e-6:
        raise ValidationError(f"{field} must be affine (last row 0, 0, 0, 1)")
    out = matrices.astype(np.float32).astype(np.float64)
    out[:, 3] = [0, 0, 0, 1]
    out.setflags(write=False)
    return out


def _readonly(value, dtype, field: str) -> np.ndarray:
    """`value` as a new read-only array of `dtype`; integers must be given as integers."""
    try:
        given = np.asarray(value)
        if np.dtype(dtype).kind == "i" and given.size and given.dtype.kind not in "iu":
            raise TypeError(f"holds {given.dtype}")
        array = np.array(given, dtype=dtype, copy=True)
    except (TypeError, ValueError, OverflowError) as exc:
        kind = "integers" if np.dtype(dtype).kind == "i" else "numbers"
        raise ValidationError(f"AnimationTextures.{field} must be an array of {kind}: {exc}") from None
    array.setflags(write=False)
    return array


@attrs.frozen(kw_only=True, eq=False)
class AnimationTextures:
    """Baked animation textures of one skeleton: several textures (one per stream or clip)
    packed frame after frame in one texel array, as one GPU texture holds them.

    Parameters
    ----------
    skeleton : Skeleton
    fps : float
        Frames per second of every texture: frame k of a texture is its stream's (or clip's)
        pose at k / fps.
    names : sequence of str
        Each texture's name (its stream's or clip's).
    texels : (F, J, 5, 4) float32
        Every frame's texels, per joint: skinning matrix rows 0-2 (joint world @ inverse bind,
        row-major), local rotation (x, y, z, w), local translation (x, y, z, 0). As a GPU
        texture: F rows of 5 J RGBA32F texels.
    starts, lengths : (S,) int
        Each texture's first row in `texels` and its number of frames (0: a stream not baked,
        one of another skeleton).
    periods : (S,) float
        Frames per loop (a frame position wraps round it), or 0 for a texture played once (its
        last frame held).
    inverse_bind : (J, 4, 4)
        The inverse bind matrices the skinning matrices were made with, rounded to float32.
    """

    skeleton: Skeleton = attrs.field()
    fps: float = attrs.field(converter=lambda v: validate.number(v, "AnimationTextures.fps", minimum=0, strict=True))
    names: tuple = attrs.field(converter=tuple)
    texels: np.ndarray = attrs.field(converter=lambda v: _readonly(v, np.float32, "texels"))
    starts: np.ndarray = attrs.field(converter=lambda v: _readonly(v, np.int64, "starts"))
    lengths: np.ndarray = attrs.field(converter=lambda v: _readonly(v, np.int64, "lengths"))
    periods: np.ndarray = attrs.field(converter=lambda v: _readonly(v, np.float64, "periods"))
    inverse_bind: np.ndarray = attrs.field()

    def __attrs_post_init__(self):
        if not isinstance(self.skeleton, Skeleton):
            raise ValidationError(f"AnimationTextures.skeleton must be a flockkit.Skeleton; got {self.skeleton!r}")
        j = self.skeleton.n_joints
        object.__setattr__(self, "inverse_bind", _inverse_bind(self.inverse_bind, j))
        if self.texels.ndim != 4 or self.texels.shape[1:] != (j, TEXELS_PER_JOINT, 4):
            raise ValidationError(f"AnimationTextures.texels must have shape (F, {j}, {TEXELS_PER_JOINT}, 4); "
                                  f"got {self.texels.shape}")  # fmt: skip
        if not np.all(np.isfinite(self.texels)):
            raise ValidationError("AnimationTextures.texels must be finite")
        s = len(self.names)
        if not s or not all(isinstance(n, str) for n in self.names):
            raise ValidationError("AnimationTextures.names must be one string per texture, at least one")
        for field in ("starts", "lengths", "periods"):
            if getattr(self, field).shape != (s,):
                raise ValidationError(f"AnimationTextures.{field} must have one value per texture ({s})")
        frames = len(self.texels)
        if self.lengths.min() < 0 or np.any((self.lengths > 0) & ((self.starts < 0) | (self.starts + self.lengths
                                                                                         > frames))):  # fmt: skip
            raise ValidationError(f"AnimationTextures.starts and lengths must lie within the {frames} frames")
        looping = self.periods != 0
        if (
            not np.all(np.isfinite(self.periods))
            or np.any(self.periods < 0)
            or np.any(looping & (self.periods > self.lengths - 1))
        ):
            raise ValidationError("AnimationTextures.periods must be 0 or in (0, length - 1] frames")

    @property
    def n_textures(self) -> int:
        """S, the number of textures (streams or clips)."""
        return len(self.names)

    @property
    def matrices(self) -> np.ndarray:
        """Skinning matrices (F, J, 3, 4) float32: rows 0-2 of joint world @ inverse bind."""
        return self.texels[:, :, 0:3, :]

    @property
    def rotations(self) -> np.ndarray:
        """Local joint rotations (F, J, 4) float32, x, y, z, w."""
        return self.texels[:, :, 3, :]

    @property
    def translations(self) -> np.ndarray:
        """Local joint translations (F, J, 3) float32."""
        return self.texels[:, :, 4, :3]

    @property
    def skeleton_texels(self) -> np.ndarray:
        """The skeleton texture (J, 4, 4) float32, per joint: inverse bind rows 0-2 and (scale
        x, y, z, parent index, -1 for a root)."""
        out = np.zeros((self.skeleton.n_joints, SKELETON_TEXELS, 4), dtype=np.float32)
        out[:, 0:3] = self.inverse_bind[:, 0:3]
        out[:, 3, 0:3] = self.skeleton.scales
        out[:, 3, 3] = self.skeleton.parents
        return out

    @property
    def nbytes(self) -> int:
        """Bytes the GPU holds: the animation texture and the skeleton texture."""
        return int(self.texels.nbytes) + int(self.skeleton_texels.nbytes)

    def save(self, path) -> None:
        """Write the documented binary layout a game engine loads (atomic): the 8 bytes
        ``FKANIMTX``, the format version and the byte length L of a JSON header (uint32
        little-endian each), the header (UTF-8, padded with spaces so that 16 + L is a multiple
        of 16), then the arrays the header's ``arrays`` entry places (offset from the file's
        start, shape, ``<f4``): ``texels`` (F, J, 5, 4) and ``skeleton`` (J, 4, 4). The header
        also holds fps, every texture's name, start, length and period, and the skeleton (names,
        parents, rest pose, scales, axes)."""
        skeleton = self.skeleton
        header = {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "fps": self.fps,
            "texels_per_joint": [
                "matrix row 0",
                "matrix row 1",
                "matrix row 2",
                "rotation x y z w",
                "translation x y z 0",
            ],
            "skeleton_texels": [
                "inverse bind row 0",
                "inverse bind row 1",
                "inverse bind row 2",
                "scale x y z, parent",
            ],
            "textures": [
                {"name": n, "start": int(s), "length": int(k), "period": float(p)}
                for n, s, k, p in zip(self.names, self.starts, self.lengths, self.periods)
            ],
            "skeleton": {
                "names": list(skeleton.names),
                "parents": skeleton.parents.tolist(),
                "rest_rotations": skeleton.rest.rotations.tolist(),
                "rest_translations": skeleton.rest.translations.tolist(),
                "scales": skeleton.scales.tolist(),
                "up_axis": skeleton.up_axis,
                "meters_per_unit": skeleton.meters_per_unit,
            },
        }
        arrays = {"texels": np.ascontiguousarray(self.texels, dtype="<f4"),
                  "skeleton": np.ascontiguousarray(self.skeleton_texels, dtype="<f4")}  # fmt: skip
        # the header's length depends on the offsets it states: place the arrays after a header
        # padded to a size that holds every offset, then pad the text to exactly that size
        header["arrays"] = {name: {"offset": 0, "shape": list(a.shape), "dtype": "<f4"} for name, a in arrays.items()}
        size = len(json.dumps(header).encode()) + 64 * len(arrays)
        size += -(16 + size) % 16
        offset = 16 + size
        for name, array in arrays.items():
            header["arrays"][name]["offset"] = offset
            offset += array.nbytes + (-array.nbytes % 16)
        text = json.dumps(header).encode("utf-8")
        text += b" " * (size - len(text))
        with atomic_path(path) as tmp, open(tmp, "wb") as handle:
            handle.write(MAGIC + struct.pack("<II", FORMAT_VERSION, size) + text)
            for array in arrays.values():
                handle.write(array.tobytes())
                handle.write(b"\0" * (-array.nbytes % 16))

    @classmethod
    def load(cls, path) -> AnimationTextures:
        """Read a file written by :meth:`save`; FileFormatError naming the file and the field
        when it is not one (another file, a damaged header, arrays outside the file)."""
        path = Path(path)
        data = _files.read_bytes(path)

        def fail(what: str):
            raise FileFormatError(f"{path}: {what}")

        if len(data) < 16 or data[:8] != MAGIC:
            fail(f"not a flockkit animation textures file (it does not start with {MAGIC.decode()})")
        version, size = struct.unpack_from("<II", data, 8)
        if version != FORMAT_VERSION:
            fail(f"animation textures format version {version} is not supported; this flockkit reads "
                 f"{FORMAT_VERSION}")  # fmt: skip
        if 16 + size > len(data):
            fail(f"header length {size} runs past the end of the file ({len(data)} bytes)")
        try:
            header = json.loads(data[16 : 16 + size].decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError) as exc:
            fail(f"corrupt header: {type(exc).__name__}: {exc}")
        if not isinstance(header, dict) or header.get("format") != FORMAT:
            fail(f"the header is not a {FORMAT!r} header")
        try:
            arrays = {name: _array(data, header["arrays"][name], name, fail) for name in ("texels", "skeleton")}
            spec = header["skeleton"]
            textures = header["textures"]
            if not isinstance(textures, list) or not all(isinstance(t, dict) for t in textures):
                fail("textures must be a list of objects")
            skeleton = Skeleton(
                names=spec["names"],
                parents=spec["parents"],
                rest=Pose(rotations=spec["rest_rotations"], translations=spec["rest_translations"]),
                scales=spec["scales"],
                up_axis=spec["up_axis"],
                meters_per_unit=spec["meters_per_unit"],
            )
            bones = arrays["skeleton"]
            if bones.shape != (skeleton.n_joints, SKELETON_TEXELS, 4):
                fail(f"arrays.skeleton has shape {bones.shape}; the skeleton has {skeleton.n_joints} joints")
            if not np.array_equal(bones[:, 3, 3], skeleton.parents):
                fail("arrays.skeleton: its parents differ from the header's skeleton.parents")
            inverse = np.zeros((skeleton.n_joints, 4, 4))
            inverse[:, 0:3] = bones[:, 0:3]
            inverse[:, 3, 3] = 1.0
            return cls(
                skeleton=skeleton,
                fps=header["fps"],
                names=[t["name"] for t in textures],
                texels=arrays["texels"],
                starts=[t["start"] for t in textures],
                lengths=[t["length"] for t in textures],
                periods=[t["period"] for t in textures],
                inverse_bind=inverse,
            )
        except (KeyError, TypeError, ValueError) as exc:  # ValidationError is a ValueError
            if isinstance(exc, FileFormatError):
                raise
            fail(f"invalid animation textures: {type(exc).__name__}: {exc}")


def _array(data: bytes, spec, name: str, fail) -> np.ndarray:
    """Array `name` of a loaded file from its header entry `spec`, checked against the file."""
    if not isinstance(spec, dict) or spec.get("dtype") != "<f4":
        fail(f"arrays.{name} must be an object with dtype '<f4'")
    shape, offset = spec.get("shape"), spec.get("offset")
    if not isinstance(shape, list) or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0
                                              for n in shape):  # fmt: skip
        fail(f"arrays.{name}.shape must be a list of sizes")
    if not isinstance(offset, int) or isinstance(offset, bool) or offset < 16 or offset % 4:
        fail(f"arrays.{name}.offset must be a multiple of 4 past the header")
    nbytes = 4 * math.prod(shape)
    if offset + nbytes > len(data):
        fail(f"arrays.{name} ({nbytes} bytes at {offset}) runs past the end of the file ({len(data)} bytes)")
    array = np.frombuffer(data, dtype="<f4", count=nbytes // 4, offset=offset).reshape(shape)
    if not np.all(np.isfinite(array)):
        fail(f"arrays.{name} holds values that are not finite")
    return array.astype(np.float32)


# -- baking ---------------------------------------------------------------------------------------


def _texels(skeleton: Skeleton, rotations, translations, inverse_bind: np.ndarray) -> np.ndarray:
    """Texels (T, J, 5, 4) of local poses (T, J): the float32 values the pool stores, their skinning
    matrices computed in float64 from those values and rounded once."""
    rotations = np.asarray(rotations, dtype=np.float32)
    translations = np.asarray(translations, dtype=np.float32)
    world = skeleton.world(Pose._adopt(rotations.astype(np.float64), translations.astype(np.float64)))
    out = np.zeros(rotations.shape[:2] + (TEXELS_PER_JOINT, 4), dtype=np.float32)
    out[:, :, 0:3] = (world @ inverse_bind)[:, :, 0:3]
    out[:, :, 3] = rotations
    out[:, :, 4, 0:3] = translations
    return out


def _size(skeleton: Skeleton, texels: np.ndarray) -> float:
    """The skeleton's size: the widest extent of its joints over the baked frames (what
    translation tolerances are relative to)."""
    positions = skeleton.world(Pose._adopt(texels[:, :, 3].astype(np.float64),
                                           texels[:, :, 4, :3].astype(np.float64)))[..., :3, 3]  # fmt: skip
    return max(float(np.ptp(positions, axis=1).max()), 1e-12)


def _loop(texels: np.ndarray, size: float, tolerance: float) -> int:
    """The fewest frames P (at most half the frames) after which every frame k of `texels` is
    frame k mod P within `tolerance`: skinning matrices relative to their size (the linear
    part to its largest entry, the translation to the skeleton's `size`), local rotations as they
    are (a rotation or its negation); 0 where there is none. Local translations follow from the
    matrices."""
    matrices = texels[:, :, 0:3].astype(np.float64)
    matrices[..., 0:3] /= max(float(np.abs(matrices[..., 0:3]).max()), 1e-12)
    matrices[..., 3] /= size
    rotations = texels[:, :, 3].astype(np.float64)

    def distance(k, m) -> float:
        turned = np.minimum(np.abs(rotations[k] - rotations[m]).max(axis=-1),
                            np.abs(rotations[k] + rotations[m]).max(axis=-1))  # fmt: skip
        return max(float(np.abs(matrices[k] - matrices[m]).max()), float(turned.max()))

    frames = len(texels)
    every = np.arange(frames)
    for period in range(1, frames // 2 + 1):
        if distance(period, 0) <= tolerance and distance(every, every % period) <= tolerance:
            return period
    return 0


def _skeleton(value) -> Skeleton:
    if not isinstance(value, Skeleton):
        raise ValidationError(f"bake_textures: skeleton must be a flockkit.Skeleton; got {type(value).__name__}")
    return value


def _clips(source) -> list:
    if isinstance(source, dict):
        items = list(source.values())
    elif isinstance(source, (list, tuple)):
        items = list(source)
    else:
        items = []
    if not items or not all(isinstance(c, SkeletalClip) for c in items):
        raise ValidationError("bake_textures needs a StreamPool or a non-empty sequence (or mapping) of SkeletalClip")
    return items


def bake_textures(source, *, seconds=None, fps=None, inverse_bind=None, skeleton=None,
                  loop_tolerance: float = LOOP_TOLERANCE) -> AnimationTextures:  # fmt: skip
    """Bake `source` into animation textures.

    Parameters
    ----------
    source : StreamPool, or a sequence or mapping of SkeletalClip
        A pool: one texture per stream (texture s is stream s, what ``instance_buffer`` reads),
        frame k its controller's pose at k / pool.fps, for every frame a crowd made from the
        pool and run `seconds` can reach (history + seconds x fps); a stream whose poses repeat
        over those frames keeps one loop (within `loop_tolerance`). Streams of another skeleton than
        `skeleton` (default the first stream's) get no frames. Clips: one texture per clip,
        frame k its pose at k / `fps` up to its end, looping over its duration (engines set
        their own frame positions with :func:`instances`).
    seconds : float
        For a pool: how long its crowd runs after it is made.
    fps : float, optional
        For clips: frames per second (default their own, which must agree). A pool's is its own.
    inverse_bind : (J, 4, 4) or SkinnedMesh, optional
        The skin's inverse bind matrices (``read_skin``); default the inverse of each joint's
        rest world transform (a mesh bound in the rest pose).
    skeleton : Skeleton, optional
        For a pool: the skeleton whose streams are baked (default the first stream's).
    loop_tolerance : float
        How far (relative, see ``LOOP_TOLERANCE``) a stream's frame k may be from frame k mod P
        for the stream to be kept as a loop of P frames: what the textures may then differ from
        the crowd's poses by. 0 keeps only exact repeats.
    """
    loop_tolerance = validate.number(loop_tolerance, "bake_textures: loop_tolerance", minimum=0)
    if isinstance(source, StreamPool):
        if fps is not None and fps != source.fps:
            raise ValidationError(f"bake_textures: a pool's textures are at its own fps ({source.fps}); got fps={fps}")
        if seconds is None:
            raise ValidationError("bake_textures: seconds (how long the pool's crowd runs) is needed for a pool")
        seconds = validate.number(seconds, "bake_textures: seconds", minimum=0)
        skeleton = _skeleton(source.streams[0].skeleton if skeleton is None else skeleton)
        rate = source.fps
        frames = int(source.history.max()) + math.ceil(seconds * rate - 1e-9)
        streams = [(s.name or f"stream {k}", s.controller) for k, s in enumerate(source.streams)]
        chosen = [k for k, s in enumerate(source.streams) if s.skeleton.matches(skeleton)]
        if not chosen:
            raise ValidationError("bake_textures: no stream of the pool has the skeleton given")
        validate.allocation(frames * len(chosen) * skeleton.n_joints * (TEXELS_PER_JOINT * 4 + 40),
                            f"bake_textures: {len(chosen)} streams of {frames} frames")  # fmt: skip
    else:
        if seconds is not None:
            raise ValidationError("bake_textures: seconds is for a pool; clips are baked over their duration")
        clips = _clips(source)
        skeleton = _skeleton(clips[0].skeleton if skeleton is None else skeleton)
        for k, clip in enumerate(clips):
            if not clip.skeleton.matches(skeleton):
                raise ValidationError(f"bake_textures: clip {k} ({clip.name!r}) has another skeleton than clip 0")
        if fps is None:
            rates = {clip.fps for clip in clips}
            if len(rates) > 1:
                raise ValidationError(f"bake_textures: the clips have different frame rates {sorted(rates)}; pass fps")
            fps = rates.pop()
        rate = validate.number(fps, "bake_textures: fps", minimum=0, strict=True)
        streams = [(clip.name, clip) for clip in clips]
        chosen = list(range(len(clips)))
        validate.allocation(sum(c.duration * rate + 2 for c in clips) * skeleton.n_joints * (TEXELS_PER_JOINT * 4 + 40),
                            f"bake_textures: {len(clips)} clips at {rate:g} fps")  # fmt: skip
    if isinstance(inverse_bind, SkinnedMesh):
        inverse_bind.check_skeleton(skeleton, field="bake_textures: inverse_bind")
        inverse_bind = inverse_bind.inverse_bind
    if inverse_bind is None:
        inverse_bind = np.linalg.inv(skeleton.world(skeleton.rest))
    inverse_bind = _inverse_bind(inverse_bind, skeleton.n_joints, "bake_textures: inverse_bind")
    blocks, starts, lengths, periods = [], [], [], []
    row = 0
    for k, (_, player) in enumerate(streams):
        if k not in chosen:
            starts.append(0), lengths.append(0), periods.append(0.0)
            continue
        if isinstance(player, SkeletalClip):
            count = math.ceil(player.duration * rate - 1e-3) + 1
            pose = player.sample(np.arange(count) / rate)
            period = min(player.duration * rate, count - 1)  # its end, within float32 rounding
        else:
            pose = player.pose(np.arange(frames) / rate)
            if pose.n_joints != skeleton.n_joints or pose.shape != (frames,):
                raise ValidationError(f"bake_textures: stream {k}'s controller gave poses of shape {pose.shape} x "
                                      f"{pose.n_joints} joints for {frames} times")  # fmt: skip
        texels = _texels(skeleton, pose.rotations, pose.translations, inverse_bind)
        if not isinstance(player, SkeletalClip):
            period = _loop(texels, _size(skeleton, texels), loop_tolerance)
            if period:
                texels = texels[: period + 1]  # frame P (frame 0 again) closes the loop
        blocks.append(texels)
        starts.append(row), lengths.append(len(texels)), periods.append(float(period))
        row += len(texels)
    return AnimationTextures(skeleton=skeleton, fps=rate, names=[n for n, _ in streams], texels=np.concatenate(blocks),
                             starts=starts, lengths=lengths, periods=periods, inverse_bind=inverse_bind)  # fmt: skip


# -- instances ------------------------------------------------------------------------------------


def _rows(textures: AnimationTextures, texture: np.ndarray, frame: np.ndarray):
    """(frame wrapped or held, row a, row b, fraction) of frame positions in `texture` (-1: none)."""
    have = texture >= 0
    k = np.where(have, texture, 0)
    period, length, start = textures.periods[k], textures.lengths[k], textures.starts[k]
    position = np.where(period > 0, np.mod(frame, np.where(period > 0, period, 1)), np.clip(frame, 0, length - 1))
    a = np.floor(position)
    fraction = position - a
    a = a.astype(np.int64)
    b = np.minimum(a + 1, length - 1)
    return (np.where(have, position, 0), np.where(have, start + a, -1), np.where(have, start + b, -1),
            np.where(have, fraction, 0))  # fmt: skip


def instances(textures: AnimationTextures, texture, frame, *, target=None, target_frame=None, weight=None,
              visible=None) -> np.ndarray:  # fmt: skip
    """Instance records (n,) TEXTURE_INSTANCE of parts that read `texture` (n,) at `frame` (n,)
    frame positions (k: its pose at k / fps; wrapped round a looping texture, held at the ends of
    one played once), blending to `target` at `target_frame` by `weight` α (-1 or None: not
    blending). What an engine driving clip textures with its own clock fills in each frame, and
    what :func:`instance_buffer` makes from a crowd."""
    texture = np.atleast_1d(np.asarray(texture))
    if texture.ndim != 1 or (texture.size and texture.dtype.kind not in "iu"):
        raise ValidationError("instances: texture must be texture indices (n,), -1 for none")
    n = len(texture)

    def floats(value, field, default):
        array = np.broadcast_to(np.asarray(default if value is None else value, dtype=np.float64), (n,))
        if not np.all(np.isfinite(array)):
            raise ValidationError(f"instances: {field} must be finite")
        return array

    def indices(value, field):
        array = np.broadcast_to(np.asarray(-1 if value is None else value), (n,))
        if array.size and (array.dtype.kind not in "iu" or array.min() < -1 or array.max() >= textures.n_textures):
            raise ValidationError(f"instances: {field} must be texture indices -1 .. {textures.n_textures - 1}")
        bare = array[array >= 0]
        if np.any(textures.lengths[bare] == 0):
            raise ValidationError(f"instances: {field} names texture {int(bare[textures.lengths[bare] == 0][0])}, "
                                  "which holds no frames (a stream of another skeleton)")  # fmt: skip
        return array.astype(np.int64)

    texture = indices(texture, "texture")
    target = indices(target, "target")
    weight = np.clip(floats(weight, "weight", 0.0), 0, 1)
    weight = np.where(target >= 0, weight, 0.0)
    out = np.zeros(n, dtype=TEXTURE_INSTANCE)
    frame, a, b, fraction = _rows(textures, texture, floats(frame, "frame", 0.0))
    t_frame, ta, tb, t_fraction = _rows(textures, target, floats(target_frame, "target_frame", 0.0))
    out["texture"], out["frame"], out["target"], out["target_frame"] = texture, frame, target, t_frame
    out["weight"] = weight
    out["rows"] = np.stack([a, b, ta, tb], axis=1)
    out["fractions"] = np.stack([fraction, t_fraction], axis=1)
    out["visible"] = np.broadcast_to(np.asarray(True if visible is None else visible), (n,))
    return out


def instance_buffer(crowd, textures: AnimationTextures, cluster=None) -> np.ndarray:
    """The instance records (N,) TEXTURE_INSTANCE of every agent's part `cluster` (default the
    crowd's first) this frame, for textures baked from the crowd's pool: each part's stream and
    offset (frame = the stream's frames written - 1 - offset, a fraction while it dilates), and
    while it blends its target stream and offset and α (``Crowd.alphas``). Agents without the
    cluster get texture -1; hidden parts are marked not visible. A part reading a unique slot
    (per-agent animation, never baked) or a frame past a texture baked once is refused."""
    from .runtime import NONE, STREAMED, Crowd

    if not isinstance(crowd, Crowd):
        raise ValidationError(f"instance_buffer needs a flockkit.Crowd; got {type(crowd).__name__}")
    if not isinstance(textures, AnimationTextures):
        raise ValidationError(f"instance_buffer: textures must be AnimationTextures; got {type(textures).__name__}")
    pool = crowd.pool
    if textures.n_textures != len(pool.streams) or textures.fps != pool.fps:
        raise ValidationError(
            f"instance_buffer: the textures hold {textures.n_textures} textures at {textures.fps:g} fps; the crowd's "
            f"pool has {len(pool.streams)} streams at {pool.fps:g} fps: bake them from this pool"
        )
    name = crowd.clusters[0] if cluster is None else cluster
    c = crowd.cluster_index(name)
    if not textures.skeleton.matches(crowd.skeletons[c]):
        raise ValidationError(f"instance_buffer: the textures' skeleton is not cluster {name!r}'s")
    record = crowd.instance_buffer()[:, c]
    blending = record["blend_time"] > 0
    has = record["kind"] != NONE
    unique = has & ((record["kind"] != STREAMED) | (blending & (record["target_kind"] != STREAMED)))
    if unique.any():
        raise ValidationError(
            f"instance_buffer: agent {int(np.flatnonzero(unique)[0])}'s part {name!r} reads a unique slot, which "
            "baked textures do not hold (draw it from Crowd.poses)"
        )

    def frames(streams, offsets, reading):
        stream = np.where(reading, streams, 0)
        frame = pool.clock[stream] - 1 - offsets.astype(np.float64)
        over = reading & (textures.periods[stream] == 0) & (frame > textures.lengths[stream] - 1)
        if over.any():
            k = int(np.flatnonzero(over)[0])
            raise ValidationError(
                f"instance_buffer: stream {int(stream[k])} is at frame {frame[k]:g}; its texture holds "
                f"{int(textures.lengths[stream[k]])} frames: bake with more seconds"
            )
        return np.where(reading, streams, -1), frame

    texture, frame = frames(record["stream"], record["offset"], has)
    target, target_frame = frames(record["target"], record["target_offset"], has & blending)
    alpha = np.nan_to_num(crowd.alphas(name), nan=0.0)
    visible = (record["mask"] >> c) & 1
    return instances(textures, texture, frame, target=target, target_frame=target_frame, weight=alpha,
                     visible=visible.astype(bool) & has)  # fmt: skip


# -- the reference skinning ------------------------------------------------------------------------


def _between(textures: AnimationTextures, a, b, fraction):
    """Local rotations and translations (n, J, ...) `fraction` (n,) of the way from rows `a` to
    rows `b`: rotations slerped the shorter way, translations linearly (row a where 0)."""
    qa, qb = textures.rotations[a].astype(np.float64), textures.rotations[b].astype(np.float64)
    ta, tb = textures.translations[a].astype(np.float64), textures.translations[b].astype(np.float64)
    u = fraction[:, None, None]
    moving = fraction > 0
    q = np.where(moving[:, None, None], rigid.slerp(qa, qb, u), qa)
    return q, ta + u * (tb - ta)


def _records(records) -> np.ndarray:
    records = np.atleast_1d(np.asarray(records))
    if records.dtype != TEXTURE_INSTANCE or records.ndim != 1:
        raise ValidationError("records must be a 1D array of TEXTURE_INSTANCE (flockkit.crowd.instances)")
    return records


def skinning_matrices(textures: AnimationTextures, records) -> np.ndarray:
    """The skinning matrices (n, J, 3, 4) (rows 0-2 of joint world @ inverse bind) that
    ``crowd_skinning.vert`` computes for each instance record (n,); NaN for records of no part.

    A whole frame without a blend takes the baked matrices of its row. Otherwise each joint's
    local transform is read from rows a and b (rotations slerped, translations lerped by the
    fraction), for the source and, while blending, the target, the two mixed by α (rotations
    nlerped, translations lerped: the crowd's blend), and forward kinematics times the inverse
    bind matrices gives the matrices. Times ``inverse(inverse_bind)`` they are the parts' world
    joint matrices, ``Crowd.poses(space="world")``."""
    if not isinstance(textures, AnimationTextures):
        raise ValidationError(f"skinning_matrices: textures must be AnimationTextures; got {type(textures).__name__}")
    records = _records(records)
    rows, fractions = records["rows"].astype(np.int64), records["fractions"].astype(np.float64)
    weight = records["weight"].astype(np.float64)
    frames = len(textures.texels)
    drawn = rows[:, 0] >= 0
    if np.any(rows >= frames) or np.any(drawn & (rows[:, 1] < 0)):
        raise ValidationError(f"skinning_matrices: records name rows outside the textures' {frames} frames")
    palette = np.full((len(records), textures.skeleton.n_joints, 3, 4), np.nan)
    steady = drawn & (weight == 0) & (fractions[:, 0] == 0)
    palette[steady] = textures.matrices[rows[steady, 0]]
    mixed = np.flatnonzero(drawn & ~steady)
    if len(mixed):
        r, f, w = rows[mixed], fractions[mixed], weight[mixed]
        q, t = _between(textures, r[:, 0], r[:, 1], f[:, 0])
        blending = (r[:, 2] >= 0) & (w > 0)
        if blending.any():
            if np.any(r[blending, 3] < 0):
                raise ValidationError("skinning_matrices: a blending record has no target row b")
            u = w[blending][:, None, None]
            tq, tt = _between(textures, r[blending, 2], r[blending, 3], f[blending, 1])
            q[blending] = np.where(u >= 1, tq, rigid.nlerp(q[blending], tq, u))
            t[blending] = np.where(u >= 1, tt, t[blending] + u * (tt - t[blending]))
        world = textures.skeleton.world(Pose._adopt(q, t))
        palette[mixed] = (world @ textures.inverse_bind)[:, :, 0:3]
    return palette


def skin(textures: AnimationTextures, records, mesh: SkinnedMesh, *, normals: bool = False):
    """The reference of ``crowd_skinning.vert``: `mesh` skinned for each instance record (n,)
    (:func:`instances`, :func:`instance_buffer`), in model space (before the agent's root):
    positions (n, V, 3), and with `normals` also the normals (n, V, 3) (turned by the 3 x 3 part
    of the vertex's skinning matrix, normalized). NaN for records of no part (texture -1).

    Each vertex is the sum over its joints of weight x skinning matrix @ position, the
    matrices those of :func:`skinning_matrices`."""
    if not isinstance(mesh, SkinnedMesh):
        raise ValidationError(f"skin: mesh must be a SkinnedMesh (flockkit.crowd.read_skin); got {type(mesh).__name__}")
    if not isinstance(textures, AnimationTextures):
        raise ValidationError(f"skin: textures must be AnimationTextures; got {type(textures).__name__}")
    mesh.check_skeleton(textures.skeleton, field="skin: mesh")
    return mesh.skin_with(skinning_matrices(textures, records), normals=normals)


def shader_source() -> str:
    """The reference vertex shader (GLSL 330 core) that reads the textures and instance records
    as :func:`skin` does; shipped as ``flockkit/crowd/shaders/crowd_skinning.vert``."""
    return resources.files("flockkit.crowd").joinpath("shaders", SHADER).read_text(encoding="utf-8")
