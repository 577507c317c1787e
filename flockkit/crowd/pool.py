"""Shared animation streams and their pose history (paper 003, sections 4.1 and 4.5).

A stream evaluates its controller once per frame while Running and keeps its last `history`
poses (M_A) in a ring buffer; every agent part that shares the stream reads it at its own offset
behind the head. All ring buffers live in ONE float32 store laid out in blocks of frames: block I
holds, for each stream whose history is longer than I, that stream's pose I slots into its ring.
A lookup table gives the store offset of (stream, slot) in O(1), so skeletons of different sizes
and different histories share the store without padding (Figure 6).

Each joint's entry is 12 float32 (48 bytes, the paper's 4 x 3 matrix): its local rotation
(x, y, z, w), translation, scale and two reserved zeros, the three parts of a transform Unreal's
FTransform keeps in the same 48 bytes. So the store's size is Equation 5 of the paper (the
extracted text lost the history factor; with histories of one frame it is the printed formula):

    Total_new = 48 * (U * MaxBones + sum over streams A of M_A * Bones_A) bytes.

A stream whose controller offers root motion (``Capabilities.root_motion``) keeps, beside each
pose, where its root had gone by then (a ground transform, float64: it accumulates over hours):
what the agents of a crowd that takes its motion from its clips advance by.

How a stream's poses are made depends on what its controller declares (``Capabilities``):

- ``batch``: every Running stream of one controller class and joint count is advanced by one
  call a frame (``BatchedController``), which writes the poses in place into the store: no
  Python runs per stream, nothing is evaluated ahead, and the frame's work is the store's writes.
- ``live`` (a state machine fed each frame): evaluated every frame at that frame's time, never
  ahead, so what is fed before an ``update`` shows in that update.
- otherwise (a function of time alone): evaluated PREFETCH_FRAMES frames ahead, a few streams
  each frame, so that a frame does not call a thousand controllers.

Events and root motion of time-only streams are read ahead in the same blocks.
"""

from __future__ import annotations

import attrs
import numpy as np

from .. import validate
from ..errors import PluginError, UnknownPluginError, ValidationError
from ..interfaces import capabilities
from ..registry import resolve
from ..skeleton import Pose, Skeleton

__all__ = ["Stream", "StreamPool", "UniquePool", "ENTRY_FLOATS", "PREFETCH_FRAMES", "READ_AHEAD_FRAMES", "equation_5",
           "equation_4"]  # fmt: skip

ENTRY_FLOATS = 12  # per joint: rotation 4, translation 3, scale 3, reserved 2: 48 bytes
# Frames a stream's controller is evaluated ahead; refills are staggered over this many frames.
PREFETCH_FRAMES = 32
# Frames a batched stream's events and root motion are read ahead (its poses are not): longer
# blocks, since these are small (4 floats a frame) and each block is one Python call per stream.
READ_AHEAD_FRAMES = 128
STATES = ("Running", "Stopped")
# The fastest animation system a pool runs (frames a second): above any display's refresh rate.
# A pool runs at least one frame a second.
MAX_FPS = 1000.0


def _controller(value, field: str):
    """`value` as a controller: an instance that honours the Controller protocol (its skeleton a
    flockkit.Skeleton), or ValidationError naming `field`."""
    try:
        controller = resolve("controller", value)
    except ValidationError as exc:
        raise ValidationError(f"{field}: {exc}") from None
    if not isinstance(controller.skeleton, Skeleton):
        raise ValidationError(f"{field}: its skeleton must be a flockkit.Skeleton; got {controller.skeleton!r}")
    return controller


def _state(value):
    if value not in STATES:
        raise ValidationError(f"Stream.default must be 'Running' or 'Stopped'; got {value!r}")
    return value


