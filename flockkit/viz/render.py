"""Pictures rendered by Blender: a flock, a scene or a crowd as an animator sees it, its agents
as meshes (cones, animated meshes, skinned characters) on a ground, under a sun, seen by a camera
that frames the action.

flockkit never imports ``bpy``: :func:`render_blender` runs the script ``_in_blender.py`` in a
Python that has it (``pip install bpy``, which pins its own numpy), on a file flockkit exported
(USD or glTF), exactly as Blender would import it for a user.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from .._atomic import atomic_path
from ..errors import FlockkitError, MissingDependencyError, ValidationError
from ..validate import integer, number
from ._figures import gif_durations, pair, picture_path, shared_palette

# The environment variable naming a Python with Blender's bpy module (the tests' too).
BPY_PYTHON = "FLOCKKIT_BPY_PYTHON"

# Files Blender imports, and the render engines by the names flockkit takes.
SOURCE_SUFFIXES = (".usda", ".usdc", ".usd", ".glb", ".gltf")
ENGINES = {"cycles": "CYCLES", "workbench": "BLENDER_WORKBENCH", "eevee": "BLENDER_EEVEE"}

# An animation's frames per second where none is asked: smooth enough for a flock seen from afar,
# and half the renders of 24.
RENDER_FPS = 12.0

# What flockkit's meshes are painted (RGB, linear): a fox's orange, which reads on the green ground.
COLOUR = (0.8, 0.3, 0.06)


def blender_python(python=None) -> str:
    """The Python that renders: `python`, else the one ``FLOCKKIT_BPY_PYTHON`` names, else this
    one where it has bpy. MissingDependencyError where there is none."""
    python = python or os.environ.get(BPY_PYTHON)
    if python:
        if shutil.which(python) is None:
            raise MissingDependencyError(f"rendering with Blender: {python} (from {BPY_PYTHON} or python=) is not an "
                                         "executable Python")  # fmt: skip
        return python
    if importlib.util.find_spec("bpy") is not None:
        return sys.executable
    raise MissingDependencyError(
        f"rendering with Blender needs Blender's bpy module: set {BPY_PYTHON} to a Python where `pip install bpy` "
        "ran (it pins its own numpy, so give it its own virtual environment)"
    )


def render_blender(source, path, *, time=None, fps=None, size=(640, 360), engine=None, samples=8,
                   colour=COLOUR, python=None) -> Path:  # fmt: skip
    """Render `source` in Blender to `path`: a still (.png) at `time` seconds (default the middle
    of its animation), or an animation (.gif) over `time` = (start, end) seconds (default all of
    it) at `fps` frames a second (default RENDER_FPS), whose frames last exactly their time.

    `source` is a flockkit.Motion (exported to USD first; needs usd-core) or a file flockkit
    exported: a flock's, a scene's (``SceneAnimation.export``) or a crowd's
    (``flockkit.crowd.export_usd``) USD stage, or a glTF file. Blender imports it unchanged;
    every mesh is painted `colour` (linear RGB), a ground is laid under the action, a sun lights
    it and a camera looking down from the south-west fits the box the action fills (over the
    frames rendered, so that an animation's camera holds still). `engine` "cycles" (on the CPU,
    `samples` a pixel, denoised; the default for a still), "workbench" (flat shading with
    shadows: on a CPU's software OpenGL about 0.3 s a frame of a few meshes at 320 x 180, over
    a second for a hundred skinned characters; the default for an animation) or "eevee" (a
    minute to compile its shaders without a GPU); `size` (width, height) in pixels; `python` the
    Python with bpy (default :func:`blender_python`'s). Written atomically; returns the path."""
    path = picture_path(path, (".png", ".gif"), "Blender render")
    moving = path.suffix.lower() == ".gif"
    width, height = (integer(v, "render_blender: size", minimum=16) for v in pair(size))
    engine = engine or ("workbench" if moving else "cycles")
    if engine not in ENGINES:
        raise ValidationError(f"render_blender: engine must be one of {', '.join(ENGINES)}; got {engine!r}")
    samples = integer(samples, "render_blender: samples", minimum=1)
    colour = [number(c, "render_blender: colour", minimum=0) for c in colour]
    if len(colour) != 3:
        raise ValidationError(f"render_blender: colour must be (red, green, blue); got {len(colour)} values")
    python = blender_python(python)
    with tempfile.TemporaryDirectory(prefix="flockkit-render-") as work:
        work = Path(work)
        source = _importable(source, work)
        duration = _duration(source)
        times = _times(time, fps, duration, moving)
        outputs = [str(work / f"frame{k:05d}.png") for k in range(len(times))]
        job = {"file": str(source.resolve()), "times": times.tolist(), "duration": duration, "outputs": outputs,
               "width": width, "height": height, "engine": ENGINES[engine], "samples": samples,
               "colour": colour}  # fmt: skip
        (work / "job.json").write_text(json.dumps(job))
        script = Path(__file__).with_name("_in_blender.py")
        done = subprocess.run([python, str(script), str(work / "job.json")], capture_output=True, text=True)
        if done.returncode != 0 or not all(Path(o).is_file() for o in outputs):
            tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-12:]) or "no output"
            raise FlockkitError(f"Blender ({python}) did not render {source.name} (exit status {done.returncode}): "
                                f"{tail}")  # fmt: skip
        with atomic_path(path) as tmp:
            if moving:
                _gif([Path(o) for o in outputs], tmp, fps or RENDER_FPS)
            else:
                shutil.copyfile(outputs[0], tmp)
    return path


