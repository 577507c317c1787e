"""OBJ sequences read at disk speed (flockkit.io.obj.read_sequence), against the disk and numpy.

    python bench/obj.py [--data ../shared/data] [--frames 48]

Writes, in a temporary folder on the disk, OBJ sequences of RobotExpressive's Dance clip (7 214
vertices, 3 237 triangles; the first `frames` frames): coordinates as Blender's exporter writes
them (``%.6f``), as ``repr`` writes them (17 significant digits), and a triangle soup of the same
frames (every face given its own corners, 9 711 vertices, ``%.6f``). For each it prints:

- the disk: the files' bytes read cold (each file's pages dropped from the page cache first, with
  ``os.posix_fadvise(..., POSIX_FADV_DONTNEED)`` after an fsync), one file after another, and
  the same bytes read again from the page cache;
- flockkit's read_sequence (vertices and faces, every number as Python's float reads it) cold,
  the pages dropped the same way, and warm (with numba's threads, and with one), and the ratio
  of its cold speed to the disk's (all times the best of 5);
- one core's parse rate: flockkit's compiled pass alone (``obj._scan``) over the later frames'
  bytes already in memory, one after another (what one thread can give, file reading and
  Python per file aside);
- the peers, on the same bytes already in memory, reading the vertices only (no faces):
  ``numpy.fromstring(..., sep=" ")`` over each file's vertex lines with their ``v`` blanked
  (numpy's C parser, correctly rounded, no Python per line: the fastest plain numpy parse we
  know), numpy.loadtxt over the vertex lines, and flockkit's own line-by-line parser (what a
  file the compiled pass gives up on costs), each checked equal to flockkit's output bit for bit;
- the load average (the machine is shared).

It also prints what the first read costs in a fresh process (numba imported, the compiled pass
loaded from its cache). Threads: numba's count (``NUMBA_NUM_THREADS``), printed.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
from timing import timed  # bench/timing.py: the scripts run from bench/

import flockkit
from flockkit.io import obj


def write_sequence(folder: Path, positions, faces, number: str) -> None:
    folder.mkdir()
    face_text = "".join("f " + " ".join(str(i + 1) for i in face) + "\n" for face in faces.tolist())
    for t, frame in enumerate(positions):
        vertices = "".join(f"v {number % x} {number % y} {number % z}\n" if number != "repr" else
                           f"v {x!r} {y!r} {z!r}\n" for x, y, z in frame.tolist())  # fmt: skip
        path = folder / f"frame{t:04d}.obj"
        path.write_text(f"# flockkit bench\no robot\n{vertices}{face_text}")
        with open(path, "rb") as handle:  # on the disk, so its pages can be dropped
            os.fsync(handle.fileno())


def drop(files) -> None:
    """Drop the files' pages from the page cache: the next read comes from the disk."""
    for file in files:
        fd = os.open(file, os.O_RDONLY)
        try:
            os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
        finally:
            os.close(fd)


def cold(function, files, repeat: int = 5):
    """The result and the best wall time of `repeat` calls of `function`, the files' pages
    dropped before each."""
    best = float("inf")
    for _ in range(repeat):
        drop(files)
        begin = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - begin)
    return result, best


