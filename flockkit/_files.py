"""Opening files that a user or another file names, safely: regular files only, and paths written
inside a file confined to that file's folder.

Every reader goes through :func:`read_bytes` or :func:`open_regular`: a FIFO, a device, a socket or
a folder is refused before anything reads from it (opening a FIFO for reading would block for
ever, and /dev/zero never ends), and the file's size is checked against the memory budget before
it is read whole. A path written inside a file (a glTF buffer's ``uri``, a USD layer's sublayers
and references) goes through :func:`confined`, which refuses absolute paths, ``..`` segments,
percent-encoded separators and links that lead outside the file's folder, unless the caller
passes ``allow_outside=True``.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from urllib.parse import unquote

from . import validate
from .errors import FileFormatError

# A URI scheme (RFC 3986, 3.1): "http:", "file:"; a Windows drive letter reads as one too.
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
# Percent-encoded characters that would change how a reference splits into folders: '/', '\', NUL.
_ENCODED_SEPARATOR = re.compile(r"%(2f|5c|00)", re.IGNORECASE)


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def open_regular(path, *, follow_links: bool = True) -> int:
    """A file descriptor open for reading on `path`, which must be a regular file.

    The file is opened without blocking (a FIFO would otherwise wait for a writer) and checked
    with fstat on the open descriptor, so a file swapped for another after a check cannot slip
    through. FileNotFoundError if there is nothing at `path`; FileFormatError naming it if it is a
    folder, FIFO, device or socket (or a link, with ``follow_links=False``)."""
    path = Path(path)
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    if not follow_links:
        flags |= os.O_NOFOLLOW
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise FileFormatError(f"{path}: not a regular file (a folder)") from None
    except OSError as exc:
        if not follow_links and path.is_symlink():
            raise FileFormatError(f"{path}: a link, where a regular file was expected") from None
        raise type(exc)(exc.errno, f"{path}: {exc.strerror}") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise FileFormatError(f"{path}: not a regular file ({_kind(mode)})")
    os.set_blocking(fd, True)
    return fd


def read_bytes(path, *, size: int | None = None) -> bytes:
    """The bytes of the regular file at `path` (see :func:`open_regular`): all of them, refused
    beforehand if they exceed the memory budget (``validate.allocation``), or with `size` the
    first `size` bytes (FileFormatError naming the file if it is shorter)."""
    fd = open_regular(path)
    with os.fdopen(fd, "rb") as handle:
        length = os.fstat(handle.fileno()).st_size
        wanted = length if size is None else size
        validate.allocation(wanted, f"{path}: reading {wanted} bytes", itemsize=1)
        data = handle.read(wanted)
    if size is not None and len(data) < size:
        raise FileFormatError(f"{path}: holds {len(data)} bytes, not the {size} it should (truncated?)")
    return data


def read_text(path) -> str:
    """The text of the regular file at `path` (UTF-8, a leading byte-order mark dropped);
    FileFormatError naming the file if it is not UTF-8 text."""
    try:
        return read_bytes(path).decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{Path(path)}: not UTF-8 text (byte {exc.start})") from None


def confined(folder, reference, *, source, where: str, allow_outside: bool = False, uri: bool = True) -> Path:
    """The file that `reference`, a relative URI (or with ``uri=False`` a plain relative path, as
    TOML files hold them) written in the file `source` at `where` (a JSON path such as
    ``buffers[0].uri``), names in `folder`.

    Refused with a FileFormatError naming `source` and `where`: anything but a non-empty string, a
    URI with a scheme (``file:``, ``http:``), an absolute path, a ``..`` segment, a
    percent-encoded separator (``%2F``, ``%5C``, ``%00``), a backslash, and a path whose links
    lead outside `folder`. With ``allow_outside=True``, for pipelines that keep buffers elsewhere,
    absolute paths and ``..`` are taken as they are (schemes are still refused: nothing is
    fetched). The file itself is checked when it is opened (:func:`read_bytes`)."""
    folder = Path(folder)

    def refuse(why: str):
        raise FileFormatError(f"{source}: {where}: {why}; flockkit reads only files inside {folder}")

    if not isinstance(reference, str) or not reference:
        raise FileFormatError(f"{source}: {where} must be a non-empty string; got {reference!r}")
    if uri and _SCHEME.match(reference):
        raise FileFormatError(f"{source}: {where}: {reference[:60]!r} is a URI with a scheme; flockkit reads local "
                              "files only")  # fmt: skip
    if (uri and _ENCODED_SEPARATOR.search(reference)) or "\\" in reference or "\0" in reference:
        refuse(f"{reference[:60]!r} holds an encoded or Windows path separator or a NUL")
    relative = unquote(reference) if uri else reference
    if not allow_outside:
        if relative.startswith("/"):
            refuse(f"{reference[:60]!r} is an absolute path")
        if ".." in relative.split("/"):
            refuse(f"{reference[:60]!r} climbs out of the folder with '..'")
    target = (folder / relative).resolve()
    if not allow_outside and not target.is_relative_to(folder.resolve()):
        refuse(f"{reference[:60]!r} leads outside the folder through a link")
    return target
