"""The one on-disk container of flockkit: an .npz of plain arrays plus a JSON metadata entry.

Plain arrays only: object arrays are refused on write and `allow_pickle=False` on read. Writes go to a
temporary file in the target folder and are renamed over the target, so an interrupted write never
leaves a half-written file.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ._atomic import atomic_path
from .errors import FileFormatError

METADATA_KEY = "__metadata__"


def write(path, *, kind: str, version: int, arrays: dict[str, np.ndarray], metadata: dict) -> Path:
    """Write `arrays` and `metadata` (plus kind and version) atomically to `path`."""
    path = Path(path)
    header = {"format": kind, "version": version, **metadata}
    payload = {name: np.asarray(array) for name, array in arrays.items()}
    for name, array in payload.items():
        if array.dtype == object:
            raise TypeError(f"refusing to write object array {name!r}: flockkit files hold plain numeric arrays only")
    payload[METADATA_KEY] = np.frombuffer(json.dumps(header).encode("utf-8"), dtype=np.uint8)
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        np.savez_compressed(handle, **payload)
    return path


def read(path, *, kind: str, versions: tuple[int, ...]) -> tuple[dict[str, np.ndarray], dict]:
    """Read a file written by :func:`write`, checking its kind and version.

    Raises FileNotFoundError for a missing file and FileFormatError, naming the file, for anything
    that is not a complete flockkit file of this `kind` and a supported version.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        with open(path, "rb") as handle:
            npz = np.load(handle, allow_pickle=False)
            if not isinstance(npz, np.lib.npyio.NpzFile):
                raise ValueError("a single .npy array, not an .npz archive")
            with npz:
                arrays = {name: npz[name] for name in npz.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError) as exc:
        raise FileFormatError(f"{path}: not a readable flockkit {kind} file (.npz): {exc}") from None
    raw = arrays.pop(METADATA_KEY, None)
    if raw is None:
        raise FileFormatError(f"{path}: no flockkit metadata; expected a {kind} file written by flockkit")
    try:
        header = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FileFormatError(f"{path}: corrupt metadata: {exc}") from None
    if not isinstance(header, dict) or header.get("format") != kind:
        found = header.get("format") if isinstance(header, dict) else None
        raise FileFormatError(f"{path}: holds a flockkit {found!r} file; expected a {kind!r} file")
    if header.get("version") not in versions:
        raise FileFormatError(
            f"{path}: {kind} format version {header.get('version')!r} is not supported; "
            f"this flockkit reads versions {', '.join(map(str, versions))}"
        )
    return arrays, header
