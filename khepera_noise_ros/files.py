"""Writing result files so that a crash or a full disk never leaves a half-written one behind.

Every writer goes through a temporary file beside the target and an
``os.replace``, so the target holds the old content or the new, never part
of one.  A write the disk refuses (full, read-only, not allowed) raises
``WriteError``: an ``OSError`` with a one-line message that names the file,
says why, and says that what was there before is unchanged.
"""
from __future__ import annotations

import contextlib
import errno
import glob
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import IO, Any, Iterator, Mapping, TypeGuard, Union, cast

import numpy as np

StrPath = Union[str, os.PathLike[str]]        # what Path() takes

# the disk refusing, as opposed to a mistake in the path; keyed by OSError.errno (int or None)
REASONS: dict[int | None, str] = {
    errno.ENOSPC: 'no space left on the device', errno.EDQUOT: 'disk quota exceeded',
    errno.EROFS: 'read-only file system', errno.EACCES: 'permission denied',
    errno.EPERM: 'operation not permitted', errno.EIO: 'input/output error',
    errno.EFBIG: 'file too large'}
# errno's names, looked up with OSError.errno as it is (None finds nothing)
_ERRORCODE = cast('Mapping[int | None, str]', errno.errorcode)


class WriteError(OSError):
    """A file the disk would not take; ``str()`` is one line for the user."""

    def __init__(self, path: StrPath, exc: OSError) -> None:
        super().__init__(exc.errno, str(exc))
        self.path = Path(path)
        code = _ERRORCODE.get(exc.errno, '')
        reason = REASONS.get(exc.errno, exc.strerror or str(exc))
        kept = ('its earlier content is unchanged' if self.path.exists()
                else 'nothing was written there')
        self.message = f'cannot write {self.path}: {reason}' + (f' ({code})' if code else '') \
            + f'; {kept}'

    def __str__(self) -> str:
        return self.message


def refused(exc: BaseException) -> TypeGuard[OSError]:
    """Is ``exc`` the disk refusing a write (full, read-only, not allowed)?"""
    return isinstance(exc, OSError) and exc.errno in REASONS


def describe(exc: OSError) -> str:
    """One line for a write the disk refused, a ``WriteError`` or a bare ``OSError``."""
    if isinstance(exc, WriteError):
        return exc.message
    where = f' {exc.filename}' if exc.filename else ''
    return (f'cannot write{where}: {REASONS.get(exc.errno, exc.strerror)} '
            f'({_ERRORCODE.get(exc.errno, exc.errno)}); files finished before are kept')


@contextlib.contextmanager
def atomic_open(path: StrPath, mode: str = 'w', fsync: bool = True,
                **kwargs: Any) -> Iterator[IO[Any]]:
    """``open(path, mode)`` into a temporary file beside ``path``, renamed into place when the
    block ends without error (flushed and, with ``fsync``, synced first); removed otherwise."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}.', suffix='.tmp')
    except OSError as exc:
        raise (WriteError(path, exc) if refused(exc) else exc) from None
    try:
        with os.fdopen(fd, mode, **kwargs) as f:
            yield f
            if fsync:
                f.flush()
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if refused(exc) and not isinstance(exc, WriteError):
            raise WriteError(path, exc) from None
        raise


def remove_leftovers(path: StrPath) -> int:
    """Remove the temporaries ``atomic_open`` left beside ``path`` when its writer was
    killed mid-write (SIGKILL runs no cleanup); only for a path with one writer."""
    path = Path(path)
    removed = 0
    for tmp in path.parent.glob(f'.{glob.escape(path.name)}.*.tmp'):
        tmp.unlink(missing_ok=True)
        removed += 1
    return removed


def atomic_write_text(path: StrPath, text: str) -> Path:
    """Write to a temporary file beside ``path``, then rename it into place."""
    with atomic_open(path) as f:
        f.write(text)
    return Path(path)


def staging_path(path: StrPath) -> Path:
    """A path beside ``path`` (not yet there) to build a directory in before
    ``replace_tree`` puts it in place; removed with its parent by ``replace_tree``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return Path(tempfile.mkdtemp(dir=path.parent, prefix=f'.{path.name}.')) / path.name
    except OSError as exc:
        raise (WriteError(path, exc) if refused(exc) else exc) from None


def replace_tree(staged: StrPath, path: StrPath) -> Path:
    """Put the directory built at ``staged`` (from ``staging_path``) in place of ``path``:
    the old one is moved aside first and removed only once the new one is in."""
    staged, path = Path(staged), Path(path)
    aside = staged.parent / '.old'
    try:
        if path.exists():
            os.replace(path, aside)
        os.replace(staged, path)
    except OSError as exc:
        if aside.exists() and not path.exists():
            os.replace(aside, path)
        raise (WriteError(path, exc) if refused(exc) else exc) from None
    shutil.rmtree(staged.parent, ignore_errors=True)
    return path


def _plain(obj: object) -> object:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f'cannot write {type(obj).__name__} as JSON')


def write_json(path: StrPath, data: object) -> Path:
    return atomic_write_text(path, json.dumps(data, indent=2, default=_plain) + '\n')
