"""Atomic replacement of a tileset directory: owned temporaries, their clean-up, the swap.

A build writes into a temporary directory beside OUTDIR named
``.NAME.gsgeo-BOOT-NS-PID-START-XXXXXXXX.tmp``: BOOT is the start of the kernel's boot id,
NS the building process's pid namespace, PID the process and START its start time (clock
ticks since boot, /proc/PID/stat), so a later run can tell a temporary whose owner is gone
(killed, machine rebooted) from one still being written, even after the pid was reused.
:func:`clean_stale` removes the former; a temporary of another pid namespace (a container
sharing the folder) cannot be told and is left alone.

:func:`commit` puts the finished directory in place. Where OUTDIR exists, Linux's
``renameat2(RENAME_EXCHANGE)`` swaps the two directories in one step, so OUTDIR exists at
every instant (a reader sees the whole old or the whole new tileset); the old tree, now under
the temporary's name, is removed afterwards. Where the kernel or the filesystem lacks the
exchange (not Linux, Linux < 3.15, some network filesystems) the fallback is two renames:
OUTDIR is moved aside under an owned temporary name, then the new tree is renamed in, so for
that short moment OUTDIR does not exist; a crash between the two leaves the old tree as a
stale temporary, removed by the next run.
"""

from __future__ import annotations

import ctypes
import errno
import os
import re
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

#: renameat2 flag: swap the two paths atomically (linux/fs.h).
RENAME_EXCHANGE = 2
_AT_FDCWD = -100
_OURS = re.compile(r"^\..*\.gsgeo-(?P<boot>[0-9a-f]{8})-(?P<ns>\d+)-(?P<pid>\d+)-(?P<start>\d+)"
                   r"-[^.]+\.tmp$")
#: Longest part of OUTDIR's name put into a temporary's name (file names end at 255 bytes).
_NAME_PART = 64


def _boot_id() -> str:
    try:
        with open("/proc/sys/kernel/random/boot_id") as f:
            return f.read().strip().replace("-", "")[:8].lower()
    except OSError:
        return "00000000"


def _pid_namespace() -> int:
    try:
        return os.stat("/proc/self/ns/pid").st_ino
    except OSError:
        return 0


def _start_ticks(pid: int) -> int | None:
    """Start time of process ``pid`` in clock ticks since boot; None if it does not exist.
    Without /proc (not Linux) 0 for a live process."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            stat = f.read()
    except FileNotFoundError:
        return None
    except OSError:
        return _alive_without_proc(pid)
    # the command name (field 2) is in parentheses and may hold spaces or parentheses
    return int(stat[stat.rindex(b")") + 2:].split()[19])


def _alive_without_proc(pid: int) -> int | None:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return None
    except PermissionError:
        pass
    return 0


def owner_tag() -> str:
    """``BOOT-NS-PID-START`` of this process, as put into its temporaries' names."""
    pid = os.getpid()
    return f"{_boot_id()}-{_pid_namespace()}-{pid}-{_start_ticks(pid) or 0}"


def is_stale(name: str) -> bool:
    """True when ``name`` is one of our temporaries and the process that made it is gone."""
    m = _OURS.match(name)
    if m is None:
        return False
    if m["boot"] != _boot_id():
        return True     # made before the last reboot
    if int(m["ns"]) != _pid_namespace():
        return False    # its pid means another process here: cannot tell
    start = _start_ticks(int(m["pid"]))
    return start is None or (start != 0 and start != int(m["start"]))


def clean_stale(folder: Path) -> list[Path]:
    """Remove our temporaries in ``folder`` whose owning process is gone; returns them.
    Anything else (other tools' files, live builds' temporaries) is left alone."""
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for e in entries:
        if e.is_dir(follow_symlinks=False) and is_stale(e.name):
            shutil.rmtree(e.path, ignore_errors=True)
            removed.append(Path(e.path))
    return removed


def make_temp(outdir: Path) -> Path:
    """A new empty owned temporary directory beside ``outdir`` (its parent must exist)."""
    prefix = f".{outdir.name[:_NAME_PART]}.gsgeo-{owner_tag()}-"
    return Path(tempfile.mkdtemp(prefix=prefix, suffix=".tmp", dir=outdir.parent))


def _renameat2() -> Callable[..., int] | None:
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):   # not glibc >= 2.28 / not Linux
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


def exchange(a: Path, b: Path) -> bool:
    """Swap the paths ``a`` and ``b`` (both must exist) in one atomic step. Returns False,
    changing nothing, where the kernel or the filesystem has no such operation; any other
    failure raises OSError."""
    fn = _renameat2()
    if fn is None:
        return False
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(a))


def commit(tmp: Path, outdir: Path) -> None:
    """Put the finished directory ``tmp`` (made by :func:`make_temp`) at ``outdir``; an
    existing ``outdir`` is replaced (atomically where :func:`exchange` works) and removed."""
    if not os.path.lexists(outdir):
        os.rename(tmp, outdir)
        return
    try:
        os.rename(tmp, outdir)    # atomic over an empty directory
        return
    except OSError as exc:
        if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST):
            raise
    if exchange(tmp, outdir):
        shutil.rmtree(tmp, ignore_errors=True)   # the old tree, now under tmp's name
        return
    old = make_temp(outdir)
    os.rmdir(old)
    os.rename(outdir, old)
    os.rename(tmp, outdir)
    shutil.rmtree(old, ignore_errors=True)
