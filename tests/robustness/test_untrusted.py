"""Untrusted assets: a file cannot read outside its folder, crash the process, ask for the machine's
memory or hang it; every damaged field is a FileFormatError naming the file and the JSON path."""

import atexit
import re
import resource
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

import flockkit
from flockkit import io as fio
from flockkit.errors import FileFormatError

from . import assets, untrusted
from .harness import cli_outcome, outcome

LIMIT = 10  # seconds a case may take
MEMORY = 3 * 1024**3  # bytes a case may add to the process's peak


# the cases' files are made once, as the tests are collected, and removed when the run ends
FOLDER = Path(tempfile.mkdtemp(prefix="flockkit-untrusted-"))
atexit.register(shutil.rmtree, FOLDER, ignore_errors=True)
CASES = {name: (call, expected) for _, name, call, expected in untrusted.cases(FOLDER)}


@pytest.fixture(scope="module")
def folder():
    return FOLDER


@pytest.fixture(scope="module")
def cases():
    return CASES


def _peak() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


@pytest.mark.parametrize("name", list(CASES))
def test_a_harmful_file_or_argument_is_named_fast_and_small(name, cases):
    call, expected = cases[name]
    before = _peak()
    kind, what = outcome(call, seconds=LIMIT)
    assert _peak() - before < MEMORY, f"{name}: the peak memory grew by {(_peak() - before) / 2**30:.1f} GiB"
    wanted = ("named", "ok") if expected == "any" else (expected,)
    assert kind in wanted, f"{name}: {kind}: {what}"
    if kind == "named" and name not in ARGUMENTS:  # a file's error names the file
        assert str(FOLDER) in what or "Fox.glb" in what, f"{name}: {what}"


# the cases about arguments rather than files: their errors name the argument
ARGUMENTS = {
    "Stream history 1e9",
    "Crowd of 1e9 agents",
    "UniquePool of 1e9",
    "StreamPool fps 1e-300",
    "mesh fps inf",
    "list_clips of /nonexistent/x.xyz",
}


def test_the_tiny_asset_reads_as_the_spec_says(tmp_path):
    document, buffer = assets.tiny()
    for suffix in (".gltf", ".glb"):
        assets.write(tmp_path / f"tiny{suffix}", document, buffer)
        mesh = fio.read_mesh_animation(tmp_path / f"tiny{suffix}", fps=assets.FPS)
        np.testing.assert_allclose(mesh.motion.positions, assets.EXPECTED, atol=1e-6)
    clip = fio.read_clips(tmp_path / "tiny.glb")["wave"]
    assert clip.skeleton.names == ("Armature", "root", "tip") and clip.fps == 2.0
    np.testing.assert_allclose(clip.translations[:, 1], [[0, 0, 0], [0, 2, 0], [0, 4, 0]])  # STEP keys, held
    np.testing.assert_allclose(clip.rotations[:, 2, 2:], [[0, 1], [np.sqrt(0.5)] * 2, [1, 0]], atol=1e-7)


@pytest.mark.parametrize("uri", untrusted.ESCAPES + ["absolute"])
def test_no_byte_outside_the_asset_folder_reaches_a_mesh(uri, tmp_path):
    path = dict(untrusted.escapes(tmp_path))[uri]
    with pytest.raises(FileFormatError, match=r"buffers\[1\]\.uri"):
        fio.read_mesh_animation(path)
    with pytest.raises(FileFormatError, match=r"buffers\[1\]\.uri"):
        fio.list_clips(path)


def test_the_escape_would_have_read_the_secret_had_it_been_allowed(tmp_path):
    """allow_outside=True lifts the folder rule: the same file then reads the planted secret, so
    the refusals above are what keeps it out."""
    escapes = dict(untrusted.escapes(tmp_path))
    for uri in ("../secret.bin", "absolute", "link.bin"):
        mesh = fio.read_mesh_animation(escapes[uri], allow_outside=True)
        assert 1234.5 in mesh.motion.positions[0]
    with pytest.raises(FileFormatError, match="not a regular file"):
        fio.read_mesh_animation(escapes["zero.bin"], allow_outside=True)


def test_errors_name_the_file_and_the_json_path(cases, folder):
    for name, where in (("view byteStride -4096", r"bufferViews\[0\]\.byteStride"),
                        ("accessor count 1.5", r"accessors\[0\]\.count"),
                        ("channel node -1", r"animations\[0\]\.channels\[0\]\.target\.node"),
                        ("interpolation FOO", r"animations\[0\]\.samplers\[0\]\.interpolation"),
                        ("a cycle of nodes", r"nodes\[\d\]"),
                        ("scene -1", r"scene must index"),
                        ("key times decreasing", r"animations\[0\]\.samplers\[\d\]\.input")):  # fmt: skip
        kind, what = outcome(cases[name][0])
        assert kind == "named" and ".gl" in what, f"{name}: {what}"
        assert re.search(where, what), f"{name}: {what}"


def test_a_stream_restarted_long_after_it_stopped_plays_from_its_start():
    for frames in (5, 40, 100):  # within one prefetch block, and far past it
        pose, start = untrusted.stream_pool_restart_pose(frames)
        np.testing.assert_allclose(pose.rotations, start.rotations, atol=1e-6)


def test_the_cli_says_one_line_for_a_harmful_asset(folder):
    from .untrusted import JSON_DAMAGE, _gltf

    path = _gltf(folder, "negstride-cli", dict(JSON_DAMAGE)["view byteStride -1000000"])
    kind, line = cli_outcome(["segment", str(path), "-o", str(folder / "parts.npz")])
    assert kind == "named" and "byteStride" in line
    fox = Path(__file__).resolve().parents[3] / "shared" / "data" / "fox-gltf" / "Fox.glb"
    kind, line = cli_outcome(["segment", str(fox), "--fps", "1e6", "-o", str(folder / "parts.npz")])
    assert kind == "named" and "memory" in line


def test_a_lowered_memory_budget_refuses_a_small_bomb(tmp_path, monkeypatch):
    bomb = untrusted._npz_bomb(tmp_path, 64 * 1024**2)
    assert bomb.stat().st_size < 1024**2
    monkeypatch.setenv("FLOCKKIT_MEMORY_LIMIT", "16M")
    with pytest.raises(flockkit.errors.ValidationError, match="bomb.npz.*needs 64 MiB of memory; the budget is 16 MiB"):
        flockkit.Motion.load(bomb)
    monkeypatch.setenv("FLOCKKIT_MEMORY_LIMIT", "lots")
    with pytest.raises(flockkit.errors.ValidationError, match="FLOCKKIT_MEMORY_LIMIT"):
        flockkit.Motion.load(bomb)
