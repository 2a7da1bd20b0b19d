"""The files tpad-rt reads and writes: regular files only, of bounded size.

Every file tpad-rt reads (texture and device YAML, trajectory CSV, images, recordings)
is opened with :func:`open_regular`: ``O_NONBLOCK`` (a FIFO would otherwise block in
``open``), then ``fstat`` on the open descriptor, so what is read is what was checked.
A FIFO, a character or block device, a directory or a socket is refused before a byte
is read, and so is a file larger than the reader's limit. An output path that exists
and is not a regular file (``/dev/zero``, a FIFO, a directory), lies in no folder or in
one that cannot be written, or is a file the command reads, is refused before the work
that fills it (:func:`check_writable_target`); a new path in a folder is fine.

Every file tpad-rt writes at a path the user names (device files, recordings, WAV files,
figures, schemas, sweeps) is written through :class:`NewFile`: a temporary file created
exclusively beside the target (``tempfile.mkstemp``: ``O_CREAT | O_EXCL | O_NOFOLLOW``,
a random name), so a link planted at any name in the folder is never followed, then
flushed, fsync'ed and renamed onto the target with ``os.replace`` only once complete. A
failure or an interruption removes the temporary file and leaves whatever was at the
target as it was (a process killed outright leaves its hidden temporary file, mode
0600, and the target intact); no reader ever sees part of a file. A symbolic link at the target
(to a regular file: one to anything else is refused) is replaced itself by the new
file; the file it pointed to is never written.

API map
-------
open_regular(path, what, limit_bytes=None, name=None) -> BinaryIO
    the open file; ConfigError when missing, unreadable, not regular or too large
read_regular(path, what, limit_bytes, name=None) -> bytes
    the whole file, at most ``limit_bytes``
ensure_regular(path, what)
    ConfigError unless ``path`` is a readable regular file (for readers that open it themselves)
check_writable_target(path, what, inputs=())
    ConfigError when ``path`` exists and is not a regular file, lies in no folder or an unwritable one, or is
    one of ``inputs``
NewFile(path, what) -> NewFile
    a temporary file beside ``path`` (``.file``) that ``commit()`` moves there, ``discard()`` removes;
    as a context manager, committed when the block ends, discarded when it raises
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from collections.abc import Sequence
from types import TracebackType
from typing import BinaryIO

from tpad_rt.errors import BackendError, ConfigError, printable

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
    """ConfigError when ``path`` holds a NUL byte, lies in no folder, exists and is not a regular file, lies in a
    folder that cannot be written, or is one of ``inputs`` (the files the command reads: writing there would
    destroy one).

    ``what`` names what is written there (``recordings``). A missing path in a folder is
    fine (it will be created); a symbolic link is judged by what it points to (one to a
    regular file is then replaced by :class:`NewFile`, not written through). The folder
    must be writable even when the file exists: NewFile creates its new version beside it.
    Checked before the work that makes what is written, so that a long run is not lost
    at its end. A name too long for the file system, or behind a folder that cannot be
    searched, is refused here too.
    """
    name = _name(path, None)
    folder = os.path.dirname(os.fspath(path)) or "."  # as written: 'missing/../x' needs 'missing'
    try:
        mode: int | None = os.stat(path).st_mode
    except ValueError:
        raise ConfigError(f"{name}: the path contains a NUL byte") from None
    except OSError as error:
        if error.errno in (errno.ENAMETOOLONG, errno.EACCES):  # too long; a folder on the way not searchable
            raise ConfigError(f"{name}: cannot write {what} there: {_reason(error)}") from None
        mode = None  # missing: creating it says what else goes wrong
    if mode is None and not os.path.isdir(folder):
        raise ConfigError(f"{name}: cannot write {what} there: no folder {printable(folder)}")
    if mode is not None and not stat.S_ISREG(mode):
        raise ConfigError(f"{name}: exists and is not a regular file ({_kind(mode)}); "
                          f"tpad-rt writes {what} to regular files only")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError(f"{name}: cannot write {what} there: the folder {printable(folder)} is not writable")
    for source in inputs:
        with contextlib.suppress(OSError, ValueError):
            if os.path.samefile(path, source):
                raise ConfigError(f"{name}: is also a file this command reads ({printable(os.fspath(source))}): "
                                  "write to another file")


#: Characters of the target's name kept in its temporary file's name (``.NAME.XXXXXXXX.tmp``): a name near
#: the file system's limit (255 bytes) must still leave room for the rest.
_TEMPORARY_NAME_CHARS = 64


class NewFile:
    """The file at ``path``, written in a temporary file beside it and moved there only once complete.

    ``what`` names what is written (``device files``, ``recordings``) in messages. The
    temporary file (``.file``, binary, read-write, at ``.temporary``) is created
    exclusively in the target's folder with a random name, so no link planted there is
    followed. :meth:`commit` flushes and fsyncs it, gives it the permissions a plain
    ``open(path, "w")`` would (those of the regular file it replaces, else 0o666 less the
    umask; its owner is the writer), and renames it onto ``path``; :meth:`discard`
    removes it. As a context manager (``with NewFile(...) as new: new.file.write(...)``)
    it commits when the block ends and discards when the block raises.

    Raises ConfigError, creating nothing, when ``path`` is refused by
    :func:`check_writable_target` or the temporary file cannot be created in its folder
    (read-only, full). Writing or committing that fails (a full disk, a file-size limit)
    raises BackendError from :meth:`failed` or :meth:`commit`, with the temporary file
    removed and ``path`` as it was; an OSError raised in the ``with`` block becomes that
    BackendError.
    """

    def __init__(self, path: PathLike, what: str) -> None:
        check_writable_target(path, what)
        self.path = os.fspath(path)
        self.what = what
        self.name = _name(path, None)
        self._folder = os.path.dirname(self.path) or "."
        prefix = f".{os.path.basename(self.path)[:_TEMPORARY_NAME_CHARS]}."
        try:
            handle, self.temporary = tempfile.mkstemp(suffix=".tmp", prefix=prefix, dir=self._folder)
        except OSError as error:
            shown = f"the folder {printable(self._folder)} is not writable ({_reason(error)})" \
                if error.errno in (errno.EACCES, errno.EPERM, errno.EROFS) else _reason(error)
            raise ConfigError(f"{self.name}: cannot write {what} there: {shown}") from None
        self.file: BinaryIO = os.fdopen(handle, "w+b")
        self.committed = False
        self._discarded = False

    @property
    def closed(self) -> bool:
        """True once committed or discarded."""
        return self.file.closed

    def commit(self) -> None:
        """Flush, fsync and set the permissions of the temporary file, and rename it onto ``path``; BackendError
        (the temporary file removed, ``path`` as it was) when that fails. Nothing once committed or discarded."""
        if self.closed:
            return
        try:
            self.file.flush()
            with contextlib.suppress(OSError):  # a file system without Unix permissions (FAT) may refuse it
                os.fchmod(self.file.fileno(), self._mode())
            os.fsync(self.file.fileno())
            self.file.close()
            os.replace(self.temporary, self.path)
        except OSError as error:
            raise self.failed(error) from None
        self.committed = True
        with contextlib.suppress(OSError):  # the rename itself made durable, where the folder can be opened
            folder = os.open(self._folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
            try:
                os.fsync(folder)
            finally:
                os.close(folder)

    def discard(self) -> None:
        """Close and remove the temporary file, leaving ``path`` as it was. Nothing once committed or discarded
        (the name, free again, may be another's by then)."""
        if self.committed or self._discarded:
            return
        self._discarded = True
        with contextlib.suppress(OSError):
            self.file.close()
        with contextlib.suppress(OSError):
            os.unlink(self.temporary)

    def failed(self, error: OSError) -> BackendError:
        """The error to raise for ``error``, met while writing: ``NAME: cannot write WHAT there: REASON``. The
        temporary file is discarded."""
        self.discard()
        return BackendError(f"{self.name}: cannot write {self.what} there: {_reason(error)}")

    def _mode(self) -> int:
        """The permission bits of the regular file at ``path``, else 0o666 less the umask."""
        with contextlib.suppress(OSError):
            status = os.lstat(self.path)
            if stat.S_ISREG(status.st_mode):
                return stat.S_IMODE(status.st_mode) & 0o777
        return 0o666 & ~_umask()

    def __enter__(self) -> NewFile:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if error is None:
            self.commit()
        elif isinstance(error, OSError):
            raise self.failed(error) from None
        else:
            self.discard()


def _umask() -> int:
    """The process's umask, read without changing it (from /proc where it shows; else set and restored)."""
    with contextlib.suppress(OSError, ValueError, IndexError), open("/proc/self/status", encoding="ascii") as status:
        for line in status:
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


__all__ = ["NewFile", "check_writable_target", "ensure_regular", "open_regular", "read_regular"]
