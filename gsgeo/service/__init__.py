"""gsgeo.service: projects as the HTTP API and the commands use them, over gsgeo.store.

- ``projects``: :class:`Projects`, one transaction per call (projects, points, lines,
  polygons, check points, accuracy);
- ``measuring``: a stored point's rays with a project's settings through gsgeo.measure;
- ``buildings``: LoD2 buildings of a project (the methods Projects inherits), built from the
  points' current results when read; the same for a session's buildings;
- ``exporting``: a project as a GeoPackage, GeoJSON or CSV file, its buildings as CityJSON;
- ``checkpoints``: check-point files (CSV, GeoJSON, GeoPackage) read into rows;
- ``validate``: ids and settings checks shared with the HTTP layer.

The store behind it keeps records only (gsgeo.store); :func:`open_projects` opens both.
"""

from __future__ import annotations

from pathlib import Path

from gsgeo.service.points import PointInput
from gsgeo.service.projects import Projects
from gsgeo.store import (
    DB_NAME,
    CheckPointRecord,
    ConflictError,
    FeatureRecord,
    NotFoundError,
    PointRecord,
    PreconditionFailed,
    Project,
    Store,
    StoreError,
    open_store,
)


def open_projects(data_dir: str | Path, store: Store | None = None,
                  url: str | None = None) -> Projects:
    """The project service over ``store``, else the store ``url`` names (a PostgreSQL
    database: gsgeo.store.open_store), else the data directory's SQLite store. The surfaces
    of buildings a store keeps for GIS are caught up (those stored by an older gsgeo)."""
    svc = Projects(store if store is not None else open_store(data_dir, url), data_dir)
    svc.keep_missing_surfaces()
    return svc


__all__ = [
    "DB_NAME",
    "CheckPointRecord",
    "ConflictError",
    "FeatureRecord",
    "NotFoundError",
    "PointInput",
    "PointRecord",
    "PreconditionFailed",
    "Project",
    "Projects",
    "Store",
    "StoreError",
    "open_projects",
    "open_store",
]
