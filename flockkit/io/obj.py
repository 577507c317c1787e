"""OBJ sequences: one Wavefront .obj file per frame, the same faces in every one (what Blender,
Houdini and Maya write for an animated mesh they cannot describe otherwise).

A folder's .obj files, or a glob's matches, are the frames in natural order (frame2 before
frame10); each must be a regular file, and a link in a folder must stay inside it.
"""

from __future__ import annotations

import glob as globbing
import re
from pathlib import Path

import numpy as np

from .. import _files, validate
from ..errors import FileFormatError

__all__ = ["read_sequence"]

# An OBJ file says nothing of its axes or unit: y up is the convention of the tools that write
# sequences (Blender's and Maya's exporters by default); the unit is the caller's to state.
UP_AXIS = "y"


def _natural(path: str):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", Path(path).name)]


def _frames(pattern: str) -> list[str]:
    """The frames of an OBJ sequence in natural order: a folder's .obj files, a glob's matches,
    or one file. Each must be a regular file, and a link in a folder must stay inside it."""
    path = Path(pattern)
    if path.is_dir():
        files = [str(f) for f in path.iterdir() if f.suffix.lower() == ".obj"]
    elif path.exists():
        files = [pattern]
    else:
        files = globbing.glob(pattern)
    if not files:
        raise FileNotFoundError(f"{pattern}: no .obj files")
    for file in files:
        folder = Path(file).parent.resolve()
        if not Path(file).resolve().is_relative_to(folder):
            raise FileFormatError(f"{file}: a link that leads outside {folder}; an OBJ sequence stays in its folder")
    return sorted(files, key=_natural)


def read_sequence(pattern: str) -> tuple[np.ndarray, np.ndarray, str]:
    """(positions (T, V, 3), faces (F, 3 or 4), the first frame's name) of the OBJ sequence
    `pattern`: a folder, a glob, or one file (a path that exists is never read as a glob)."""
    files = _frames(pattern)
    frames, faces, known = [], None, None
    for file in files:
        points, polygons, known = _read_obj(file, known)
        if faces is None:
            faces, first = polygons, file
            validate.allocation(len(files) * points.size, f"{pattern}: {len(files)} frames of {len(points)} vertices")
        elif len(points) != len(frames[0]) or not np.array_equal(polygons, faces):
            raise FileFormatError(
                f"{file}: its topology differs from {first} ({len(points)} vertices and {len(polygons)} faces, against "
                f"{len(frames[0])} and {len(faces)}); an OBJ sequence keeps one topology"
            )
        frames.append(points)
    return np.stack(frames), faces, Path(files[0]).stem


_MAX_VERTEX = 2**40  # far above any file's vertex count, far below numpy's int64


_VERTEX_LINE = re.compile(r"^[ \t]*v[ \t]+([^\r\n]*)", re.MULTILINE)
_FACE_LINE = re.compile(r"^[ \t]*f[ \t]+([^\r\n]*)", re.MULTILINE)


def _read_obj(file, known=None) -> tuple[np.ndarray, np.ndarray, tuple]:
    """The vertices (V, 3) and faces (F, 3 or 4) of one OBJ file, and what a later frame of the
    sequence may reuse: the text of its face lines and its faces.

    Where the face lines are the same text as `known`'s (an earlier frame's) and use no relative
    indices, the faces are those, and the vertices are parsed by numpy at once (every vertex line
    then needs the same number of coordinates); anything else, or anything numpy refuses, goes
    through the line-by-line parser, whose errors name the line."""
    text = _files.read_text(file)
    face_text = "\n".join(_FACE_LINE.findall(text))
    if known is not None and face_text == known[0] and "-" not in face_text:
        points = _vertices(text)
        if points is not None:
            return points, known[1], known
    points, faces = _parse_obj(file, text)
    return points, faces, (face_text, faces)


def _vertices(text: str) -> np.ndarray | None:
    """The (V, 3) finite vertices of an OBJ text parsed at once, or None where it cannot be."""
    import warnings

    lines = _VERTEX_LINE.findall(text)
    if not lines:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # an empty or odd line: the careful parser says which
            points = np.loadtxt(lines, dtype=float, ndmin=2, usecols=(0, 1, 2), comments=None)
    except (ValueError, IndexError, Warning):
        return None
    return points if points.shape == (len(lines), 3) and np.all(np.isfinite(points)) else None


def _parse_obj(file, text: str) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (V, 3) and faces (F, 3 or 4) of one OBJ file's text: ``v x y z`` lines (a
    fourth coordinate or vertex colours after them are ignored) and ``f`` lines of 1-based or
    negative (relative) indices; other lines are ignored."""
    points, polygons = [], []
    for number_, line in enumerate(text.splitlines(), 1):
        fields = line.split()
        if not fields or fields[0] not in ("v", "f"):
            continue
        try:
            if fields[0] == "v":
                if len(fields) < 4:
                    raise ValueError
                points.append([float(v) for v in fields[1:4]])
                continue
            corners = [int(f.split("/")[0]) for f in fields[1:]]
            if len(corners) < 3 or 0 in corners:
                raise ValueError
        except ValueError:
            raise FileFormatError(
                f"{file}, line {number_}: not an OBJ vertex (v x y z) or face (f and 3 or more vertex numbers from 1, "
                f"or negative ones): {line.strip()[:80]!r}"
            ) from None
        corners = [c - 1 if c > 0 else len(points) + c for c in corners]  # 1-based, or relative
        if min(corners) < 0 or max(corners) > _MAX_VERTEX:
            raise FileFormatError(f"{file}, line {number_}: a face refers to a vertex that no OBJ file can hold")
        if len(corners) in (3, 4):
            polygons.append(corners)
        else:
            polygons += [[corners[0], corners[i], corners[i + 1]] for i in range(1, len(corners) - 1)]
    if not points:
        raise FileFormatError(f"{file}: no vertices (not an OBJ file?)")
    points = np.array(points, dtype=float)
    if not np.all(np.isfinite(points)):
        raise FileFormatError(f"{file}: vertices must have finite coordinates")
    triangles = [p for p in polygons if len(p) == 3]
    quads = [p for p in polygons if len(p) == 4]
    if triangles and quads:  # one face width per mesh: split the quads
        triangles += [q[:3] for q in quads] + [[q[0], q[2], q[3]] for q in quads]
        quads = []
    faces = np.array(quads or triangles or np.zeros((0, 3)), dtype=np.int64).reshape(-1, 4 if quads else 3)
    if len(faces) and faces.max() >= len(points):
        raise FileFormatError(f"{file}: a face refers to vertex {faces.max() + 1}; the file has {len(points)}")
    return points, faces
