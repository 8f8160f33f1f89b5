"""Long-lived threads for the stateless intersections of POST /api/intersect, and for the
stored points of POST /api/projects/{pid}/points (a second pool, ``gsgeo serve
--store-threads``).

Why not FastAPI's thread pool: anyio starts worker threads on demand (up to 40) and ends them
after 10 s idle, and pyproj keeps its PROJ objects (every Transformer, CRS and the operation
candidates gsgeo caches) per thread, so a request landing on a fresh thread rebuilds them:
~25 ms instead of ~3 ms on the 2-core machine. Under intermittent load (operators clicking)
that happened often enough to set the latency tail. A fixed, small pool keeps its threads and
their PROJ objects for the server's lifetime, and with the GIL a few threads are as fast as
many for this CPU-bound work (one more thread than cores would only time-slice). A stored
point also waits for its database (the GIL released), so its pool has a few more threads.
A job runs in a copy of the caller's context (contextvars: the request's user for the audit
trail), as anyio's threads do.
"""

from __future__ import annotations

import asyncio
import contextvars
import functools
import logging
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

T = TypeVar("T")
log = logging.getLogger("gsgeo.server")


class IntersectPool:
    """``threads`` worker threads, started on first use and kept until :meth:`close`
    (after which the next use starts them again: an app may be run more than once)."""

    def __init__(self, threads: int = 1, name: str = "gsgeo-solve"):
        if not 1 <= threads <= 64:
            raise ValueError(f"{name} threads must be between 1 and 64, got {threads}")
        self.threads = threads
        self.name = name
        self._executor: ThreadPoolExecutor | None = None
        self._lock = threading.Lock()

    def _pool(self) -> ThreadPoolExecutor:
        with self._lock:
            if self._executor is None:
                self._executor = ThreadPoolExecutor(max_workers=self.threads,
                                                    thread_name_prefix=self.name)
            return self._executor

    async def run(self, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """``fn(*args, **kwargs)`` on one of the pool's threads; exceptions propagate to the caller."""
        loop = asyncio.get_running_loop()
        job = functools.partial(contextvars.copy_context().run, fn, *args, **kwargs)
        return await loop.run_in_executor(self._pool(), job)

    async def warm_up(self, fn: Callable[[], object]) -> None:
        """Start every thread and run ``fn`` once on each (imports, PROJ objects), so that no
        request pays for it; a failure is logged, never raised (requests report their own)."""
        barrier = threading.Barrier(self.threads, timeout=30)

        def job() -> None:
            try:
                barrier.wait()  # one job per thread: all threads start
            except threading.BrokenBarrierError:
                pass
            fn()

        loop = asyncio.get_running_loop()
        results = await asyncio.gather(
            *(loop.run_in_executor(self._pool(), job) for _ in range(self.threads)),
            return_exceptions=True)
        for r in results:
            if isinstance(r, BaseException):
                log.warning("%s pool warm-up failed: %s", self.name, r)

    def close(self) -> None:
        """Finish the running solves and end the threads."""
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown(wait=True, cancel_futures=True)
