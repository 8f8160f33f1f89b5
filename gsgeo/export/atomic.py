"""Atomic file replacement: write a temporary file beside the target, then os.replace it.

A failed export leaves neither a partial file nor a damaged earlier export: the target is
only ever replaced by a complete, flushed file (rename within one directory is atomic on
POSIX and on Windows' NTFS).
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path

from gsgeo.errors import InputError

#: Files SQLite (GeoPackage) may leave beside a database.
_SIDECARS = ("-journal", "-wal", "-shm")


def check_target(path: str | os.PathLike) -> Path:
    """The target path, after checking that its directory exists and it is not a directory."""
    target = Path(path).expanduser()
    parent = target.parent if str(target.parent) else Path(".")
    if target.name in ("", ".", ".."):
        raise InputError(f"cannot write '{path}': not a file name")
    if not parent.exists():
        raise InputError(f"cannot write {target}: the directory {parent} does not exist")
    if not parent.is_dir():
        raise InputError(f"cannot write {target}: {parent} is not a directory")
    if target.is_dir():
        raise InputError(f"cannot write {target}: it is a directory")
    return target


def _remove(tmp: Path) -> None:
    for p in (tmp, *(tmp.with_name(tmp.name + s) for s in _SIDECARS)):
        with contextlib.suppress(FileNotFoundError):
            p.unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a fresh temporary path in the target's directory; on success it replaces the target.

    The temporary name ends with the target's suffix (GDAL checks extensions) and does not
    exist yet, so the writer creates it. On any exception the temporary file (and SQLite
    side files) are removed and the target is untouched. OSErrors become InputError naming
    the target.
    """
    target = check_target(path)
    tmp = target.with_name(f".{target.stem}.{secrets.token_hex(6)}.tmp{target.suffix}")
    try:
        try:
            yield tmp
            if not tmp.is_file():
                raise InputError(f"cannot write {target}: the writer produced no file")
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, target)
        except PermissionError:
            raise InputError(f"cannot write {target}: permission denied") from None
        except IsADirectoryError:
            raise InputError(f"cannot write {target}: it is a directory") from None
        except OSError as exc:
            raise InputError(f"cannot write {target}: {exc.strerror or exc}") from None
    except BaseException:
        _remove(tmp)
        raise
    _remove(tmp)  # side files only; tmp itself has been renamed
    with contextlib.suppress(OSError):
        fd = os.open(target.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
