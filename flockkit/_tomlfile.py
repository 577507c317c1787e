"""TOML input files (scenarios, scenes): read whole, errors naming the file."""

from __future__ import annotations

import tomllib
from pathlib import Path

from . import _files
from .errors import FileFormatError


def read(path, what: str) -> dict:
    """The tables of the TOML file at `path`; FileNotFoundError when there is none,
    FileFormatError ("not a TOML <what>") when it is not a regular file or does not parse."""
    path = Path(path)
    try:
        return tomllib.loads(_files.read_text(path))
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise FileFormatError(f"{path}: not a TOML {what}: {type(exc).__name__}: {exc}") from None
