"""Files out: atomic writes, refusing to overwrite an input or an existing output."""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import shutil
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError, printable


def output_directory(path: str | Path) -> Path:
    """Create the output directory ``path`` if it is missing (its parent must exist); an
    OS error (read-only, no permission, a name too long) is one line naming it."""
    path = Path(path)
    try:
        path.mkdir(exist_ok=True)
        if not os.access(path, os.W_OK | os.X_OK):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))
    except FileExistsError:
        raise InputError(f"{printable(path)}: is a file, expected a directory for the outputs") from None
    except OSError as err:
        raise InputError(f"{printable(path)}: cannot write into it ({err.strerror})") from None
    return path


def names_a_directory(text: str) -> bool:
    """An output as typed that can only be a directory: ``out/``, ``out/.``, ``..``
    (pathlib drops the ``/`` and the ``.``, and a file ``out`` would be written)."""
    return str(text).endswith(("/", os.sep)) or os.path.basename(str(text)) in (".", "..")


def refuse_overwriting_input(out: str | Path, inputs) -> None:
    """Refuse an output path that is one of the inputs, even with ``--force``."""
    target = Path(out).resolve()
    for f in inputs:
        if Path(f).resolve() == target:
            raise InputError(f"{out}: is also an input file; write the output somewhere else")


# errors of a write that a user can act on (free space, permissions): not bugs
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM}


def check_output(path: str | Path, *, force: bool) -> None:
    """Refuse, before any work is done, an output that cannot or may not be written."""
    if str(path) == "-":  # an input's '-' is standard input: a file named '-' surprised
        raise InputError("-: an output is written to a file, atomically, not to standard "
                         "output; give a file name (--json prints a document on stdout)")
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory, expected a file name for the output")
    if not force and path.exists():
        raise InputError(f"{path}: already exists; pass --force to overwrite it")
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"{path}: directory {directory} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise InputError(
            f"{path}: cannot write in {directory} (read-only filesystem or no permission)"
        )


def _directory(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _appeared(path: Path) -> InputError:
    return InputError(
        f"{path}: appeared while writing; not replaced (pass --force to overwrite it)"
    )


_RENAME_NOREPLACE = 1
_AT_FDCWD = -100
_renameat2 = None
if sys.platform.startswith("linux"):
    with contextlib.suppress(OSError, AttributeError):
        _libc = ctypes.CDLL(None, use_errno=True)
        _renameat2 = _libc.renameat2
        _renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                               ctypes.c_uint]
        _renameat2.restype = ctypes.c_int

# errnos meaning "this filesystem (or kernel) cannot do that", not "refused"
_UNSUPPORTED = {errno.EINVAL, errno.ENOSYS, errno.EPERM, errno.EXDEV, errno.EMLINK,
                getattr(errno, "ENOTSUP", errno.EOPNOTSUPP), errno.EOPNOTSUPP}


def _rename_noreplace(tmp: str, path: Path) -> bool:
    """``renameat2(RENAME_NOREPLACE)``: True if done, False if not available here."""
    if _renameat2 is None:
        return False
    if _renameat2(_AT_FDCWD, os.fsencode(tmp), _AT_FDCWD, os.fsencode(path),
                  _RENAME_NOREPLACE) == 0:
        return True
    code = ctypes.get_errno()
    if code == errno.EEXIST:
        raise _appeared(path)
    if code in _UNSUPPORTED:
        return False
    raise OSError(code, os.strerror(code), str(path))


def _link_noreplace(tmp: str, path: Path) -> bool:
    """Hard-link ``tmp`` as ``path`` (fails if ``path`` exists), then drop ``tmp``."""
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise _appeared(path) from None
    except OSError as err:
        if err.errno in _UNSUPPORTED:
            return False
        raise
    os.unlink(tmp)
    return True


