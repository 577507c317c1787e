"""Interrupts and files: SIGTERM mid-write leaves no temporary file and no worker process; files
get the mode an ordinary open() gives; a symlinked target is replaced, its target left alone."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import flockkit
from flockkit._atomic import TERMINATED, atomic_path


def test_sigterm_inside_a_write_removes_the_temporary_file(tmp_path):
    target = tmp_path / "out.npz"
    previous = signal.signal(signal.SIGTERM, signal.SIG_DFL)  # the default action (Ray, Dask change it)
    try:
        with pytest.raises(SystemExit) as info, atomic_path(target) as tmp:
            tmp.write_bytes(b"half")
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1)  # the handler raises SystemExit here
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # restored
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert info.value.code == TERMINATED
    assert list(tmp_path.iterdir()) == []


def _flockkit(*args, cwd):
    return subprocess.Popen([sys.executable, "-m", "flockkit.cli", *args], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip


def _terminate_when(process, ready, limit=60.0) -> bool:
    """Send SIGTERM as soon as ready() holds; False if the process ended first."""
    end = time.monotonic() + limit
    while time.monotonic() < end and process.poll() is None:
        if ready():
            process.send_signal(signal.SIGTERM)
            return True
        time.sleep(0.002)
    return False


@pytest.mark.parametrize("suffix", [".csv", ".json", ".gif"])
def test_sigterm_mid_write_exits_143_and_leaves_nothing(tmp_path, suffix):
    frames = 4000 if suffix != ".gif" else 300
    motion = flockkit.Motion(positions=np.random.default_rng(0).normal(size=(frames, 40, 2)), dt=0.1)
    motion.save(tmp_path / "in.npz")
    out = tmp_path / "out"
    out.mkdir()
    command = "render" if suffix == ".gif" else "export"
    process = _flockkit(command, str(tmp_path / "in.npz"), "-o", str(out / f"flock{suffix}"), cwd=tmp_path)
    caught = _terminate_when(process, lambda: any(p.name.startswith(".") for p in out.iterdir()))
    _, err = process.communicate(timeout=60)
    assert caught, "the command finished before its write could be interrupted"
    assert process.returncode == TERMINATED and err.strip().endswith("terminated"), err
    assert list(out.iterdir()) == []


def _loky_children(pid) -> set[int]:
    found = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                command = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            if int(stat[1]) == pid and b"loky" in command:
                found.add(int(entry.name))
    return found


def _alive(pids) -> set[int]:
    return {
        pid
        for pid in pids
        if Path(f"/proc/{pid}").exists() and "Z" not in Path(f"/proc/{pid}/stat").read_text().split()[2]
    }


def test_sigterm_during_a_parallel_build_stops_its_workers(tmp_path):
    flockkit.simulate(n_agents=20, steps=1500, seed=1).save(tmp_path / "in.npz")
    process = _flockkit("build", str(tmp_path / "in.npz"), "-o", str(tmp_path / "g.npz"), "--jobs", "2", cwd=tmp_path)
    workers = set()

    def started():
        workers.update(_loky_children(process.pid))
        return len(workers) >= 2

    caught = _terminate_when(process, started)
    _, err = process.communicate(timeout=60)
    assert caught, "the build ended before its workers started"
    assert process.returncode == TERMINATED, err
    end = time.monotonic() + 10
    while _alive(workers) and time.monotonic() < end:
        time.sleep(0.1)
    assert not _alive(workers)
    assert [p.name for p in tmp_path.iterdir()] == ["in.npz"]


def test_files_take_the_umask_and_replace_a_symlink_not_its_target(tmp_path):
    motion = flockkit.simulate(n_agents=3, steps=5, seed=1)
    previous = os.umask(0o027)
    try:
        motion.save(tmp_path / "a.npz")
    finally:
        os.umask(previous)
    assert (tmp_path / "a.npz").stat().st_mode & 0o777 == 0o640
    elsewhere = tmp_path / "elsewhere.npz"
    elsewhere.write_bytes(b"keep")
    elsewhere.chmod(0o600)
    (tmp_path / "link.npz").symlink_to(elsewhere)
    motion.save(tmp_path / "link.npz")
    assert not (tmp_path / "link.npz").is_symlink() and flockkit.Motion.load(tmp_path / "link.npz") == motion
    assert elsewhere.read_bytes() == b"keep" and elsewhere.stat().st_mode & 0o777 == 0o600


def test_usd_is_written_under_a_name_nobody_else_holds(tmp_path):
    pytest.importorskip("pxr", reason="USD export needs the usd extra")
    motion = flockkit.simulate(n_agents=3, steps=5, seed=1)
    flockkit.io.export(motion, tmp_path / "flock.usda")
    assert [p.name for p in tmp_path.iterdir()] == ["flock.usda"]
