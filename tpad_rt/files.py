"""The files tpad-rt reads and writes: regular files only, of bounded size.

Every file tpad-rt reads (texture and device YAML, trajectory CSV, images, recordings)
is opened with :func:`open_regular`: ``O_NONBLOCK`` (a FIFO would otherwise block in
``open``), then ``fstat`` on the open descriptor, so what is read is what was checked.
A FIFO, a character or block device, a directory or a socket is refused before a byte
is read, and so is a file larger than the reader's limit. An output path that exists
and is not a regular file (``/dev/zero``, a FIFO, a directory), lies in no folder, or is
a file the command reads, is refused before the work that fills it
(:func:`check_writable_target`); a new path in a folder is fine.

API map
-------
open_regular(path, what, limit_bytes=None, name=None) -> BinaryIO
    the open file; ConfigError when missing, unreadable, not regular or too large
read_regular(path, what, limit_bytes, name=None) -> bytes
    the whole file, at most ``limit_bytes``
ensure_regular(path, what)
    ConfigError unless ``path`` is a readable regular file (for readers that open it themselves)
check_writable_target(path, what, inputs=())
    ConfigError when ``path`` exists and is not a regular file, lies in no folder, or is one of ``inputs``
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Sequence
from typing import BinaryIO

from tpad_rt.errors import ConfigError, printable

PathLike = str | os.PathLike[str]

#: What each non-regular file type is called in messages.
_KINDS = (
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISSOCK, "a socket"),
)


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a file")


def _size(n_bytes: int) -> str:
    """``4 MiB`` for whole MiB, else ``N bytes``."""
    return f"{n_bytes // 2**20} MiB" if n_bytes % 2**20 == 0 else f"{n_bytes:,} bytes"


def _name(path: PathLike, name: str | None) -> str:
    """The file as messages show it: ``name``, else the path, control characters escaped."""
    return printable(str(path) if name is None else name)


def _reason(error: OSError) -> str:
    reason = error.strerror or str(error)
    return reason[:1].lower() + reason[1:]


def _mode(path: PathLike) -> int | None:
    """``st_mode`` of ``path``, or None when it cannot be stat'ed."""
    try:
        return os.stat(path).st_mode
    except OSError:
        return None


def _not_regular(name: str, mode: int, what: str) -> str:
    return f"{name}: not a regular file ({_kind(mode)}); tpad-rt reads {what} from regular files only"


def open_regular(path: PathLike, what: str, limit_bytes: int | None = None, name: str | None = None) -> BinaryIO:
    """``path`` opened for reading in binary, once checked to be a regular file of at most ``limit_bytes``.

    ``what`` names the files the caller reads (``textures``), ``name`` the file in
    messages (default: the path). Raises ConfigError ``name: problem`` when the path
    holds a NUL byte, is missing or unreadable, is not a regular file (a FIFO, a
    device, a directory, a socket), or is larger than ``limit_bytes``.
    """
    name = _name(path, name)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except ValueError:  # an embedded NUL byte
        raise ConfigError(f"{name}: the path contains a NUL byte") from None
    except OSError as error:  # a socket cannot be opened at all: say what it is
        mode = _mode(path)
        if mode is not None and not stat.S_ISREG(mode):
            raise ConfigError(_not_regular(name, mode, what)) from None
        raise ConfigError(f"{name}: cannot read: {_reason(error)}") from None
    try:
        status = os.fstat(fd)
        if not stat.S_ISREG(status.st_mode):
            raise ConfigError(_not_regular(name, status.st_mode, what))
        if limit_bytes is not None and status.st_size > limit_bytes:
            raise ConfigError(f"{name}: file is larger than {_size(limit_bytes)}")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: PathLike, what: str, limit_bytes: int, name: str | None = None) -> bytes:
    """The bytes of the regular file at ``path``, at most ``limit_bytes`` (errors: :func:`open_regular`).

    A file that grows past the limit while being read is refused too.
    """
    with open_regular(path, what, limit_bytes, name) as stream:
        try:
            data = stream.read(limit_bytes + 1)
        except OSError as error:
            raise ConfigError(f"{_name(path, name)}: cannot read: {_reason(error)}") from None
    if len(data) > limit_bytes:
        raise ConfigError(f"{_name(path, name)}: file is larger than {_size(limit_bytes)}")
    return data


def ensure_regular(path: PathLike, what: str) -> None:
    """ConfigError unless ``path`` is a readable regular file (errors: :func:`open_regular`).

    For a reader that opens the path itself; the file could be swapped in between.
    """
    open_regular(path, what).close()


def check_writable_target(path: PathLike, what: str, inputs: Sequence[PathLike] = ()) -> None:
    """ConfigError when ``path`` holds a NUL byte, lies in no folder, exists and is not a regular file, or is
    one of ``inputs`` (the files the command reads: writing there would destroy one).

    ``what`` names what is written there (``recordings``). A missing path in a folder is
    fine (it will be created); a symbolic link is judged by what it points to. Checked
    before the work that makes what is written, so that a long run is not lost at its end.
    """
    name = _name(path, None)
    try:
        mode = os.stat(path).st_mode
    except ValueError:
        raise ConfigError(f"{name}: the path contains a NUL byte") from None
    except OSError:
        folder = os.path.dirname(os.fspath(path)) or "."  # as written: 'missing/../x' needs 'missing'
        if not os.path.isdir(folder):
            raise ConfigError(f"{name}: cannot write {what} there: no folder {printable(folder)}") from None
        if not os.access(folder, os.W_OK | os.X_OK):
            raise ConfigError(f"{name}: cannot write {what} there: the folder {printable(folder)} is not writable")
        return  # missing: opening it for writing says what else goes wrong
    if not stat.S_ISREG(mode):
        raise ConfigError(f"{name}: exists and is not a regular file ({_kind(mode)}); "
                          f"tpad-rt writes {what} to regular files only")
    for source in inputs:
        with contextlib.suppress(OSError, ValueError):
            if os.path.samefile(path, source):
                raise ConfigError(f"{name}: is also a file this command reads ({printable(os.fspath(source))}): "
                                  "write to another file")


__all__ = ["check_writable_target", "ensure_regular", "open_regular", "read_regular"]
