"""OBJ sequences read at disk speed (flockkit.io.obj.read_sequence).

    python bench/obj.py [--data ../shared/data] [--frames 48]

Writes, in a temporary folder, OBJ sequences of RobotExpressive's Dance clip (7 214 vertices,
3 237 triangles; the first `frames` frames): coordinates as Blender's exporter writes them
(``%.6f``), as ``repr`` writes them (17 significant digits), and a triangle soup of the same
frames (every face given its own corners, 9 711 vertices, ``%.6f``). For each it prints the bytes
of the sequence, the time to read those bytes (page-cached, what ``read_bytes`` costs: the floor),
flockkit's read_sequence (the best of 3, in a process where it has run once) and its time beyond
the bytes, and beside it, on the same bytes already in memory: numpy.loadtxt over the vertex
lines (the plain numpy parse of the same numbers, faces not read) and the line-by-line parser
every frame went through before (flockkit's own ``_parse_obj``). It also prints what the first
read costs in a fresh process (importing numba and loading the compiled pass from its cache).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

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
        (folder / f"frame{t:04d}.obj").write_text(f"# flockkit bench\no robot\n{vertices}{face_text}")


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
    print(f"{'sequence':>16} {'frames':>6} {'vertices':>8} {'MB':>6} {'read bytes s':>12} {'flockkit s':>10} "
          f"{'beyond bytes s':>14} {'MB/s':>6} {'loadtxt s':>9} {'line by line s':>14}")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        for name, frames, own_faces, number in cases:
            folder = Path(tmp) / name.replace(" ", "-").replace("%", "")
            write_sequence(folder, frames, own_faces, number)
            files = obj._frames(str(folder))
            size = sum(Path(f).stat().st_size for f in files)
            obj.read_sequence(str(folder))  # compiled (or loaded from the cache) and page-cached
            data, reading = timed(lambda files=files: [flockkit._files.read_bytes(f) for f in files], repeat=3)
            (found, _, _), reader = timed(lambda folder=folder: obj.read_sequence(str(folder)), repeat=3)
            texts = [d.decode() for d in data]

            def loadtxt(texts=texts):
                return [np.loadtxt([line for line in text.splitlines() if line.startswith("v ")], usecols=(1, 2, 3))
                        for text in texts]  # fmt: skip

            _, peer = timed(loadtxt, repeat=3)
            lines, careful = timed(lambda texts=texts, files=files: list(map(obj._parse_obj, files, texts)))
            np.testing.assert_array_equal(found, [points for points, _ in lines])  # the same numbers, bit for bit
            print(f"{name:>16} {len(files):>6} {frames.shape[1]:>8} {size / 1e6:>6.1f} {reading:>12.3f} "
                  f"{reader:>10.3f} {reader - reading:>14.3f} {size / 1e6 / reader:>6.0f} {peer:>9.3f} "
                  f"{careful:>14.3f}", flush=True)  # fmt: skip
        fresh = (f"import sys, time; sys.path.insert(0, {str(Path(__file__).parent)!r}); import flockkit; "
                 f"from flockkit.io import obj; t = time.perf_counter(); obj.read_sequence({str(folder)!r}); "
                 f"print(time.perf_counter() - t)")  # fmt: skip
        first = float(subprocess.run([sys.executable, "-c", fresh], capture_output=True, text=True, check=True).stdout)
        print(f"first read of the soup in a fresh process (numba imported, the compiled pass loaded): {first:.3f} s")


if __name__ == "__main__":
    main()
