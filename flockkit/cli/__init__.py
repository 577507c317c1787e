"""The ``flockkit`` command: a thin layer over the public API.

Every error becomes one line on stderr and a non-zero exit, never a traceback: 1 for errors, 2 for
usage, 3 when ``solve`` wrote a motion that does not meet its constraints, 70 for an error
flockkit did not foresee (a bug: ``FLOCKKIT_TRACEBACK=1`` shows it), 130 on Ctrl-C and 143 on
SIGTERM (temporary files removed, worker processes stopped). Output paths are checked before any
work. Warnings raised along the way are printed after the result, one line each, never before an
error line.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import warnings

import flockkit

from .._atomic import TERMINATED
from ..errors import FlockkitError
from . import blender, crowds, demo, flocks, graphs, plugins, scenes, solve
from .solve import Unmet

__all__ = ["main", "build_parser"]


# the commands, in the order `flockkit --help` lists them: command -> (help, arguments, run)
ORDER = (
    "plugins",
    "simulate",
    "build",
    "segment",
    "walk",
    "info",
    "solve",
    "demo",
    "render",
    "export",
    "scene",
    "crowd",
    "import",
    "check",
    "new-plugin",
    "blender-addon",
)
GROUPS = (flocks, graphs, scenes, crowds, solve, plugins, demo, blender)
COMMANDS = {name: group.COMMANDS[name] for name in ORDER for group in GROUPS if name in group.COMMANDS}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="flockkit", description="Animate flocks, schools, herds and small crowds.")
    parser.add_argument("--version", action="version", version=f"flockkit {flockkit.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (help, arguments, run) in COMMANDS.items():
        command = commands.add_parser(name, help=help)
        arguments(command)
        command.set_defaults(run=run)
    return parser


class _Terminated(BaseException):
    """SIGTERM, raised where the command is so that every cleanup runs."""


_TERMINATION = []  # set when SIGTERM arrives: a library's cleanup may replace our exception with its own


def _terminate(signum, frame):
    _TERMINATION.append(signum)
    raise _Terminated


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    previous = signal.signal(signal.SIGTERM, _terminate)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = _run(args)
        finally:
            _stop_workers()
            signal.signal(signal.SIGTERM, previous)
    if code == 0:
        for message in dict.fromkeys(_line(w.message) for w in caught):
            print(f"flockkit {args.command}: warning: {message}", file=sys.stderr)
    return code


def _run(args) -> int:
    """Run the command; every exception becomes one line on stderr and an exit status."""
    _TERMINATION.clear()
    try:
        return args.run(args)
    except SystemExit:
        raise
    except BaseException as exc:  # noqa: BLE001 - each becomes its line and status below
        if _TERMINATION or isinstance(exc, _Terminated):
            print(f"flockkit {args.command}: terminated", file=sys.stderr)
            return TERMINATED
        if isinstance(exc, KeyboardInterrupt):
            print(f"flockkit {args.command}: interrupted", file=sys.stderr)
            return 130
        if isinstance(exc, Unmet):
            return _fail(args, exc, 3)
        if isinstance(exc, FlockkitError | OSError | AssertionError | MemoryError):
            return _fail(args, exc, 1)
        if os.environ.get("FLOCKKIT_TRACEBACK") == "1" or not isinstance(exc, Exception):
            raise
        return _fail(args, exc, 70, prefix="internal error (please report; FLOCKKIT_TRACEBACK=1 shows where): ")


def _fail(args, exc: BaseException, code: int, prefix: str = "") -> int:
    kind = "" if isinstance(exc, FlockkitError | OSError | AssertionError) else f"{type(exc).__name__}: "
    print(f"flockkit {args.command}: error: {prefix}{kind}{_line(exc)}", file=sys.stderr)
    return code


def _line(message) -> str:
    return " ".join(line.strip() for line in str(message).splitlines() if line.strip())


def _stop_workers() -> None:
    """Stop the worker processes a command started (joblib's loky workers idle for minutes
    otherwise), however far their pool got: a SIGTERM may catch it half made."""
    import multiprocessing

    children = multiprocessing.active_children()
    for child in children:
        with contextlib.suppress(Exception):  # best effort: the command's result stands
            child.terminate()
    for child in children:
        with contextlib.suppress(Exception):
            child.join(timeout=10)
