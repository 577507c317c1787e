"""A coverage-guided fuzzer (atheris, libFuzzer for Python) over flockkit's file readers.

    python -m tests.robustness.fuzz --minutes N [--reader gltf|bvh|obj|npz|scenario ...]

Each reader is fuzzed for N minutes in a process of its own, from seeds made here (a tiny skinned
glTF as text and as GLB, small BVH, OBJ, flockkit .npz files and the example scenarios), with a
dictionary of its format's keywords, and with flockkit's memory budget (FLOCKKIT_MEMORY_LIMIT) at
256 MiB unless set. An input "works" when the reader returns or raises a documented error
(``FlockkitError``, ``FileNotFoundError``); anything else, a hang past 10 s or a process past 3 GB
is a finding: its input is kept in ``tests/robustness/crashes/<reader>/``, one per distinct failure
(exception type and the flockkit line that raised it), where ``test_crashes.py`` replays it. The
run prints a table: reader, inputs run, findings.

Needs atheris (``pip install atheris``), which is in the test extra.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

CRASHES = Path(__file__).resolve().parent / "crashes"
READERS = ("gltf", "bvh", "obj", "npz", "scenario")
SECONDS = 10  # an input that takes longer hangs
MEMORY_MB = 3072  # a process that grows past this is a finding (libFuzzer's -rss_limit_mb)
# flockkit's memory budget in the fuzzed process: what one input may ask for, and so (simulating,
# sampling) about how much work it may describe, is well inside MEMORY_MB and SECONDS
BUDGET = "256M"

KEYWORDS = {
    "gltf": ["asset", "version", "2.0", "buffers", "bufferViews", "accessors", "byteLength", "byteOffset",
             "byteStride", "buffer", "bufferView", "componentType", "count", "type", "SCALAR", "VEC3", "VEC4", "MAT4",
             "normalized", "sparse", "indices", "values", "nodes", "children", "mesh", "skin", "matrix", "rotation",
             "translation", "scale", "weights", "meshes", "primitives", "attributes", "POSITION", "JOINTS_0",
             "WEIGHTS_0", "mode", "targets", "skins", "joints", "inverseBindMatrices", "animations", "samplers",
             "channels", "input", "output", "interpolation", "LINEAR", "STEP", "CUBICSPLINE", "target", "node", "path",
             "scenes", "scene", "uri", "data:application/octet-stream;base64,", "extensionsRequired", "5126",
             "5123", "5121", "-1", "4294967295", "1e308", "glTF", "JSON", "BIN\x00"],
    "bvh": ["HIERARCHY", "ROOT", "JOINT", "End", "Site", "OFFSET", "CHANNELS", "Xposition", "Yposition", "Zposition",
            "Xrotation", "Yrotation", "Zrotation", "MOTION", "Frames:", "Frame", "Time:", "{", "}", "-1", "1e308",
            "nan"],
    "obj": ["v ", "f ", "vt ", "vn ", "/", "-1", "0", "99999999999", "1e308", "nan", "\n"],
    "npz": ["PK", "__metadata__.npy", "positions.npy", "\x93NUMPY", "'descr'", "'<f8'", "'|b1'", "'shape'",
            "'fortran_order'", "format", "version", "motion", "graph", "mesh", "segmentation", "layers", "scene"],
    "scenario": ["[problem]", "[solve]", "[[point]]", "[[com]]", "[[shape]]", "[[obstacle]]", "agents", "duration",
                 "dims", "dt", "time", "position", "velocity", "agent", "box", "ball", "polygon", "lower", "upper",
                 "center", "radius", "vertices", "iterations", "seed", "chains", "-1", "1e308", "nan", "inf"],
}  # fmt: skip


def _call_all(calls) -> None:
    for call in calls:
        call()


def reader_calls(reader: str, path: Path):
    """What reading `path` as `reader` means: every flockkit call that reads such a file."""
    import flockkit
    from flockkit import io

    if reader == "gltf":
        return [lambda: io.list_clips(path), lambda: io.read_mesh_animation(path, fps=4), lambda: io.read_clips(path)]
    if reader == "bvh":
        return [lambda: io.read_clips(path), lambda: io.read_clips(path, fps=30)]
    if reader == "obj":
        return [lambda: io.read_mesh_animation(path)]
    if reader == "npz":
        from flockkit import _npzfile

        loaders = {"motion": flockkit.Motion.load, "graph": flockkit.MotionGraph.load,
                   "mesh": flockkit.AnimatedMesh.load, "segmentation": flockkit.Segmentation.load,
                   "layers": flockkit.GraphLayers.load, "scene": flockkit.SceneAnimation.load}  # fmt: skip

        def load():
            loaders.get(_npzfile.kind_of(path), flockkit.Motion.load)(path)

        return [load]
    from flockkit.constrained.scenario import load_scenario
    from flockkit.crowd.file import read_crowd_scene
    from flockkit.scene import read_scene

    return [lambda: load_scenario(path), lambda: read_scene(path), lambda: read_crowd_scene(path)]


def suffix(reader: str, data: bytes) -> str:
    if reader == "gltf":
        return ".glb" if data[:4] == b"glTF" else ".gltf"
    return {"bvh": ".bvh", "obj": ".obj", "npz": ".npz", "scenario": ".toml"}[reader]


def fixtures(reader: str, folder: Path) -> None:
    """The files inputs of `reader` name, beside them in `folder`: for crowd and scene files, a
    tiny skinned glTF (tiny.glb) and a small motion graph (graph.npz)."""
    if reader != "scenario" or (folder / "graph.npz").exists():
        return
    import flockkit

    from . import assets

    document, buffer = assets.tiny()
    assets.write(folder / "tiny.glb", document, buffer)
    flockkit.build_graph(flockkit.simulate(n_agents=3, steps=150, seed=0), seed=0).save(folder / "graph.npz")


def outcome(reader: str, data: bytes, folder: Path) -> tuple[str, str]:
    """("ok", "") when every call that reads `data` as `reader` returns or raises a documented
    error within the time limit; else ("crash", the failure's signature: the exception type and
    the innermost flockkit line that raised it, then its message)."""
    from flockkit.errors import FlockkitError

    from .harness import _Hang, _time_limit

    fixtures(reader, folder)
    path = folder / f"input{suffix(reader, data)}"
    path.write_bytes(data)
    for call in reader_calls(reader, path):
        try:
            with _time_limit(SECONDS):
                call()
        except (FlockkitError, FileNotFoundError):
            continue
        except _Hang as exc:
            return "crash", f"{signature(exc)} (past {SECONDS} s)"
        except Exception as exc:  # noqa: BLE001 - what the fuzzer looks for
            return "crash", f"{signature(exc)}: {str(exc)[:300]}"
    return "ok", ""


def signature(exc: BaseException) -> str:
    """The exception type and the innermost flockkit frame that raised it: one per bug."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if "flockkit" in f.filename]
    where = f"{Path(frames[-1].filename).name}:{frames[-1].lineno}" if frames else "outside flockkit"
    return f"{type(exc).__name__} at {where}"


