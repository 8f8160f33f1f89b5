"""write_measurements: the one entry point of gsgeo.export (format from the file suffix)."""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from gsgeo.errors import InputError
from gsgeo.export.atomic import atomic_path, check_target
from gsgeo.export.tables import collect
from gsgeo.pointschema import provenance as provenance_of

#: Formats and the suffixes that select them.
FORMATS = ("gpkg", "geojson", "geojson-grid", "csv")
SUFFIXES = {".gpkg": "gpkg", ".geojson": "geojson", ".json": "geojson", ".csv": "csv"}


def format_for(path: str | os.PathLike, fmt: str | None = None) -> str:
    """The export format: `fmt` when given, else from the suffix (.gpkg, .geojson/.json, .csv)."""
    if fmt is not None:
        f = str(fmt).lower().lstrip(".")
        if f not in FORMATS:
            raise InputError(f"unknown export format '{fmt}'; choose one of {', '.join(FORMATS)}")
        return f
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(
            f"cannot tell the export format of '{path}' from its suffix '{suffix}'; use .gpkg "
            "(GeoPackage), .geojson (GeoJSON, RFC 7946) or .csv")
    return SUFFIXES[suffix]


def write_measurements(path: str | os.PathLike, measurements: Iterable[Any], *,
                       lines: Iterable[Any] = (), polygons: Iterable[Any] = (),
                       check_points: Iterable[Any] = (), buildings: Iterable[Any] = (),
                       fmt: str | None = None,
                       provenance: Mapping[str, Mapping[str, Any]] | None = None) -> Path:
    """Export measured points, lines, polygons and check points to GeoPackage, GeoJSON or CSV.

    Parameters
    ----------
    path : target file; written atomically (temporary file beside it, then os.replace), so an
        error leaves neither a partial file nor a damaged earlier export.
    measurements : gsgeo.measure.point.Measurement objects or their ``to_dict()`` JSON, all in
        one grid CRS. MeasurementFailure entries are skipped (a line through one is an error).
    lines, polygons : ordered point ids, each as a session Feature (``id``, ``points``), a store
        record (``id``, ``point_ids``), a dict with those keys or a tuple (id, [ids]).
        Polygons close themselves; fewer than 3 distinct points, an unknown point id or a
        self-intersecting ring raises.
    check_points : ground truth in the same grid CRS, each with ``id`` (or ``point_id``) and
        ``easting``/``northing``/``height`` (or ``x``/``y``/``z``); written as a layer
        (GeoPackage) or null-geometry features (GeoJSON); not part of a CSV.
    buildings : built LoD2 models (gsgeo.buildings.model.BuildingModel) in the same grid CRS;
        a GeoPackage layer "buildings" (one row per surface), not part of GeoJSON or CSV.
    fmt : 'gpkg', 'geojson' (RFC 7946), 'geojson-grid' (legacy grid coordinates with a crs
        member, not RFC 7946) or 'csv'; None: from the suffix.
    provenance : point id -> who measured it and how many of its rays were clicked and
        matched automatically (gsgeo.pointschema.provenance), the points' last columns; a
        point it does not name: measured_by unknown, every ray counted as clicked.

    Returns the path written. Raises InputError / GeometryError / CRSError with a message
    naming the problem; nothing is written then.
    """
    kind = format_for(path, fmt)
    target = check_target(path)
    data = collect(measurements, lines=lines, polygons=polygons, check_points=check_points,
                   buildings=buildings, map_layers=kind == "gpkg", provenance=provenance)
    with atomic_path(target) as tmp:
        if kind == "gpkg":
            from gsgeo.export.gpkg import write_gpkg

            write_gpkg(tmp, data)
        elif kind == "csv":
            from gsgeo.export.csvfile import write_csv

            write_csv(tmp, data)
        else:
            from gsgeo.export.geojson import write_geojson

            write_geojson(tmp, data, grid=kind == "geojson-grid")
    return target


def write_session_results(path: str | os.PathLike, results: Iterable[Any], session: Any, *,
                          fmt: str | None = None, buildings: Iterable[Any] = ()) -> Path:
    """`write_measurements` for `gsgeo solve -o`: measure_session results + the session's
    features (and its built buildings)."""
    points = getattr(session, "points", ()) or ()
    return write_measurements(path, results, lines=getattr(session, "lines", ()) or (),
                              polygons=getattr(session, "polygons", ()) or (),
                              buildings=buildings, fmt=fmt,
                              provenance={p.id: provenance_of([r.to_dict() for r in p.rays],
                                                              None) for p in points})
