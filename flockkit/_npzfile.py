"""The one on-disk container of flockkit: an .npz of plain arrays plus a JSON metadata entry.

Plain arrays only: object arrays are refused on write and `allow_pickle=False` on read. Writes go to a
temporary file in the target folder and are renamed over the target, so an interrupted write never
leaves a half-written file.
"""

from __future__ import annotations

import json
import math
import os
import warnings
import zipfile
from pathlib import Path

import numpy as np

from . import _files, validate
from ._atomic import atomic_path
from .errors import FileFormatError, ValidationError

METADATA_KEY = "__metadata__"
_NUMERIC = "biuf"  # flags, integers, floats: never Python objects, strings, records or complex numbers


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
    that is not a complete flockkit file of this `kind` and a supported version: a folder or device,
    a corrupt or truncated archive, an array whose header claims more data than the archive holds
    (refused before anything is allocated), or metadata that is not a JSON object.
    """
    path = _existing_file(path)
    try:
        arrays = _arrays(path)
    except (FileFormatError, ValidationError):  # damaged, or larger than the memory budget
        raise
    except Exception as exc:  # noqa: BLE001 - zlib, zipfile, numpy header parsing: all mean a bad file
        raise FileFormatError(
            f"{path}: not a readable flockkit {kind} file (.npz): {type(exc).__name__}: {exc}"
        ) from None
    raw = arrays.pop(METADATA_KEY, None)
    if raw is None:
        raise FileFormatError(f"{path}: no flockkit metadata; expected a {kind} file written by flockkit")
    try:
        header = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise FileFormatError(f"{path}: corrupt metadata: {type(exc).__name__}: {exc}") from None
    if not isinstance(header, dict) or header.get("format") != kind:
        found = header.get("format") if isinstance(header, dict) else None
        raise FileFormatError(f"{path}: holds a flockkit {found!r} file; expected a {kind!r} file")
    if header.get("version") not in versions:
        raise FileFormatError(
            f"{path}: {kind} format version {header.get('version')!r} is not supported; "
            f"this flockkit reads versions {', '.join(map(str, versions))}"
        )
    return arrays, header


def _existing_file(path) -> Path:
    path = Path(path)
    os.close(_files.open_regular(path))
    return path


def kind_of(path) -> str:
    """The kind of flockkit file at `path` ("motion", "graph", ...), from its metadata alone;
    FileNotFoundError or FileFormatError, naming the file, as for :func:`read`."""
    path = _existing_file(path)
    try:
        with zipfile.ZipFile(path) as archive, archive.open(METADATA_KEY + ".npy") as handle:
            from numpy.lib import format as npy

            raw = npy.read_array(handle, allow_pickle=False)
        header = json.loads(raw.tobytes().decode("utf-8"))
        return str(header["format"])
    except Exception as exc:  # noqa: BLE001 - whatever went wrong, it is not a flockkit file
        raise FileFormatError(f"{path}: not a flockkit file (.npz with flockkit metadata): {exc}") from None


def _arrays(path: Path) -> dict[str, np.ndarray]:
    """The arrays of an .npz, each header checked against the size its archive entry declares
    before the array is read (a corrupt header cannot make us allocate what is not there)."""
    arrays = {}
    with zipfile.ZipFile(path) as archive:
        entries = archive.infolist()
        # the sizes the zip headers declare, before anything is inflated: a few megabytes of zeros
        # may declare gigabytes, and would inflate to them
        validate.allocation(sum(info.file_size for info in entries), f"{path}: the arrays it holds", itemsize=1)
        for info in entries:
            if not info.filename.endswith(".npy"):
                raise FileFormatError(f"{path}: unexpected entry {info.filename!r} in the archive")
            with archive.open(info) as handle:
                array = read_array(handle, info.file_size, source=f"{path}: array {info.filename!r}")
            arrays[info.filename.removesuffix(".npy")] = array
    return arrays


def read_array(handle, size: int, *, source: str) -> np.ndarray:
    """The .npy array in the `size` bytes `handle` reads: its header is parsed and checked (numbers
    and flags only; a shape whose data fills exactly the bytes that follow) before its data is
    read. FileFormatError naming `source` otherwise."""
    from numpy.lib import format as npy

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a damaged header's text may warn as numpy parses it
            version = npy.read_magic(handle)
            read_header = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
            shape, fortran, dtype = read_header(handle)
    except (ValueError, EOFError, SyntaxError, TypeError) as exc:
        raise FileFormatError(f"{source}: not a .npy array: {type(exc).__name__}: {exc}") from None
    if dtype.kind not in _NUMERIC or dtype.hasobject:
        raise FileFormatError(f"{source} holds {dtype}; flockkit reads numbers and flags only")
    needed = math.prod(shape) * dtype.itemsize
    if needed != size - handle.tell():
        raise FileFormatError(f"{source} claims shape {shape} ({needed} bytes) but holds {size - handle.tell()} bytes")
    data = handle.read(needed)
    if len(data) != needed:
        raise FileFormatError(f"{source} ends after {len(data)} of its {needed} bytes (truncated?)")
    return np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C").copy()