@attrs.frozen(kw_only=True, eq=False)
class Stream:
    """An animation stream (section 4.1): a controller (an instance, or a registered name made with
    `controller_params`), the number of past poses kept (`history`, M_A frames: agents read
    offsets 0 .. history - 1), and its default state: Running from the start, or Stopped until an
    agent part needs it."""

    controller: object = attrs.field()
    history: int = attrs.field(validator=lambda i, a, v: validate.integer(v, "Stream.history", minimum=1))
    default: str = attrs.field(default="Running", converter=_state)
    name: str = attrs.field(default="")
    controller_params: dict = attrs.field(factory=dict, converter=dict, repr=False)

    def __attrs_post_init__(self):
        made = self.controller
        if isinstance(made, str):
            try:
                made = resolve("controller", made, **self.controller_params)
            except (ValidationError, PluginError, UnknownPluginError) as exc:
                raise type(exc)(f"Stream.controller: {exc}") from None
        elif self.controller_params:
            raise ValidationError("Stream.controller_params are for a controller made by name; got an instance")
        object.__setattr__(self, "controller", _controller(made, "Stream.controller"))

    @property
    def skeleton(self) -> Skeleton:
        return self.controller.skeleton


def equation_5(bones, histories, *, unique: int = 0, max_bones: int | None = None) -> int:
    """Bytes of the new layout (paper 003, Equation 5 with each stream's history):
    48 (U MaxBones + sum_A M_A Bones_A)."""
    bones, histories = np.asarray(bones, dtype=np.int64), np.asarray(histories, dtype=np.int64)
    max_bones = int(bones.max()) if max_bones is None else max_bones
    return int(48 * (unique * max_bones + np.sum(histories * bones)))


def equation_4(bones, histories, *, unique: int = 0, transitions: int = 0) -> int:
    """Bytes of the previous layout (Equation 4 with histories): every stream padded to the
    largest skeleton and the longest history, and a slot of MaxBones per transition."""
    bones, histories = np.asarray(bones, dtype=np.int64), np.asarray(histories, dtype=np.int64)
    max_bones, longest = int(bones.max()), int(histories.max())
    return int(48 * ((unique + transitions) * max_bones + len(bones) * longest * max_bones))


def _entries(pose: Pose, scales: np.ndarray) -> np.ndarray:
    """Poses (..., J) as store entries (..., J, 12) float32."""
    out = np.zeros(pose.rotations.shape[:-1] + (ENTRY_FLOATS,), dtype=np.float32)
    out[..., 0:4] = pose.rotations
    out[..., 4:7] = pose.translations
    out[..., 7:10] = scales
    return out


def namespace(array):
    """The array API namespace of `array` (numpy, CuPy, ...): the one code path that samples and
    blends poses wherever the store lives."""
    return array.__array_namespace__() if hasattr(array, "__array_namespace__") else np


def blend_entries(a, b, weight):
    """Store entries `a` (n, J, 12) blended towards `b` by `weight` (n,): rotations on the sphere
    (nlerp, the shorter way round), translations and scales linearly (Listing 3's lerp, per
    joint); weight 0 gives `a` and 1 gives `b` exactly. Array API calls only, so the same code
    runs on a GPU array library's arrays; `a` is overwritten."""
    xp = namespace(a)
    w = xp.reshape(xp.astype(weight, a.dtype), (-1, 1, 1))
    change = b - a
    opposite = xp.vecdot(a[..., 0:4], b[..., 0:4]) < 0
    if bool(xp.any(opposite)):  # the other hemisphere: blend towards -b, the same rotation
        change[..., 0:4] = xp.where(opposite[..., None], -b[..., 0:4] - a[..., 0:4], change[..., 0:4])
    change *= w
    change += a
    rotations = change[..., 0:4]
    change[..., 0:4] = rotations / xp.sqrt(xp.vecdot(rotations, rotations))[..., None]
    if bool(xp.any((w <= 0) | (w >= 1))):
        change = xp.where(w <= 0, a, xp.where(w >= 1, b, change))
    return change


def entries_pose(entries: np.ndarray) -> Pose:
    """Store entries (..., J, 12) as a float32 Pose (the store's precision)."""
    return Pose._adopt(entries[..., 0:4], entries[..., 4:7])