def keep(reader: str, data: bytes, key: str, what: str, crashes: Path = CRASHES) -> Path:
    """Keep a finding's input under <crashes>/<reader>/, named by its signature `key` (one input
    per bug), with what happened beside it."""
    folder = crashes / reader
    folder.mkdir(parents=True, exist_ok=True)
    name = hashlib.sha1(key.encode()).hexdigest()[:12]
    path = folder / f"{name}{suffix(reader, data)}"
    if not path.exists():
        path.write_bytes(data)
        (folder / f"{name}.txt").write_text(what[:2000] + "\n")
    return path


def seeds(reader: str, folder: Path) -> list[bytes]:
    """Small valid inputs of each reader to start from."""
    import numpy as np

    import flockkit

    from . import assets, untrusted

    if reader == "gltf":
        document, buffer = assets.tiny()
        assets.write(folder / "tiny.gltf", document, buffer)
        assets.write(folder / "tiny.glb", document, buffer)
        return [(folder / "tiny.gltf").read_bytes(), (folder / "tiny.glb").read_bytes()]
    if reader == "bvh":
        return [untrusted._nested_bvh(3).encode(), untrusted._nested_bvh(1).encode()]
    if reader == "obj":
        return [b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n",
                b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\nf -4 -3 -2\n"]  # fmt: skip
    if reader == "npz":
        recording = flockkit.simulate(n_agents=3, steps=150, seed=0)
        values = {
            "motion": flockkit.simulate(n_agents=3, steps=30, seed=0),
            "graph": flockkit.build_graph(recording, seed=0),
            "segmentation": flockkit.Segmentation(labels=[0, 1, 1], n_parts=2),
            "mesh": flockkit.AnimatedMesh(
                motion=flockkit.Motion(positions=np.zeros((2, 3, 3)), dt=0.1), faces=[[0, 1, 2]]
            ),  # fmt: skip
        }
        found = []
        for name, value in values.items():
            value.save(folder / f"{name}.npz")
            found.append((folder / f"{name}.npz").read_bytes())
        return found
    fixtures(reader, folder)
    examples = Path(__file__).resolve().parents[2] / "examples" / "scenarios"
    return [p.read_bytes() for p in sorted(examples.glob("*.toml"))] + [CROWD_SEED, SCENE_SEED]


CROWD_SEED = b"""seconds = 0.5
fps = 10
record = 2
[trajectories]
simulate = { agents = 3, seed = 1 }
[character]
clips = "tiny.glb"
up = "y"
forward = "x"
[[streams]]
name = "idle"
clip = "wave"
history = 4
[[streams]]
name = "fast"
clip = "wave"
rate = 2.0
default = "Stopped"
[[states]]
name = "idle"
streams = ["idle"]
high = 0.5
[[states]]
name = "move"
streams = ["fast"]
low = 0.5
[[cues]]
name = "go"
time = 0.2
stream = "fast"
agents = "half"
duration = 0.2
"""
SCENE_SEED = b"""duration = 2
seed = 1
region = [[0, 0], [40, 0], [40, 30], [0, 30]]
scale = [0.8, 1.2]
headings = "aligned"
[[templates]]
graph = "graph.npz"
count = 2
[[arrows]]
position = [20, 15]
keyframes = [[0, [0.8, 0]], [1, [0, 0.8]]]
[walk]
budget = 5
"""


def _npz_mutator(data: bytes, max_size: int, seed: int) -> bytes:
    """A structure-aware mutation of an .npz: one member's bytes mutated and the archive written
    again with correct CRCs, so that mutations reach the arrays and the metadata instead of
    dying at the zip's checksum; an input that is not an archive is mutated as bytes."""
    import io
    import random
    import zipfile

    import atheris

    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            members = [(info.filename, archive.read(info)) for info in archive.infolist()]
    except Exception:  # noqa: BLE001 - not an archive (yet): mutate it as bytes
        return atheris.Mutate(data, max_size)
    if not members:
        return atheris.Mutate(data, max_size)
    pick = random.Random(seed).randrange(len(members))
    name, content = members[pick]
    members[pick] = (name, atheris.Mutate(content, max(len(content) * 2, 64)))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as archive:
        for name, content in members:
            archive.writestr(name, content)
    return out.getvalue()[:max_size] if len(out.getvalue()) > max_size else out.getvalue()


def _escaped(word: str) -> str:
    """`word` as a libFuzzer dictionary entry: printable ASCII as it is, other bytes as \\xHH."""
    return "".join(chr(b) if 32 <= b < 127 and chr(b) not in '"\\' else f"\\x{b:02X}" for b in word.encode("latin-1"))


def _child(reader: str, seconds: float, corpus: Path, runs: int | None, crashes: Path) -> int:
    """Run atheris on `reader` for `seconds`; findings are kept as they come, not raised, so one
    run finds every bug it can reach. Prints the inputs run."""
    import atheris

    os.environ.setdefault("FLOCKKIT_MEMORY_LIMIT", BUDGET)
    with atheris.instrument_imports(include=["flockkit", "flockkit_controllers"]):
        import flockkit  # noqa: F401
        import flockkit.constrained.scenario  # noqa: F401
        import flockkit.crowd.file  # noqa: F401
        import flockkit.io  # noqa: F401
        import flockkit.scene  # noqa: F401
    folder = Path(tempfile.mkdtemp(prefix=f"flockkit-fuzz-{reader}-"))
    for k, data in enumerate(seeds(reader, folder)):
        (corpus / f"seed{k}").write_bytes(data)  # libFuzzer adds what it finds to this folder
    found = set()

    def one(data: bytes) -> None:
        kind, what = outcome(reader, data, folder)
        if kind == "crash":
            key = what.split(":")[0]
            if key not in found:
                found.add(key)
                keep(reader, data, key, what, crashes)
                print(f"finding: {what[:300]}", file=sys.stderr, flush=True)

    dictionary = corpus.parent / f"{reader}.dict"
    dictionary.write_text("".join(f'"{_escaped(word)}"\n' for word in KEYWORDS[reader]))
    argv = [sys.argv[0], str(corpus), f"-max_total_time={int(seconds)}", f"-timeout={SECONDS * 3}",
            f"-rss_limit_mb={MEMORY_MB}", f"-dict={dictionary}", "-print_final_stats=1", "-max_len=65536",
            f"-artifact_prefix={crashes / reader}/"]  # fmt: skip
    if runs is not None:
        argv += [f"-runs={runs}", "-seed=1"]
    (crashes / reader).mkdir(parents=True, exist_ok=True)
    atheris.Setup(argv, one, custom_mutator=_npz_mutator if reader == "npz" else None)
    atheris.Fuzz()
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=1.0, help="minutes per reader (default 1)")
    parser.add_argument("--reader", action="append", choices=READERS, help="the readers to fuzz (default all)")
    parser.add_argument("--runs", type=int, help="stop each reader after this many inputs (with -seed=1: repeatable)")
    parser.add_argument("--crashes", type=Path, default=CRASHES, help="where findings are kept (default: the suite's)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--corpus", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        return _child(args.child, args.minutes * 60, Path(args.corpus), args.runs, args.crashes)
    rows = []
    for reader in args.reader or READERS:
        kept = args.crashes / reader
        before = set(kept.glob("*"))
        corpus = Path(tempfile.mkdtemp(prefix=f"flockkit-corpus-{reader}-")) / "corpus"
        corpus.mkdir()
        start, runs, restarts = time.monotonic(), 0, 0
        while (left := args.minutes * 60 - (time.monotonic() - start)) > 5:
            # libFuzzer ends a run at a timeout or out of memory (and keeps the input): go on
            process = subprocess.run(
                [sys.executable, "-m", "tests.robustness.fuzz", "--child", reader, "--corpus", str(corpus),
                 "--minutes", str(left / 60), "--crashes", str(args.crashes),
                 *(["--runs", str(args.runs)] if args.runs else [])],
                cwd=Path(__file__).resolve().parents[2], capture_output=True, text=True,
            )  # fmt: skip
            output = process.stdout + process.stderr
            runs += sum(int(line.split()[-1]) for line in output.splitlines() if "number_of_executed_units" in line)
            for line in output.splitlines():
                if line.startswith("finding:") or "ERROR: libFuzzer" in line:
                    print(f"{reader}: {line[:300]}", file=sys.stderr)
            if process.returncode == 0:
                break
            restarts += 1
        new = sorted(p.name for p in set(kept.glob("*")) - before if p.suffix != ".txt")
        rows.append((reader, round((time.monotonic() - start) / 60, 1), runs, len(new), restarts))
    print("| reader | minutes | inputs run | new findings | runs ended early |")
    print("|---|---|---|---|---|")
    for row in rows:
        print("| " + " | ".join(map(str, row)) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