def fromstring(data: list[bytes]) -> list[np.ndarray]:
    """Each file's vertices by numpy's C parser: the vertex lines (one block in these files)
    with their ``v`` blanked, parsed with ``numpy.fromstring(sep=" ")``."""
    found = []
    for text in data:
        first, last = text.index(b"\nv ") + 1, text.rindex(b"\nv ")
        block = bytearray(text[first : text.index(b"\n", last + 1)])
        np.frombuffer(block, np.uint8)[np.frombuffer(block, np.uint8) == ord("v")] = ord(" ")
        found.append(np.fromstring(block.decode(), sep=" ").reshape(-1, 3))
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    parser.add_argument("--frames", type=int, default=48)
    args = parser.parse_args()
    mesh = flockkit.io.read_mesh_animation(Path(args.data) / "robot-expressive-gltf" / "RobotExpressive.glb",
                                           clip="Dance")  # fmt: skip
    positions, faces = mesh.motion.positions[: args.frames], mesh.faces
    soup = positions[:, faces.ravel()], np.arange(faces.size).reshape(faces.shape)
    cases = [("Dance %.6f", positions, faces, "%.6f"), ("Dance repr", positions, faces, "repr"),
             ("Dance soup %.6f", *soup, "%.6f")]  # fmt: skip
    print(f"threads: {numba.get_num_threads()} (numba's); MB/s of the files' bytes; the peers read vertices only")
    print(f"{'sequence':>16} {'frames':>6} {'MB':>5} | {'disk cold':>9} {'cached':>7} | {'flockkit cold':>13} "
          f"{'warm':>5} {'1 thread':>8} {'cold/disk':>9} {'1-core pass':>11} | {'fromstring':>10} {'loadtxt':>7} "
          f"{'line by line':>12} | {'load':>5}")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:  # /tmp: on the disk here (ext4), not in memory
        for name, frames, own_faces, number in cases:
            folder = Path(tmp) / name.replace(" ", "-").replace("%", "")
            write_sequence(folder, frames, own_faces, number)
            files = obj._frames(str(folder))
            size = sum(Path(f).stat().st_size for f in files) / 1e6
            obj.read_sequence(str(folder))  # compiled (or loaded from the cache)

            def read_bytes(files=files):
                return [flockkit._files.read_bytes(f) for f in files]

            data, disk = cold(read_bytes, files)
            _, cached = timed(read_bytes, repeat=5)
            (found, _, _), reader_cold = cold(lambda folder=folder: obj.read_sequence(str(folder)), files)
            _, reader = timed(lambda folder=folder: obj.read_sequence(str(folder)), repeat=5)
            threads = numba.get_num_threads()
            numba.set_num_threads(1)
            _, alone = timed(lambda folder=folder: obj.read_sequence(str(folder)), repeat=5)
            numba.set_num_threads(threads)
            padded = [obj._read_padded(file) for file in files[1:]]
            first, _, known = obj._read_first(files[0])
            out = np.empty((len(files), *first.shape))

            def parse(padded=padded, known=known, out=out):
                return [obj._compiled()(b, n, out[t], *known, True)[0] for t, (b, n) in enumerate(padded, 1)]

            statuses, pass_time = timed(parse, repeat=5)
            assert statuses == [obj._READ] * len(padded)
            np.testing.assert_array_equal(out[1:].view(np.uint64), found[1:].view(np.uint64))
            pass_rate = sum(n for _, n in padded) / 1e6 / pass_time
            texts = [d.decode() for d in data]

            def loadtxt(texts=texts):
                return [np.loadtxt([line for line in text.splitlines() if line.startswith("v ")], usecols=(1, 2, 3))
                        for text in texts]  # fmt: skip

            parsed, numpy_c = timed(lambda data=data: fromstring(data), repeat=3)
            loaded, peer = timed(loadtxt)
            lines, careful = timed(lambda texts=texts, files=files: list(map(obj._parse_obj, files, texts)))
            for other in (parsed, loaded, [points for points, _ in lines]):  # the same numbers, bit for bit
                np.testing.assert_array_equal(np.asarray(other).view(np.uint64), found.view(np.uint64))
            print(f"{name:>16} {len(files):>6} {size:>5.1f} | {size / disk:>9.0f} {size / cached:>7.0f} | "
                  f"{size / reader_cold:>13.0f} {size / reader:>5.0f} {size / alone:>8.0f} "
                  f"{disk / reader_cold:>9.2f} {pass_rate:>11.0f} | "
                  f"{size / numpy_c:>10.0f} {size / peer:>7.0f} {size / careful:>12.0f} | "
                  f"{os.getloadavg()[0]:>5.2f}", flush=True)  # fmt: skip
        fresh = (f"import sys, time; sys.path.insert(0, {str(Path(__file__).parent)!r}); import flockkit; "
                 f"from flockkit.io import obj; t = time.perf_counter(); obj.read_sequence({str(folder)!r}); "
                 f"print(time.perf_counter() - t)")  # fmt: skip
        first = float(subprocess.run([sys.executable, "-c", fresh], capture_output=True, text=True, check=True).stdout)
        print(f"first read of the soup in a fresh process (flockkit imported; the compiled pass loaded from its cache, "
              f"the files page-cached): {first:.3f} s")  # fmt: skip


if __name__ == "__main__":
    main()