class StreamPool:
    """The shared streams of a crowd and their pose history (sections 4.1, 4.5).

    Parameters
    ----------
    streams : sequence of Stream
    fps : float
        Frames per second of the animation system (animFrameRate), 1 to MAX_FPS: one ``advance``
        is one frame.
    xp : array namespace, optional
        Where the store lives (default numpy): a GPU array library's namespace (``cupy``) keeps
        it on the device, where ``Crowd.poses`` samples and blends it through the same code.

    Streams are referred to by their index in `streams`.
    """

    def __init__(self, streams, *, fps: float = 30.0, xp=None):
        self.streams = tuple(streams)
        if not self.streams or not all(isinstance(s, Stream) for s in self.streams):
            raise ValidationError("StreamPool needs a non-empty sequence of flockkit.crowd.Stream")
        self.fps = validate.number(fps, "StreamPool.fps", minimum=1, maximum=MAX_FPS)
        s = len(self.streams)
        self.history = np.array([st.history for st in self.streams], dtype=np.int64)
        self.bones = np.array([st.skeleton.n_joints for st in self.streams], dtype=np.int64)
        longest = int(self.history.max())
        floats = float(np.sum(self.history.astype(float) * self.bones)) * ENTRY_FLOATS
        validate.allocation(
            4 * floats + 8 * 3 * s * float(longest) + 4 * float(self.bones.sum()) * PREFETCH_FRAMES * ENTRY_FLOATS,
            f"StreamPool: {s} streams, histories up to {longest} frames",
            itemsize=1,
        )
        # Figure 6: block by block (slot I of every stream holding more than I frames), so that a
        # stream's slot is found by one lookup and no stream is padded.
        held = self.history[:, None] > np.arange(longest)  # (streams, slots)
        sizes = np.where(held, self.bones[:, None] * ENTRY_FLOATS, 0)
        block_start = np.cumsum(sizes.sum(axis=0)) - sizes.sum(axis=0)
        self.lookup = np.where(held, block_start + np.cumsum(sizes, axis=0) - sizes, -1)
        self.xp = np if xp is None else xp
        declared = [capabilities(st.controller) for st in self.streams]
        self.live = np.array([c.live for c in declared])
        self.batched = np.array([c.batch and not c.live for c in declared])
        # every slot holds its stream's scales from the start: a batched write touches only the
        # rotations and translations
        store = np.zeros(int(sizes.sum()), dtype=np.float32)
        for k, st in enumerate(self.streams):
            slots = self.lookup[k, : self.history[k]]
            scales = np.broadcast_to(st.skeleton.scales.astype(np.float32), (len(slots), self.bones[k], 3))
            self._blocks(store, int(self.bones[k]), writeable=True)[slots, :, 7:10] = scales
        self.store = store if self.xp is np else self.xp.asarray(store)
        self.head = np.zeros(s, dtype=np.int64)  # the slot written last
        self.filled = np.zeros(s, dtype=np.int64)  # frames written since the stream (re)started
        self.clock = np.zeros(s, dtype=np.int64)  # frames evaluated since the stream (re)started
        self.running = np.array([st.default == "Running" for st in self.streams])
        self.users = np.zeros(s, dtype=np.int64)  # agent parts reading the stream
        # batched streams: per (controller class, joint count), the streams and one evaluator
        self._batches = []
        for key in dict.fromkeys((type(st.controller), int(self.bones[k])) for k, st in enumerate(self.streams)
                                 if self.batched[k]):  # fmt: skip
            members = np.array([k for k, st in enumerate(self.streams) if self.batched[k] and
                                (type(st.controller), int(self.bones[k])) == key])  # fmt: skip
            controllers = [self.streams[k].controller for k in members]
            self._batches.append((members, controllers[0].batch(controllers)))
        self._batch_of = np.full(s, -1, dtype=np.int64)  # each batched stream's index in its evaluator
        for members, _ in self._batches:
            self._batch_of[members] = np.arange(len(members))
        # prefetched poses, for streams neither batched nor live: per skeleton size, (streams of
        # that size, PREFETCH_FRAMES, J, 12); a stream's block starts at frame _first and holds
        # _count frames (0: refill at once); batched and live streams read ahead only events
        # and root motion (live ones not at all)
        ahead = ~self.batched & ~self.live
        self._group = {int(b): np.flatnonzero((self.bones == b) & ahead) for b in np.unique(self.bones[ahead])}
        self._place = np.zeros(s, dtype=np.int64)
        for members in self._group.values():
            self._place[members] = np.arange(len(members))
        self._ahead = {
            b: np.zeros((len(m), PREFETCH_FRAMES, b, ENTRY_FLOATS), np.float32) for b, m in self._group.items()
        }
        self._first = np.zeros(s, dtype=np.int64)
        self._count = np.zeros(s, dtype=np.int64)
        self._events: dict[int, dict] = {}  # stream -> {frame: events} ahead, for streams that have some
        self._stops = np.array([st.default == "Stopped" for st in self.streams])
        self._scales = [st.skeleton.scales.astype(np.float32) for st in self.streams]
        # root motion: which streams have it, their roots per ring slot and prefetched ahead
        self.rooted = np.array([capabilities(st.controller).root_motion for st in self.streams])
        self.roots = np.zeros((s, longest if self.rooted.any() else 0, 4))
        self._block = np.where(self.batched, READ_AHEAD_FRAMES, PREFETCH_FRAMES)
        self._ahead_roots = np.zeros((s, int(self._block[self.rooted].max()) if self.rooted.any() else 0, 4))
        self._restart(np.flatnonzero(self.running))

    # -- lookups --------------------------------------------------------------------------------

    def check_streams(self, streams, *, field: str = "stream") -> np.ndarray:
        ids = np.atleast_1d(np.asarray(streams))
        if ids.dtype.kind not in "iu" or ids.size and (ids.min() < 0 or ids.max() >= len(self.streams)):
            raise ValidationError(
                f"{field}: unknown stream id {streams!r}; the pool has streams 0..{len(self.streams) - 1}"
            )
        return ids.astype(np.int64)

    def rows(self, streams: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """Store offsets (in floats) of the poses `offsets` frames behind each stream's head."""
        slots = (self.head[streams] - offsets) % self.history[streams]
        return self.lookup[streams, slots]

    def read(self, stream: int, offset: int = 0) -> Pose:
        """The pose stored `offset` frames behind `stream`'s head (0: the newest), as a float32
        Pose. Offsets outside 0 .. history - 1, or older than the frames written since the
        stream started, are refused."""
        (k,) = self.check_streams(stream)
        offset = validate.integer(offset, "offset", minimum=0)
        if offset >= self.history[k]:
            raise ValidationError(f"offset {offset} is beyond stream {k}'s history of {self.history[k]} frames")
        if offset >= self.filled[k]:
            raise ValidationError(
                f"stream {k} has written {self.filled[k]} frames since it started; offset {offset} is older"
            )
        return entries_pose(self.gather(np.array([k]), np.array([offset]), int(self.bones[k]))[0])

    def root_at(self, streams: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """Where each stream's root had gone (n, 4; ``RootMotionSource``) at the frame `offsets`
        behind its head: between the two frames either side of a fractional offset, linearly
        (as a dilating part reads its poses); zero for streams without root motion."""
        out = np.zeros((len(streams), 4))
        rooted = self.rooted[streams]
        if not rooted.any():
            return out
        streams, offsets = streams[rooted], np.asarray(offsets, dtype=np.float64)[rooted]
        whole = np.floor(offsets)
        share = (offsets - whole)[:, None]
        newer = self.roots[streams, (self.head[streams] - whole.astype(np.int64)) % self.history[streams]]
        older = self.roots[streams, (self.head[streams] - whole.astype(np.int64) - 1) % self.history[streams]]
        out[rooted] = np.where(share > 0, (1 - share) * newer + share * older, newer)
        return out

    def is_running(self, stream: int) -> bool:
        (k,) = self.check_streams(stream)
        return bool(self.running[k])

    def memory(self) -> int:
        """Bytes of every array the pool holds: the store (Equation 5 with U = 0), the prefetched
        poses (48 * PREFETCH_FRAMES * Bones_A for each stream neither batched nor live), the
        batch evaluators' tables and the bookkeeping (lookup table, heads, clocks, ref counts)."""
        return sum(self.memory_parts().values())

    def memory_parts(self) -> dict:
        """`memory` by part, in bytes: ``store`` (the ring buffers, what Equation 5 counts),
        ``prefetch`` (PREFETCH_FRAMES poses ahead per stream that is neither batched nor live),
        ``batch`` (what the evaluators of batched streams hold: their ``nbytes``) and
        ``bookkeeping``."""
        ahead = sum(int(a.nbytes) for a in self._ahead.values())
        batch = sum(int(getattr(evaluator, "nbytes", 0)) for _, evaluator in self._batches)
        tables = [self.lookup, self.history, self.bones, self.head, self.filled, self.clock, self.running,
                  self.users, self._place, self._first, self._count, self._stops, *self._group.values(),
                  *self._scales, self.rooted, self.roots, self._ahead_roots, self.live, self.batched,
                  self._batch_of, self._block]  # fmt: skip
        store = int(self.store.size) * 4  # float32, in whatever namespace holds it
        tables += [members for members, _ in self._batches]
        return {"store": store, "prefetch": ahead, "batch": batch,
                "bookkeeping": sum(int(a.nbytes) for a in tables)}  # fmt: skip

    def gather(self, streams: np.ndarray, offsets: np.ndarray, bones: int):
        """Entries (n, bones, 12) of `streams` (all of `bones` joints) `offsets` frames behind their
        heads: numpy takes whole rows of a strided view; other namespaces take by flat index."""
        rows = self.rows(streams, offsets)
        if self.xp is np:
            return self.windows(bones)[rows].reshape(-1, bones, ENTRY_FLOATS)
        index = (rows[:, None] + np.arange(bones * ENTRY_FLOATS)).reshape(-1)
        return self.xp.reshape(self.xp.take(self.store, self.xp.asarray(index)), (-1, bones, ENTRY_FLOATS))

    @staticmethod
    def _blocks(store: np.ndarray, bones: int, *, writeable: bool = False) -> np.ndarray:
        """`store` seen as overlapping pose blocks (count, bones, 12), one starting at every float."""
        count = max(len(store) - bones * ENTRY_FLOATS + 1, 0)
        return np.lib.stride_tricks.as_strided(store, shape=(count, bones, ENTRY_FLOATS), strides=(4, 48, 4),
                                               writeable=writeable)  # fmt: skip

    def windows(self, bones: int, *, writeable: bool = False) -> np.ndarray:
        """The store seen as overlapping rows of `bones` entries, one starting at every float:
        rows[k] is the pose block starting at store offset k (a view; fancy indexing copies, and
        assigns into the store when `writeable`)."""
        width = bones * ENTRY_FLOATS
        count = max(len(self.store) - width + 1, 0)
        return np.lib.stride_tricks.as_strided(self.store, shape=(count, width), strides=(4, 4), writeable=writeable)

    # -- running --------------------------------------------------------------------------------

    def _restart(self, streams: np.ndarray) -> None:
        """Start `streams` from their clocks' zero: nothing written, nothing prefetched, then the
        first pose written at once (offset 0 reads it)."""
        self.running[streams] = True
        self.head[streams] = self.history[streams] - 1
        self.filled[streams], self.clock[streams] = 0, 0
        self._first[streams], self._count[streams] = 0, 0
        for k in streams.tolist():
            self._events.pop(k, None)
        self._write(streams)

    def acquire(self, streams: np.ndarray) -> np.ndarray:
        """Count agent parts arriving on `streams` (repeats count); start Stopped ones. Returns the
        streams that started."""
        counts = np.bincount(streams, minlength=len(self.streams))
        starting = np.flatnonzero((counts > 0) & ~self.running)
        self.users += counts
        self._restart(starting)
        return starting

    def release(self, streams: np.ndarray) -> None:
        """Count agent parts leaving `streams`; a stream whose default is Stopped stops when its
        last user leaves."""
        self.users -= np.bincount(streams, minlength=len(self.streams))
        ending = np.flatnonzero(self._stops & self.running & (self.users <= 0))
        self.running[ending] = False

    def advance(self) -> list:
        """One frame: every Running stream evaluates its controller and writes its head. Returns
        (stream, Event) for the events its controller reports within the frame."""
        return self._write(np.flatnonzero(self.running))

    def _write(self, live: np.ndarray) -> list:
        if not len(live):
            return []
        fed = self.live[live]
        for k in live[~fed & (self.clock[live] - self._first[live] >= self._count[live])]:
            self._refill(int(k))
        self.head[live] = (self.head[live] + 1) % self.history[live]
        rows = self.lookup[live, self.head[live]]
        events = []
        for k in self._events.keys() & set(live.tolist()):
            events.extend((k, e) for e in self._events[k].pop(int(self.clock[k]), ()))
        for k, row in zip(live[fed].tolist(), rows[fed].tolist()):
            events.extend((k, e) for e in self._evaluate_live(k, row))
        for members, evaluator in self._batches:
            mine = self._batch_of[live] >= 0
            mine[mine] = np.isin(live[mine], members)
            if not mine.any():
                continue
            streams = live[mine]
            times = self.clock[streams] / self.fps
            if self.xp is np:
                evaluator.write(self._batch_of[streams], times, self.store, rows[mine], ENTRY_FLOATS)
            else:  # written on the host, copied over once
                width = int(self.bones[streams[0]]) * ENTRY_FLOATS
                host = np.zeros(len(streams) * width, dtype=np.float32)
                evaluator.write(self._batch_of[streams], times, host, np.arange(len(streams)) * width, ENTRY_FLOATS)
                host = host.reshape(len(streams), -1, ENTRY_FLOATS)
                host[..., 7:10] = np.stack([self._scales[k] for k in streams.tolist()])
                for row, entry in zip(rows[mine].tolist(), host):
                    self.store[row : row + entry.size] = self.xp.asarray(entry.ravel())
        for bones, members in self._group.items():
            mine = np.isin(live, members)
            streams = live[mine]
            if not len(streams):
                continue
            entries = self._ahead[bones][self._place[streams], self.clock[streams] - self._first[streams]]
            if self.xp is np:
                self.windows(bones, writeable=True)[rows[mine]] = entries.reshape(len(streams), -1)
            else:
                for row, entry in zip(rows[mine].tolist(), entries):
                    self.store[row : row + entry.size] = self.xp.asarray(entry.ravel())
        rooted = live[self.rooted[live] & ~fed]
        if len(rooted):
            self.roots[rooted, self.head[rooted]] = self._ahead_roots[rooted, self.clock[rooted] - self._first[rooted]]
        self.filled[live] = np.minimum(self.filled[live] + 1, self.history[live])
        self.clock[live] += 1
        return events

    def _checked(self, k: int, pose, count: int):
        if not isinstance(pose, Pose) or pose.n_joints != self.bones[k] or pose.shape != (count,):
            raise ValidationError(
                f"stream {k}'s controller gave poses of shape {getattr(pose, 'shape', None)} x "
                f"{getattr(pose, 'n_joints', None)} joints for {count} times and a skeleton of {self.bones[k]}"
            )
        return pose

    def _evaluate_live(self, k: int, row: int) -> list:
        """Stream k's live controller at this frame's time, written at store offset `row`; its
        root motion and the events it reports within the frame."""
        frame = int(self.clock[k])
        controller, now = self.streams[k].controller, np.array([frame / self.fps])
        entry = _entries(self._checked(k, controller.pose(now), 1), self._scales[k])[0]
        self.store[row : row + entry.size] = entry.ravel() if self.xp is np else self.xp.asarray(entry.ravel())
        if self.rooted[k]:
            self.roots[k, self.head[k]] = self._roots_of(k, controller, now)[0]
        return controller.events(frame / self.fps, (frame + 1) / self.fps)

    def _roots_of(self, k: int, controller, times) -> np.ndarray:
        roots = np.asarray(controller.root_motion(times), dtype=np.float64)
        if roots.shape != (len(times), 4) or not np.all(np.isfinite(roots)):
            raise ValidationError(f"stream {k}'s controller gave root motion of shape {roots.shape} for {len(times)} "
                                  "times (finite, 4 per time: a ground translation and a heading)")  # fmt: skip
        return roots

    def _refill(self, k: int) -> None:
        """Evaluate stream k's controller for its next block of frames (a batched stream: only its
        root motion, READ_AHEAD_FRAMES of it), and note its events there. A stream's first block
        is shorter by its index modulo the block's length, so that refills of streams started
        together fall on different frames."""
        frame = int(self.clock[k])
        block = int(self._block[k])
        count = block - (k % block if frame == 0 else 0)
        controller = self.streams[k].controller
        if not self.batched[k]:
            pose = self._checked(k, controller.pose((frame + np.arange(count)) / self.fps), count)
            self._ahead[int(self.bones[k])][self._place[k], :count] = _entries(pose, self._scales[k])
        if self.rooted[k]:
            self._ahead_roots[k, :count] = self._roots_of(k, controller, (frame + np.arange(count)) / self.fps)
        self._first[k], self._count[k] = frame, count
        found = {}
        for e in controller.events(frame / self.fps, (frame + count) / self.fps):
            at = min(max(int(np.floor(e.time * self.fps + 1e-9)), frame), frame + count - 1)
            found.setdefault(at, []).append(e)
        if found:
            self._events[k] = found
        else:
            self._events.pop(k, None)


class UniquePool:
    """Per-agent animations without history (section 4.1): `size` slots (U), each holding a
    controller of at most `max_bones` joints, evaluated every frame; agents in a slot read its
    current pose. Its store is padded to `max_bones` per slot, as the paper's is."""

    def __init__(self, size: int, *, max_bones: int, fps: float = 30.0):
        self.size = validate.integer(size, "UniquePool.size", minimum=0)
        self.max_bones = validate.integer(max_bones, "UniquePool.max_bones", minimum=1)
        self.fps = validate.number(fps, "UniquePool.fps", minimum=1, maximum=MAX_FPS)
        validate.allocation(self.size * (self.max_bones * ENTRY_FLOATS * 4 + 16), f"UniquePool: {self.size} slots "
                            f"of {self.max_bones} joints", itemsize=1)  # fmt: skip
        self.store = np.zeros((self.size, self.max_bones, ENTRY_FLOATS), dtype=np.float32)
        self.controllers: list = [None] * self.size
        self.clock = np.zeros(self.size, dtype=np.int64)

    def check_slots(self, slots, *, field: str = "slot") -> np.ndarray:
        ids = np.atleast_1d(np.asarray(slots))
        if ids.dtype.kind not in "iu" or ids.size and (ids.min() < 0 or ids.max() >= self.size):
            raise ValidationError(f"{field}: unknown unique slot {slots!r}; the pool has slots 0..{self.size - 1}")
        empty = [int(k) for k in ids if self.controllers[int(k)] is None]
        if empty:
            raise ValidationError(f"{field}: unique slot {empty[0]} holds no controller (set it first)")
        return ids.astype(np.int64)

    def set(self, slot: int, controller) -> None:
        """Put `controller` in `slot`, its clock at 0, and evaluate its first pose."""
        slot = validate.integer(slot, "slot", minimum=0)
        if slot >= self.size:
            raise ValidationError(f"slot {slot} is beyond the unique pool's {self.size} slots")
        controller = _controller(controller, "UniquePool.set: controller")
        if controller.skeleton.n_joints > self.max_bones:
            raise ValidationError(
                f"the controller's skeleton has {controller.skeleton.n_joints} joints; "
                f"unique slots hold {self.max_bones}"
            )
        self.controllers[slot] = controller
        self.clock[slot] = 0
        self._evaluate(slot)

    def clear(self, slot: int) -> None:
        self.controllers[self.check_slots(slot)[0]] = None

    def advance(self) -> list:
        events = []
        for slot, controller in enumerate(self.controllers):
            if controller is not None:
                start = self.clock[slot] / self.fps
                events.extend((slot, e) for e in controller.events(start, start + 1 / self.fps))
                self.clock[slot] += 1
                self._evaluate(slot)
        return events

    def _evaluate(self, slot: int) -> None:
        controller = self.controllers[slot]
        pose = controller.pose([self.clock[slot] / self.fps])[0]
        j = controller.skeleton.n_joints
        self.store[slot, :j] = _entries(pose, controller.skeleton.scales.astype(np.float32))

    def read(self, slot: int) -> Pose:
        (k,) = self.check_slots(slot)
        j = self.controllers[k].skeleton.n_joints
        return entries_pose(self.store[k, :j].copy())

    def memory(self) -> int:
        """Bytes of every array the pool holds: its store, 48 U MaxBones (Equation 5's first
        term), and the slots' clocks."""
        return int(self.store.nbytes) + int(self.clock.nbytes)