def _importable(source, work: Path) -> Path:
    """`source` as a file Blender imports: a Motion exported to USD in `work`, or the file."""
    from ..motion import Motion

    if isinstance(source, Motion):
        from ..io import export

        export(source, work / "motion.usdc")
        return work / "motion.usdc"
    source = Path(source)
    if source.suffix.lower() not in SOURCE_SUFFIXES:
        raise ValidationError(f"render_blender: {source} is not a file Blender imports here; expected a "
                              f"flockkit.Motion or one of {', '.join(SOURCE_SUFFIXES)}")  # fmt: skip
    if not source.is_file():
        raise ValidationError(f"render_blender: {source} is not a file")
    return source


def _duration(source: Path) -> float:
    """Seconds the file's animation lasts (its longest clip)."""
    from ..io import list_clips

    return max(list_clips(source, allow_outside=True).values(), default=0.0)


def _times(time, fps, duration: float, moving: bool) -> np.ndarray:
    """The times (seconds) rendered: one for a still, every 1 / fps over the span asked for an
    animation."""
    if not moving:
        when = duration / 2 if time is None else number(time, "render_blender: time", minimum=0)
        return np.array([min(when, duration)])
    start, end = (0.0, duration) if time is None else (number(t, "render_blender: time", minimum=0) for t in time)
    if not start < end <= duration + 1e-9:
        raise ValidationError(f"render_blender: time must be (start, end) with start < end <= {duration:g} s, the "
                              f"animation's length; got {time}")  # fmt: skip
    rate = number(fps or RENDER_FPS, "render_blender: fps", minimum=0, strict=True)
    return start + np.arange(int(np.floor((end - start) * rate + 1e-9)) + 1) / rate


def _gif(frames: list[Path], path: Path, rate: float) -> None:
    """The rendered `frames` as one GIF at `rate` frames a second, on one shared palette."""
    from PIL import Image

    images = [Image.open(frame).convert("RGB") for frame in frames]
    picks = np.unique(np.linspace(0, len(images) - 1, 9).round().astype(int))
    palette = shared_palette([images[k] for k in picks])
    quantized = [image.quantize(palette=palette, dither=Image.Dither.FLOYDSTEINBERG) for image in images]
    quantized[0].save(path, format="GIF", save_all=True, append_images=quantized[1:],
                      duration=gif_durations(len(quantized), rate), loop=0)  # fmt: skip
