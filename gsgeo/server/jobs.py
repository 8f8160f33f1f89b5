"""Bounded pools for the server's heavy jobs (image matching, survey reports).

A heavy job (decoding two views and matching them; laying out a report) costs tens to
hundreds of megabytes and seconds of CPU. Run on FastAPI's thread pool, as many run at once
as requests arrive (up to 40), and a burst of them takes the server's memory and its cores
from every other request. A :class:`JobPool` runs at most ``threads`` jobs at once on its own
long-lived threads; up to ``queue`` more wait their turn (holding no thread, only their
request), and any beyond are refused at once with :class:`Busy` (HTTP 503 with Retry-After),
before any of their work is done.
"""

from __future__ import annotations

import asyncio
import contextvars
import ctypes
import ctypes.util
import functools
import gc
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

T = TypeVar("T")


class Busy(Exception):
    """Every slot and queue place of a pool is taken; try again after ``retry_after`` s."""

    def __init__(self, what: str, retry_after: int):
        super().__init__(f"the server is busy with other {what}; try again in "
                         f"{retry_after} s")
        self.retry_after = retry_after


class JobPool:
    """``threads`` worker threads (started on first use, kept until :meth:`close`) and at most
    ``queue`` jobs waiting for them; ``what`` names the jobs in a Busy message (plural) and
    ``retry_after`` (seconds) is what a refused request is told to wait."""

    def __init__(self, what: str, threads: int, queue: int, retry_after: int = 2):
        if not 1 <= threads <= 64 or not 0 <= queue <= 10_000:
            raise ValueError(f"{what}: threads must be 1..64 and queue 0..10000, got "
                             f"{threads} and {queue}")
        self.what = what
        self.threads = threads
        self.queue = queue
        self.retry_after = retry_after
        self._executor: ThreadPoolExecutor | None = None
        self._lock = threading.Lock()
        self._pending = 0  # jobs submitted and not finished (running or waiting)

    @property
    def pending(self) -> int:
        """Jobs running or waiting now."""
        return self._pending

    def _admit(self) -> ThreadPoolExecutor:
        with self._lock:
            if self._pending >= self.threads + self.queue:
                raise Busy(self.what, self.retry_after)
            if self._executor is None:
                self._executor = ThreadPoolExecutor(self.threads,
                                                    thread_name_prefix=f"gsgeo-{self.what}")
            self._pending += 1
            return self._executor

    def _done(self, *_: object) -> None:
        with self._lock:
            self._pending -= 1

    async def run(self, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """``fn(*args, **kwargs)`` on one of the pool's threads, in a copy of the caller's
        context (the request's user); Busy when the pool and its queue are full. A request
        that goes away leaves its job to finish (it still counts until then)."""
        executor = self._admit()
        job = functools.partial(contextvars.copy_context().run, fn, *args, **kwargs)
        try:
            future = executor.submit(job)
        except BaseException:
            self._done()
            raise
        future.add_done_callback(self._done)
        return await asyncio.wrap_future(future)

    def close(self) -> None:
        """Finish the running jobs, drop the waiting ones and end the threads."""
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown(wait=True, cancel_futures=True)


def release_memory() -> None:
    """Give the memory a finished heavy job freed back to the system: a full garbage
    collection, then glibc's ``malloc_trim`` (freed memory otherwise stays in the process's
    heap arenas: a report of 5 000 points left gigabytes resident). A no-op elsewhere."""
    gc.collect()
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim: Callable[[int], int] = libc.malloc_trim
    except (OSError, AttributeError):
        return None
    return trim
