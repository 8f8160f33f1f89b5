"""Projects, points (rays + solved results), lines, polygons and check points.

The storage backend sits behind :class:`~gsgeo.store.base.Store`; the embedded default is
one SQLite file in the data directory (:func:`open_store`). :class:`Projects` is the service
the HTTP API uses: it validates, solves through gsgeo.crs and writes one transaction per call.
"""

from gsgeo.store.base import Store, Transaction
from gsgeo.store.projects import Projects
from gsgeo.store.records import (
    CheckPointRecord,
    ConflictError,
    FeatureRecord,
    NotFoundError,
    PointRecord,
    Project,
)
from gsgeo.store.sqlite import DB_NAME, SQLiteStore, StoreError, open_store

__all__ = [
    "DB_NAME",
    "CheckPointRecord",
    "ConflictError",
    "FeatureRecord",
    "NotFoundError",
    "PointRecord",
    "Project",
    "Projects",
    "SQLiteStore",
    "Store",
    "StoreError",
    "Transaction",
    "open_store",
]
