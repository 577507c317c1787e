"""What the robustness suite shares: calling something and saying how it went.

Every outcome is one of

- ``ok``: it worked;
- ``named``: it raised a documented flockkit error (``FlockkitError``, or for files that are not
  there ``FileNotFoundError``; for the CLI, one line on stderr and a non-zero exit);
- ``crash``: any other exception (for the CLI: a traceback, several lines, or exit 0 with an
  error);
- ``hang``: it ran past its time limit.

``python -m tests.robustness.tally`` runs every case of the suite with larger budgets and prints
the table per area.
"""

from __future__ import annotations

import contextlib
import io
import signal
import sys

from flockkit.errors import FlockkitError

LIMIT = 30  # seconds a single call may take before it counts as a hang


class _Hang(BaseException):
    pass


def _alarm(signum, frame):
    raise _Hang


@contextlib.contextmanager
def _time_limit(seconds):
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def outcome(call, *, seconds: int = LIMIT) -> tuple[str, str]:
    """(ok | named | crash | hang, what happened) of `call()`."""
    try:
        with _time_limit(seconds):
            call()
    except _Hang:
        return "hang", f"ran past {seconds} s"
    except (FlockkitError, FileNotFoundError) as exc:
        return "named", f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001 - anything else is what we look for
        return "crash", f"{type(exc).__name__}: {exc}"
    return "ok", ""


def cli_outcome(argv, *, seconds: int = LIMIT) -> tuple[str, str]:
    """(ok | named | crash | hang, stderr) of ``flockkit <argv>`` run in this process."""
    from flockkit.cli import main

    out, err = io.StringIO(), io.StringIO()
    try:
        with _time_limit(seconds), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(list(argv))
    except _Hang:
        return "hang", f"ran past {seconds} s"
    except SystemExit as exc:  # argparse: usage errors exit 2 with a usage line and an error line
        code = exc.code
        if code == 2 and "Traceback" not in err.getvalue():
            return "named", err.getvalue().strip().splitlines()[-1]
    except Exception as exc:  # noqa: BLE001
        return "crash", f"{type(exc).__name__}: {exc}"
    text = err.getvalue()
    lines = [line for line in text.splitlines() if line.strip() and ": warning: " not in line]
    if "Traceback" in text:
        return "crash", text[-300:]
    if code == 0:
        return "ok", ""
    if len(lines) == 1 and lines[0].startswith("flockkit ") and code in (1, 3):
        return "named", lines[0]
    return "crash", f"exit {code}: {text[-300:]}"


def say(area: str, results) -> str:
    """A table row: area, tried, named, ok, crash, hang."""
    counts = {kind: sum(1 for k, _ in results if k == kind) for kind in ("named", "ok", "crash", "hang")}
    return f"| {area} | {len(results)} | {counts['named']} | {counts['ok']} | {counts['crash']} | {counts['hang']} |"


if __name__ == "__main__":
    sys.exit("run python -m tests.robustness.tally")
