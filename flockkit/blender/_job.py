"""One run of the flockkit worker (``python -m flockkit.cli.blender JOB.json``) in its own
process: the job written, progress read from its output by a thread that touches no Blender data,
the result read back. Operators poll a Job from Blender's main thread (a modal timer) or wait."""

import json
import os
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path

import numpy as np

WORKER = "flockkit.cli.blender"


class WorkerError(RuntimeError):
    """The worker could not start, or it stopped with an error (its message)."""


def find_python(preference: str = "") -> str:
    """The Python where flockkit is installed: the add-on's preference if set, else the
    FLOCKKIT_PYTHON environment variable, else the interpreter of the ``flockkit`` command on the
    PATH (the first line of that script)."""
    for candidate in (preference, os.environ.get("FLOCKKIT_PYTHON", "")):
        if candidate:
            if not Path(candidate).is_file():
                raise WorkerError(f"flockkit's Python {candidate!r} does not exist")
            return candidate
    command = shutil.which("flockkit")
    if command:
        first = Path(command).read_bytes()[:512].split(b"\n", 1)[0]
        if first.startswith(b"#!"):
            python = first[2:].decode(errors="replace").strip().split()[0]
            if Path(python).is_file():
                return python
    raise WorkerError(
        "no flockkit found: install flockkit (pip install flockkit) and set its Python in the add-on's "
        "preferences (Edit > Preferences > Add-ons > flockkit), or set FLOCKKIT_PYTHON"
    )


class Job:
    """A worker process running `task` with the job's `fields`; `arrays` (name -> array) travel
    in an .npz beside the job. `progress` (0..1) and `stage` follow its PROGRESS lines."""

    def __init__(self, python: str, task: str, fields: dict, arrays: dict | None = None, folder=None):
        self.folder = Path(folder or tempfile.mkdtemp(prefix="flockkit-blender-"))
        self.folder.mkdir(parents=True, exist_ok=True)
        job = dict(fields, task=task, output=str(self.folder / f"{task}-result"))
        if arrays:
            np.savez(self.folder / f"{task}-input.npz", **arrays)
        path = self.folder / f"{task}.json"
        path.write_text(json.dumps(job, default=float))
        self.progress, self.stage, self.error, self.lines = 0.0, task, None, []
        self._output = Path(job["output"])
        environment = {k: v for k, v in os.environ.items() if k not in ("PYTHONHOME", "PYTHONPATH")}
        try:
            self.process = subprocess.Popen(
                [python, "-m", WORKER, str(path)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                env=environment, cwd=self.folder,
            )  # fmt: skip
        except OSError as exc:
            raise WorkerError(f"cannot run flockkit's Python {python!r}: {exc}") from None
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.process.stdout:
            line = line.rstrip("\n")
            self.lines.append(line)
            if line.startswith("PROGRESS "):
                done, total, *stage = line.split(" ", 3)[1:]
                self.progress = int(done) / max(int(total), 1)
                self.stage = stage[0] if stage else self.stage
            elif line.startswith("ERROR "):
                self.error = line[6:]

    def poll(self) -> bool:
        """Whether the worker has finished (successfully or not)."""
        return self.process.poll() is not None and not self._reader.is_alive()

    def wait(self):
        """Wait for the worker; its result, or WorkerError."""
        self.process.wait()
        self._reader.join()
        return self.result()

    def cancel(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            self.process.wait()

    def result(self):
        """(arrays, fields) the worker wrote; WorkerError with its message if it failed."""
        if self.process.returncode != 0 or self.error:
            tail = " ".join(self.lines[-5:]) if not self.error else self.error
            raise WorkerError(self.error or f"flockkit's worker stopped (status {self.process.returncode}): {tail}")
        with np.load(self._output.with_suffix(".npz"), allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
        return arrays, json.loads(self._output.with_suffix(".json").read_text())


def run(python: str, task: str, fields: dict, arrays=None, folder=None):
    """Run a job to its end: (arrays, fields)."""
    return Job(python, task, fields, arrays, folder).wait()
