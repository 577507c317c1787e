"""Writing files so that an interrupted write leaves nothing behind: the one atomic writer.

Every file flockkit writes goes through :func:`atomic_path`: the data goes to a temporary name
beside the target and is renamed over it only when complete. The temporary file is removed on any
failure, and also on SIGTERM: while a write is open in the main thread and SIGTERM has its default
action, a handler turns the signal into ``SystemExit(143)`` so that the cleanup runs (and the
default action is restored afterwards). The result gets the mode an ordinary ``open()`` would give
it, 0666 less the umask.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import tempfile
import threading
from pathlib import Path

TERMINATED = 128 + signal.SIGTERM  # the exit status of a process ended by SIGTERM


def _terminate(signum, frame):
    raise SystemExit(TERMINATED)


@contextlib.contextmanager
def _cleanup_on_sigterm():
    """Within the block, SIGTERM raises SystemExit (so `finally` clauses run) where it would
    otherwise kill the process outright."""
    main = threading.current_thread() is threading.main_thread()
    if not main or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        yield
        return
    signal.signal(signal.SIGTERM, _terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_writable(path) -> Path:
    """`path` if a file can be created there: its folder exists and takes a new file, and it is not
    a folder itself. Raises OSError naming `path` otherwise, before any work is done."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise IsADirectoryError(f"{path}: is a folder; expected a file name")
    if not folder.is_dir():
        raise FileNotFoundError(f"{path}: folder {folder} does not exist")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{path.name}.", dir=folder)
    except OSError as exc:
        raise PermissionError(f"{path}: cannot write in {folder}: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)
    return path


@contextlib.contextmanager
def atomic_path(path, *, create: bool = True):
    """Yield a temporary path beside `path` with the same suffix (writers that pick the format
    from the suffix, like matplotlib and USD, still can); on success it replaces `path`, and on
    failure (or SIGTERM) it is removed. With ``create=False`` the temporary path does not exist
    yet (it lies in a private temporary folder beside `path`), for writers that insist on
    creating the file themselves. OSErrors name `path`, not the temporary name."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    with _cleanup_on_sigterm():
        try:
            if create:
                fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=folder)
                os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes it private; the result is ordinary
                os.close(fd)
                tmp, private = Path(name), None
            else:
                private = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=folder))
                tmp = private / path.name
        except OSError as exc:
            raise type(exc)(exc.errno, f"{path}: cannot write in {folder}: {exc.strerror}") from None
        try:
            yield tmp
            if private is not None:  # the writer made the file: set its mode without following links
                fd = os.open(tmp, os.O_RDONLY | os.O_NOFOLLOW)
                os.fchmod(fd, 0o666 & ~_umask())
                os.close(fd)
            os.replace(tmp, path)
        except OSError as exc:
            if exc.filename is not None and str(exc.filename) != str(path):
                raise type(exc)(exc.errno, f"{path}: {exc.strerror}") from None
            raise
        finally:
            tmp.unlink(missing_ok=True)
            if private is not None:
                shutil.rmtree(private, ignore_errors=True)
