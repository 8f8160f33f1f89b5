"""Persistence of projects, points (rays + measured result), lines, polygons, buildings and
check points.

The storage backend sits behind :class:`~gsgeo.store.base.Store`; the embedded default is
one SQLite file in the data directory, the shared one a PostgreSQL + PostGIS database given by
a ``postgresql://`` URL (:func:`open_store` chooses). Records only: validation and
measuring are gsgeo.service's (which imports this package, never the other way round).
"""

from pathlib import Path

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
from gsgeo.store.sqlite import DB_NAME, SQLiteStore, StoreError
from gsgeo.store.sqlite import open_store as open_sqlite

#: The environment variable naming the store's URL when no --store is given.
STORE_ENV = "GSGEO_STORE"


def open_store(data_dir: str | Path, url: str | None = None) -> Store:
    """The store ``url`` names (``postgresql://USER[:PASSWORD]@HOST:PORT/DATABASE``), or
    without one the SQLite file of the data directory (``DATA/gsgeo.sqlite``).

    Raises StoreError naming the problem: a URL of another kind, a server that cannot be
    reached, a refused login, a database without PostGIS that the role may not enable."""
    if url is None or not url.strip():
        return open_sqlite(data_dir)
    url = url.strip()
    if not url.lower().startswith(("postgresql://", "postgres://")):
        what = f"a {url.split('://', 1)[0]}:// URL is not supported" if "://" in url \
            else f"{url!r} is not a URL"
        raise StoreError(f"{what}; give "
                         "postgresql://USER[:PASSWORD]@HOST:PORT/DATABASE", field="store")
    from gsgeo.store.postgres import PostgresStore  # psycopg is loaded only when used

    return PostgresStore(url)


__all__ = [
    "DB_NAME",
    "STORE_ENV",
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
