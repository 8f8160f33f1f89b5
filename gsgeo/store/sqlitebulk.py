"""Writing the results of many re-measured points into the SQLite store, overlapped.

A re-measure (a georeference applied or undone, a project's settings changed) rewrites every
point's result: some 4 KB of JSON a point. Written row by row, SQLite's share of it (the
UPDATE, its JSON checks, the pages) runs after each result is made, on the same core. Here
the rows go in chunks, each one statement (``UPDATE ... FROM (VALUES ...)``) run on a writer
thread while the caller's thread makes the next chunk: ``sqlite3_step`` runs without Python's
GIL, so with a second core the writing hides behind the making of the results. The writer
borrows the transaction's connection (the store opens connections with
``check_same_thread=False``); the caller's thread does not touch it until the writer is done.
"""

from __future__ import annotations

import functools
import queue
import sqlite3
import threading
from collections.abc import Callable, Iterable

from gsgeo.jsontypes import JSON
from gsgeo.store.base import result_rows
from gsgeo.store.records import PointRecord

#: Points per statement: small enough that the writer starts early and the last chunk (which
#: nothing overlaps) is short, large enough that a statement's own cost does not count
#: (7 parameters a point, far below SQLite's limit of 32 766).
CHUNK = 200

_END = object()


@functools.lru_cache(maxsize=4)
def update_sql(n: int) -> str:
    """The statement that writes ``n`` rows of ``result_rows`` (result, error, solved_rev,
    frame, updated_at, project_id, id). The VALUES table is materialised and scanned, each
    point found by its primary key (checked by tests/test_store_bulk.py with EXPLAIN QUERY
    PLAN)."""
    values = ",".join(["(?,?,?,?,?,?,?)"] * n)
    return ("UPDATE points SET result = j.column1, error = j.column2, solved_rev = j.column3,"
            " frame = j.column4, updated_at = j.column5, version = version + 1"
            f" FROM (VALUES {values}) AS j"
            " WHERE points.project_id = j.column6 AND points.id = j.column7")


def write_results(con: sqlite3.Connection, points: Iterable[PointRecord], now: str,
                  dumps: Callable[[JSON], str]) -> None:
    """Write the measured state of ``points`` on ``con`` (inside the caller's transaction), as
    ``result_rows`` makes it with ``dumps``: made on this thread, written on a writer thread a
    chunk behind. An error on either side stops both and is raised here (the caller's
    transaction then rolls back)."""
    # room for a block of the caller's (gsgeo.service: 1000 points, 5 chunks) while the
    # next block is measured
    todo: queue.Queue[object] = queue.Queue(maxsize=16)
    failed: list[BaseException] = []

    def writer() -> None:
        while (item := todo.get()) is not _END:
            if failed:
                continue  # drained, so that the maker never blocks
            rows: list[tuple[object, ...]] = item  # type: ignore[assignment]
            try:
                con.execute(update_sql(len(rows)), [v for row in rows for v in row])
            except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
                failed.append(exc)

    thread = threading.Thread(target=writer, name="gsgeo-store-writer", daemon=True)
    thread.start()
    try:
        chunk: list[tuple[object, ...]] = []
        for row in result_rows(points, now, dumps):
            chunk.append(row)
            if len(chunk) == CHUNK:
                if failed:
                    break
                todo.put(chunk)
                chunk = []
        else:
            if chunk:
                todo.put(chunk)
    finally:
        todo.put(_END)
        thread.join()
    if failed:
        raise failed[0]
