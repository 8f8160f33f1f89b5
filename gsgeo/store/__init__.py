"""Persistence of projects, points (rays + measured result), lines, polygons, buildings and
check points.

The storage backend sits behind :class:`~gsgeo.store.base.Store`; the embedded default is
one SQLite file in the data directory (:func:`open_store`). Records only: validation and
measuring are gsgeo.service's (which imports this package, never the other way round).
"""

from gsgeo.store.base import Store, Transaction
from gsgeo.store.records import (
    BuildingRecord,
    CheckPointRecord,
    ConflictError,
    FeatureRecord,
    NotFoundError,
    PointRecord,
    PreconditionFailed,
    Project,
)
from gsgeo.store.sqlite import DB_NAME, SQLiteStore, StoreError, open_store

__all__ = [
    "DB_NAME",
    "BuildingRecord",
    "CheckPointRecord",
    "ConflictError",
    "FeatureRecord",
    "NotFoundError",
    "PointRecord",
    "PreconditionFailed",
    "Project",
    "SQLiteStore",
    "Store",
    "StoreError",
    "Transaction",
    "open_store",
]
