"""Files in and out: atomic writes, refusing to overwrite, digests, natural order."""

from __future__ import annotations

import contextlib
import errno
import os
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError


@contextlib.contextmanager
def reading(path: str | Path, what: str = "a CSV file") -> Iterator[None]:
    """Turn the OS errors of opening and reading ``path`` into one-line InputErrors."""
    try:
        yield
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, expected {what}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None
    except OSError as err:
        raise InputError(f"{path}: cannot read ({err.strerror})") from None


def natural_key(name: str) -> list:
    """Sort ``rep2`` before ``rep10``."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]



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
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory, expected a file name for the output")
    if not force and path.exists():
        raise InputError(f"{path}: already exists; pass --force to overwrite it")
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"{path}: directory {directory} does not exist")


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "w", *, force: bool = True) -> Iterator:
    """Write to a temporary file beside ``path`` and rename it into place on success.

    The temporary file is hidden (``.NAME.XXXX.tmp``) in the same directory, so the
    rename is atomic.  An exception, Ctrl-C or SIGTERM leaves any previous file
    untouched and removes the temporary file; a full disk is reported as an
    :class:`InputError`.  Only SIGKILL (or a power cut) can leave the hidden
    temporary file behind, never a partial ``path``.
    """
    path = Path(path)
    check_output(path, force=force)
    directory = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    except OSError as err:
        raise InputError(f"{path}: cannot write in {directory} ({err.strerror})") from None
    try:
        # mkstemp creates the file 0600; give the output the mode a plain open() would
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""})) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(err, OSError) and err.errno in _WRITE_ERRNOS:
            raise InputError(
                f"{path}: cannot write ({err.strerror}); any previous file is unchanged"
            ) from None
        raise
