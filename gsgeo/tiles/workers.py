"""Worker processes for `gsgeo tiles`: forked after the job's state is set up, so they share
it (copy-on-write) without pickling; results land in shared memory.

numpy releases the GIL only inside its loops; a block of splats needs dozens of short
numpy calls, so threads leave much of the second core idle. Forked processes do not.
Where fork is unavailable, or one worker is asked for, tasks run in the calling process.
"""

from __future__ import annotations

import ctypes
import mmap
import multiprocessing
import os
import signal
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import numpy.typing as npt


def shared_empty(shape: tuple[int, ...] | int, dtype: npt.DTypeLike) -> np.ndarray:
    """An uninitialised array in anonymous shared memory: writes by forked workers are seen
    by the parent (and the pages are returned to the system when the array is freed)."""
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    dtype = np.dtype(dtype)
    nbytes = max(1, int(np.prod(shape, dtype=np.int64)) * dtype.itemsize)
    buf = mmap.mmap(-1, nbytes, flags=mmap.MAP_SHARED | mmap.MAP_ANONYMOUS)
    return np.frombuffer(buf, dtype, count=int(np.prod(shape, dtype=np.int64))).reshape(shape)


def can_fork() -> bool:
    return "fork" in multiprocessing.get_all_start_methods()


#: prctl option: the signal a process gets when its parent dies (linux/prctl.h).
PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int) -> None:
    """Have the kernel SIGKILL this process as soon as its parent ``parent`` dies (Linux), so a
    killed build leaves no workers behind writing into its temporary directory or printing
    tracebacks about the parent's pipes. Elsewhere a no-op."""
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        return
    prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong,
                      ctypes.c_ulong]
    prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent:    # the parent died before the request took effect
        os._exit(1)


def _quiet_child(parent: int) -> None:
    die_with_parent(parent)
    # Ctrl-C reaches the whole process group: the parent handles it and stops the pool
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    keep_freed_memory()


def keep_freed_memory() -> None:
    """Let glibc's malloc reuse freed blocks instead of returning them to the kernel.

    A worker allocates and frees the same few megabyte-sized numpy temporaries for every
    block; by default glibc maps such sizes fresh (or trims them off the heap) each time, and
    the page faults of touching them again cost more system time than the arithmetic.
    Workers are short-lived, so keeping the memory is harmless; the `gsgeo tiles` command
    does the same in its own process (a batch job too), not build_tileset."""
    try:
        libc = ctypes.CDLL(None)
        m_trim_threshold, m_mmap_threshold = -1, -3
        libc.mallopt(m_mmap_threshold, 32 * 2**20)    # glibc's maximum on 64-bit
        libc.mallopt(m_trim_threshold, 1 << 30)
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        pass


class WorkerFailed(Exception):
    """A non-Exception (e.g. KeyboardInterrupt, SystemExit) escaped a task in a worker."""


def _guarded(fn_and_task: tuple[Callable[[Any], Any], Any]) -> Any:
    fn, task = fn_and_task
    try:
        return fn(task)
    except Exception:
        raise
    except BaseException as exc:   # would kill the worker and hang the pool
        raise WorkerFailed(f"{type(exc).__name__} in a worker: {exc}") from None


class Imap:
    """``imap(fn, tasks)``: results in completion order; ``close()`` says no more tasks will
    come, so the workers exit (and the kernel frees their memory) while the caller goes on."""

    def __init__(self, p: multiprocessing.pool.Pool | None = None) -> None:
        self._pool = p

    def __call__(self, fn: Callable, tasks: Iterable) -> Iterator:
        if self._pool is None:
            return (fn(t) for t in tasks)
        return self._pool.imap_unordered(_guarded, ((fn, t) for t in tasks))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()


@contextmanager
def pool(processes: int) -> Iterator[Imap]:
    """Yield an :class:`Imap` over ``processes`` forked workers (in this process when
    ``processes`` <= 1). ``fn`` must be a module-level function; the state it reads must be
    set before entering (workers fork here). Leaving the block waits for the workers."""
    if processes <= 1 or not can_fork():
        yield Imap()
        return
    ctx = multiprocessing.get_context("fork")
    p = ctx.Pool(processes, initializer=_quiet_child, initargs=(os.getpid(),))
    try:
        yield Imap(p)
        p.close()
        p.join()
    finally:
        p.terminate()


def cpu_count() -> int:
    """CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1
