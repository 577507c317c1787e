"""Run the robustness suite's cases with larger budgets and print the table of outcomes per area.

    python -m tests.robustness.tally [--examples N]

Areas: the replayed library and CLI cases, arbitrary values for every field of the value types and
convenience calls, every single-byte flip (two ways) and truncation of a saved motion and graph,
arbitrary CLI arguments, SIGTERM in the middle of writes, byte-for-byte determinism across n_jobs
and joblib backends, the untrusted-assets cases by area (escapes from the asset folder, damaged
glTF fields and buffers, sizes before allocation, hangs, damaged BVH, OBJ and npz files, silent
nonsense), and every input the fuzzer found. A row counts: tried, named (a documented flockkit error; for the CLI
one line and a non-zero exit), worked, crash (anything else), hang (past the time limit).
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import flockkit
from flockkit.testing import strategies as fst

from . import cases, fuzz, untrusted
from .harness import cli_outcome, outcome, say
from .test_fuzz import _BASE, CALLS, _argv, _junk


def _values(examples):
    from hypothesis.errors import NonInteractiveExampleWarning

    found = []
    strategy = fst.anything().filter(_junk)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NonInteractiveExampleWarning)
        for name, field in CALLS:
            for _ in range(examples):
                value = strategy.example()
                call = _BASE[name]
                kind, what = outcome(lambda c=call, f=field, v=value: c(**{f: v}), seconds=20)
                found.append((kind, f"{name}({field}={value!r}): {what}"))
    return found


def _files(folder):
    found = []
    for kind, load in (("motion", flockkit.Motion.load), ("graph", flockkit.MotionGraph.load)):
        data = (folder / f"{kind}.npz").read_bytes()
        target = folder / f"damaged-{kind}.npz"
        variants = [
            bytes(data[:i]) + bytes([data[i] ^ mask]) + data[i + 1 :] for i in range(len(data)) for mask in (1, 255)
        ]
        variants += [data[:n] for n in range(0, len(data), 3)]
        for variant in variants:
            target.write_bytes(variant)
            found.append(outcome(lambda: load(target), seconds=20))  # noqa: B023 - called at once
    return found


def _cli_random(folder, examples):
    from hypothesis import strategies as st
    from hypothesis.errors import NonInteractiveExampleWarning

    @st.composite
    def argvs(draw):
        return _argv(_Drawer(draw), folder)

    found = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NonInteractiveExampleWarning)
        for _ in range(examples):
            found.append(cli_outcome(argvs().example(), seconds=30))
    return found


class _Drawer:
    """What the CLI argument grammar expects of hypothesis's `data` object."""

    def __init__(self, draw):
        self.draw = draw


def _signals(folder, runs):
    motion = flockkit.Motion(positions=np.random.default_rng(0).normal(size=(4000, 40, 2)), dt=0.1)
    motion.save(folder / "big.npz")
    found = []
    for run in range(runs):
        out = folder / f"sig{run}"
        out.mkdir()
        suffix = (".csv", ".json", ".gif", ".npz")[run % 4]
        command = {".gif": "render", ".npz": "simulate"}.get(suffix, "export")
        args = ["--agents", "300", "--steps", "3000"] if command == "simulate" else [str(folder / "big.npz")]
        argv = [sys.executable, "-m", "flockkit.cli", command, *args, "-o", str(out / f"f{suffix}")]
        process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        time.sleep(0.5 + 0.37 * run)
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=120)
        left = [p.name for p in out.iterdir() if p.name.startswith(".")]
        if left:
            found.append(("crash", f"left {left}"))
        elif process.returncode in (0, 143, -signal.SIGTERM) and "Traceback" not in err:
            # -15: the signal came while Python was still starting, before any work: nothing to clean
            found.append(("ok" if process.returncode == 0 else "named", err.strip()))
        else:
            found.append(("crash", err[-300:]))
    return found


def _determinism():
    import joblib

    from flockkit.constrained.scenario import load_scenario

    recording = flockkit.simulate(n_agents=6, steps=200, seed=3)
    # 20 agents squeezing past obstacles: where chains once drifted apart with the BLAS threads
    problem, _ = load_scenario(Path(__file__).resolve().parents[2] / "examples" / "scenarios" / "obstacle-squeeze.toml")

    def results(n_jobs=None):
        graph = flockkit.build_graph(recording, seed=0, n_jobs=n_jobs)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", flockkit.errors.FlockkitWarning)
            solution = flockkit.solve(problem, iterations=5, chains=2, starts=1, seed=1, n_jobs=n_jobs)
        return graph, [m.positions.tobytes() for m in solution.motions]

    reference, found = results(1), []
    for n_jobs in (1, 2, -1):
        found.append(("ok", "") if results(n_jobs) == reference else ("crash", f"n_jobs={n_jobs} differs"))
    try:
        from distributed import Client, LocalCluster

        with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster, Client(cluster):
            with joblib.parallel_config(backend="dask", n_jobs=-1):
                found.append(("ok", "") if results() == reference else ("crash", "dask differs"))
    except ImportError:
        pass
    return found


def _untrusted(folder) -> list:
    """(area, outcomes) of the untrusted-assets cases, each under 10 s; a file that should have
    been refused and was read counts as a crash ("accepted"), as does a refused correct file."""
    areas: dict[str, list] = {}
    for area, name, call, expected in untrusted.cases(folder / "untrusted"):
        kind, what = outcome(call, seconds=10)
        if (expected, kind) in (("named", "ok"), ("ok", "named")):
            kind, what = "crash", f"expected {expected}: {what or 'accepted'}"
        areas.setdefault(area, []).append((kind, f"{name}: {what}"))
    findings = sorted(p for p in fuzz.CRASHES.glob("*/*") if p.suffix != ".txt")
    replayed = []
    for path in findings:
        kind, what = fuzz.outcome(path.parent.name, path.read_bytes(), folder)
        replayed.append(("named" if kind == "ok" else kind, f"{path.name}: {what}"))
    return [(f"untrusted: {area}", results) for area, results in areas.items()] + [
        ("fuzzer findings replayed", replayed)
    ]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=40, help="arbitrary values per field (default 40)")
    parser.add_argument("--cli", type=int, default=300, help="arbitrary CLI invocations (default 300)")
    parser.add_argument("--signals", type=int, default=12, help="SIGTERM runs (default 12)")
    args = parser.parse_args(argv)
    folder = Path(tempfile.mkdtemp(prefix="flockkit-tally-"))
    flockkit.simulate(n_agents=4, steps=40, seed=2).save(folder / "motion.npz")
    flockkit.build_graph(flockkit.simulate(n_agents=4, steps=150, seed=2), seed=0).save(folder / "graph.npz")
    rows = [
        ("replayed library cases", [outcome(call) for _, call in cases.library(folder)]),
        ("replayed CLI cases", [cli_outcome(argv) for _, argv in cases.cli(folder)]),
        ("arbitrary values for value types and calls", _values(args.examples)),
        ("byte flips and truncations of saved files", _files(folder)),
        ("arbitrary CLI arguments", _cli_random(folder, args.cli)),
        ("SIGTERM during writes (named = exit 143, nothing left)", _signals(folder, args.signals)),
        ("determinism across n_jobs and backends", _determinism()),
        *_untrusted(folder),
    ]
    print("| area | tried | named error | worked | crash | hang |")
    print("|---|---|---|---|---|---|")
    for area, results in rows:
        print(say(area, results))
        for kind, what in results:
            if kind in ("crash", "hang"):
                print(f"    {kind}: {what[:200]}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
