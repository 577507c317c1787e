"""The documented exception types of flockkit.

Every error flockkit raises on purpose derives from :class:`FlockkitError`. The specific types
also derive from the built-in exception they refine, so callers may catch either::

    try:
        flockkit.get("behavior", "no-such-model")
    except KeyError:  # or flockkit.errors.UnknownPluginError, or FlockkitError
        ...

Messages name the field, file or plugin at fault and say what was expected.
"""

from __future__ import annotations

__all__ = [
    "FlockkitError",
    "ValidationError",
    "UnknownPluginError",
    "PluginError",
    "FileFormatError",
    "MissingDependencyError",
    "FlockkitWarning",
]


class FlockkitError(Exception):
    """Base class of every error flockkit raises on purpose."""


class ValidationError(FlockkitError, ValueError):
    """A value, argument or parameter is out of its documented range (shape, finiteness, sign)."""


class UnknownPluginError(FlockkitError, KeyError):
    """No plugin component of that kind and name is installed (or the kind itself is unknown)."""

    def __str__(self) -> str:
        # KeyError would print the repr of its argument, quotes and escaped newlines included.
        return str(self.args[0]) if self.args else ""


class PluginError(FlockkitError):
    """A plugin breaks the rules of registration: it fails to import, misspells a hook, reuses a
    name, or offers a component without the methods and signatures its interface requires."""


class FileFormatError(FlockkitError, ValueError):
    """A file is corrupt, truncated, of another kind or of an unsupported format version.

    A file that does not exist raises the built-in ``FileNotFoundError`` instead."""


class MissingDependencyError(FlockkitError, ImportError):
    """An optional dependency is not installed; the message names the extra that provides it."""


class FlockkitWarning(UserWarning):
    """Something works, but probably not as meant: no plugin component found at all, for one."""