def _placeholder_noreplace(tmp: str, path: Path) -> None:
    """For filesystems without renameat2 and hard links (FAT, some network shares).

    Claim ``path`` with an exclusive create (O_EXCL is atomic on every local filesystem),
    then rename the finished file over our own empty placeholder.  A file that exists
    before the claim is never replaced, and of two exclusive writers exactly one gets the
    claim.  What this cannot give: for the moment between the claim and the rename an
    empty ``path`` is visible, and a SIGKILL exactly then leaves it behind (empty, never
    partial); a writer that does not create exclusively may write into the placeholder.
    """
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        raise _appeared(path) from None
    claimed = os.fstat(fd)
    os.close(fd)
    try:
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            now = os.stat(path)
            if (now.st_dev, now.st_ino) == (claimed.st_dev, claimed.st_ino):
                os.unlink(path)  # still our empty placeholder
        raise


def place(tmp: str, path: Path, *, force: bool) -> None:
    """The final step of a write: move the finished ``tmp`` to ``path``.

    With ``force``, ``os.replace``.  Without it, a file at ``path`` is never
    replaced, even one created after :func:`check_output` looked: the step is
    ``renameat2(RENAME_NOREPLACE)`` (Linux), else a hard link then unlink, else an
    exclusive placeholder (see :func:`_placeholder_noreplace`).  A file that is
    there is an :class:`InputError` ("appeared while writing; not replaced").
    """
    if force:
        os.replace(tmp, path)
    elif not (_rename_noreplace(tmp, path) or _link_noreplace(tmp, path)):
        _placeholder_noreplace(tmp, path)


