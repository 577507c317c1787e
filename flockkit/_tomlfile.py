"""TOML input files (scenarios, scenes): read whole, errors naming the file."""

from __future__ import annotations

import tomllib
from pathlib import Path

from .errors import FileFormatError


def read(path, what: str) -> dict:
    """The tables of the TOML file at `path`; FileNotFoundError when there is none,
    FileFormatError ("not a TOML <what>") when it does not parse."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{path}: not a TOML {what}: {exc}") from None
