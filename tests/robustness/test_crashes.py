"""Every input the coverage-guided fuzzer (``python -m tests.robustness.fuzz``) ever found, replayed:
each now reads, or raises a documented error, within the time limit. And the fuzzer itself runs."""

import subprocess
import sys
from pathlib import Path

import pytest

from . import fuzz

FINDINGS = sorted(p for p in fuzz.CRASHES.glob("*/*") if p.suffix != ".txt")


@pytest.mark.parametrize("path", FINDINGS, ids=[f"{p.parent.name}/{p.name}" for p in FINDINGS])
def test_a_finding_of_the_fuzzer_is_named_now(path, tmp_path):
    kind, what = fuzz.outcome(path.parent.name, path.read_bytes(), tmp_path)
    assert kind == "ok", f"{path.with_suffix('.txt').read_text().strip()} -> now {what}"


@pytest.mark.parametrize("reader", fuzz.READERS)
def test_the_fuzzer_runs_each_reader_and_finds_nothing(reader, tmp_path):
    pytest.importorskip("atheris", reason="the fuzzer needs atheris (in the test extra)")
    command = [sys.executable, "-m", "tests.robustness.fuzz", "--reader", reader, "--runs", "300"]
    run = subprocess.run([*command, "--crashes", str(tmp_path)], cwd=Path(__file__).resolve().parents[2],
                         capture_output=True, text=True, timeout=600)  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    row = next(line for line in run.stdout.splitlines() if line.startswith(f"| {reader} |"))
    _, _, _, inputs, findings, ended, _ = (cell.strip() for cell in row.split("|"))
    assert int(inputs) >= 300 and findings == "0" and ended == "0", run.stdout + run.stderr[-2000:]