def place_directory(tmp: str | Path, path: Path, *, force: bool) -> None:
    """:func:`place` for a finished directory (a Parquet dataset): all its files or none.

    With ``force`` a previous directory at ``path`` is moved aside, replaced, then
    removed; without it an existing ``path`` is never replaced.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"{path}: is a file, expected a directory for the dataset")
    if not force:
        if not _rename_noreplace(str(tmp), path):
            if path.exists():
                raise _appeared(path)
            os.rename(tmp, path)
        return
    old = None
    if path.exists():
        old = Path(tempfile.mkdtemp(prefix=_hidden(path), suffix=".old", dir=_directory(path)))
        os.replace(path, old / path.name)
    try:
        os.replace(tmp, path)
    except BaseException:
        if old is not None:
            os.replace(old / path.name, path)
        raise
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def _hidden(path: Path) -> str:
    """``.NAME.``, NAME cut to leave room for 8 random characters and ``.tmp.old`` in 255 bytes."""
    return "." + os.fsencode(path.name)[:255 - 18].decode(errors="ignore") + "."


def _write_error(path: Path, err: OSError) -> InputError:
    return InputError(f"{path}: cannot write ({err.strerror}); any previous file is unchanged")


class _Pending:
    """One temporary file of an :class:`atomic_files` group, beside its target."""

    def __init__(self, path: Path, mode: str):
        self.path = path
        directory = _directory(path)
        try:
            fd, self.tmp = tempfile.mkstemp(prefix=_hidden(path), suffix=".tmp", dir=directory)
        except OSError as err:
            raise InputError(f"{path}: cannot write in {directory} ({err.strerror})") from None
        try:
            # mkstemp creates the file 0600; give the output the mode a plain open() would
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(self.tmp, 0o666 & ~umask)
            self.fh = os.fdopen(
                fd, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""})
            )
        except BaseException:
            os.close(fd)
            self.discard()
            raise

    def finish(self) -> None:
        self.fh.flush()
        os.fsync(self.fh.fileno())
        self.fh.close()

    def discard(self) -> None:
        with contextlib.suppress(OSError):
            self.fh.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.tmp)


class atomic_files:  # noqa: N801 (used as a context manager, like open)
    """Several outputs that appear together or not at all.

    ``with atomic_files(force=...) as group:`` then ``with group.open(path) as fh`` for
    each output (directories it needs are created, and removed again on failure if they
    were created here).  Nothing is placed until the ``with`` block ends without an error;
    then every file is placed (see :func:`place`).  If one cannot be placed (it appeared
    meanwhile), those placed before it are taken back (with ``force``, the previous files
    are restored) and nothing of the group remains.  An error removes every temporary.
    """

    def __init__(self, *, force: bool):
        self.force = force
        self._pending: list[_Pending] = []
        self._made_dirs: list[Path] = []

    def __enter__(self):
        return self

    def mkdir(self, directory: Path) -> None:
        """Create ``directory`` (and its parents) now; removed on failure if still empty."""
        missing = []
        d = Path(directory)
        while not d.exists():
            missing.append(d)
            if d.parent == d:
                break
            d = d.parent
        for d in reversed(missing):
            try:
                d.mkdir()
            except FileExistsError:
                continue
            except OSError as err:
                raise InputError(f"{directory}: cannot create directory ({err.strerror})") from None
            self._made_dirs.append(d)
        if not Path(directory).is_dir():
            raise InputError(f"{directory}: exists and is not a directory")

    @contextlib.contextmanager
    def open(self, path: str | Path, mode: str = "w") -> Iterator:
        path = Path(path)
        if path.is_dir():
            raise InputError(f"{path}: is a directory, expected a file name for the output")
        self.mkdir(_directory(path))
        pending = _Pending(path, mode)
        self._pending.append(pending)
        yield pending.fh
        pending.finish()

    def __exit__(self, kind, err, tb):
        if kind is None:
            try:
                self._commit()
            except BaseException as exc:
                self._abort()
                if isinstance(exc, OSError) and exc.errno in _WRITE_ERRNOS:
                    raise _write_error(Path(exc.filename or "output"), exc) from None
                raise
            return False
        self._abort()
        if isinstance(err, OSError) and err.errno in _WRITE_ERRNOS:
            name = next((p.path for p in reversed(self._pending)), Path(err.filename or "output"))
            raise _write_error(name, err) from None
        return False

    def _commit(self) -> None:
        placed: list[tuple[_Pending, str | None, bool]] = []
        try:
            for p in self._pending:
                backup, existed = None, p.path.exists()
                if self.force and existed and len(self._pending) > 1:
                    backup = f"{p.tmp}.old"  # to restore it if a later file cannot be placed
                    try:
                        os.link(p.path, backup)
                    except OSError:
                        backup = None
                place(p.tmp, p.path, force=self.force)
                placed.append((p, backup, existed))
        except BaseException:
            for p, backup, existed in reversed(placed):  # take back what this group placed
                with contextlib.suppress(OSError):
                    if backup is not None:
                        os.replace(backup, p.path)
                    elif not existed:
                        os.unlink(p.path)
            raise
        finally:
            for _, backup, _ in placed:
                if backup is not None:
                    with contextlib.suppress(FileNotFoundError):
                        os.unlink(backup)
        self._pending = []
        self._made_dirs = []

    def _abort(self) -> None:
        for p in self._pending:
            p.discard()
        for d in reversed(self._made_dirs):
            with contextlib.suppress(OSError):
                d.rmdir()  # only if still empty


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "w", *, force: bool = True) -> Iterator:
    """Write to a temporary file beside ``path`` and put it in place on success.

    The temporary file is hidden (``.NAME.XXXX.tmp``, NAME cut for a name near 255 bytes)
    in the same directory, so the final step is atomic.  An exception, Ctrl-C or SIGTERM
    leaves any previous file untouched and removes the temporary file; a full disk is an
    :class:`InputError`.  Only SIGKILL (or a power cut) can leave the hidden temporary
    file, never a partial ``path``.  Without ``force``, a file that appears at ``path``
    while writing is not replaced (see :func:`place`).
    """
    path = Path(path)
    check_output(path, force=force)
    directory = _directory(path)
    if not directory.is_dir():
        raise InputError(f"{path}: directory {directory} does not exist")
    with atomic_files(force=force) as group, group.open(path, mode) as fh:
        yield fh
