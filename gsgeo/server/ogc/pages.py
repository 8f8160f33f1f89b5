"""The next page of items, made while the client reads the current one.

A client pages through a collection one request after the other (GDAL parses a page of
10 000 features, about 0.5 s, before it asks for the next), so the server would idle while
the client works and the client while the server works. After answering a page with a
``next`` link, the server makes that next page in a background thread and keeps it, labelled
with the store's revision taken before reading. The request for it takes it only if the store's
revision is still the same, so a change committed meanwhile (a point stored through the API)
is always in the answer: a page made before it is thrown away and made again.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Generic, TypeVar

log = logging.getLogger("gsgeo.server")

T = TypeVar("T")

#: Pages kept at most (a page of 10 000 points is about 13 MB).
KEPT = 4
#: How long a request waits for its page being made ahead (s) before making it itself.
WAIT = 30.0


class PageCache(Generic[T]):
    """Pages made ahead, by key, each valid for one store revision; one background thread."""

    def __init__(self, revision: Callable[[], int | None], kept: int = KEPT) -> None:
        self._revision = revision
        self._kept = kept
        self._lock = threading.Lock()
        self._pages: OrderedDict[Hashable, tuple[int, T]] = OrderedDict()
        self._pending: dict[Hashable, Future[None]] = {}
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ogc-next-page")

    def take(self, key: Hashable) -> T | None:
        """The page made ahead for ``key`` if the store has not changed since (removed from
        the cache either way)."""
        with self._lock:
            pending = self._pending.get(key)
        if pending is not None:  # being made: wait for it rather than make it twice
            try:
                pending.result(timeout=WAIT)
            except FutureTimeout:
                return None
        with self._lock:
            got = self._pages.pop(key, None)
        if got is None:
            return None
        rev, page = got
        now = self._revision()
        return page if now is not None and now == rev else None

    def make_ahead(self, key: Hashable, make: Callable[[], T]) -> None:
        """Make the page of ``key`` in the background (once at a time per key)."""

        def job() -> None:
            try:
                rev = self._revision()  # before reading: a later change makes it stale
                if rev is None:
                    return
                page = make()
                with self._lock:
                    self._pages[key] = (rev, page)
                    while len(self._pages) > self._kept:
                        self._pages.popitem(last=False)
            except Exception:  # the client's own request for it will answer the error
                log.debug("making a page ahead failed", exc_info=True)
            finally:
                with self._lock:
                    self._pending.pop(key, None)

        with self._lock:  # the job's own bookkeeping waits for this block
            if key not in self._pending and key not in self._pages:
                self._pending[key] = self._pool.submit(job)

    def close(self) -> None:
        """Stop the background thread (pages being made are finished and dropped)."""
        self._pool.shutdown(wait=False, cancel_futures=True)
