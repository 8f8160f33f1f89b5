"""A project's points, lines, polygons and check points as a GeoPackage, GeoJSON or CSV file.

Stored results are exported as they are when the project's grid CRS is wanted; another CRS
re-measures every point from its rays (rays are the source of truth). Lines and polygons
whose measures cannot be computed (a failed point, a self-intersecting ring) are left out
and named in the ``skipped`` list rather than failing the whole export.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from gsgeo.errors import GsgeoError, InputError
from gsgeo.export import write_measurements
from gsgeo.jsontypes import JSONObject
from gsgeo.measure import Measurement
from gsgeo.service.measuring import measure, stored_rays
from gsgeo.service.projects import (
    Projects,
    check_points_in_grid,
    feature_measures,
    validate_settings,
)

SUFFIX = {"gpkg": ".gpkg", "geojson": ".geojson", "geojson-grid": ".geojson", "csv": ".csv"}


def export_project(svc: Projects, pid: str, outdir: Path, fmt: str,
                   crs: str | None = None) -> tuple[Path, list[str]]:
    """Write the export into ``outdir``; returns (path, skipped feature descriptions)."""
    if fmt not in SUFFIX:
        raise InputError(f"must be one of {', '.join(SUFFIX)}", field="format")
    project = svc.get_project(pid)
    points = svc.list_points(pid)
    if crs is not None and crs.strip() and crs.strip() != project.crs:
        settings = project.settings() | {"crs": crs.strip()}
        if project.vertical or project.geoid:
            settings |= {"vertical": None, "geoid": None}  # a vertical datum belongs to its grid
        settings = validate_settings(settings, svc.data_dir)
        measurements: list[Measurement | JSONObject] = []
        by_id: dict[str, JSONObject | None] = {}
        for pt in points:
            try:
                m = measure(stored_rays(pt.rays), settings, pt.excluded, svc.data_dir,
                            point_id=pt.id, code=pt.code, description=pt.description)
            except GsgeoError:
                by_id[pt.id] = None
                continue
            measurements.append(m)
            by_id[pt.id] = m.record()
        grid_crs = settings["crs"]
    else:
        if project.crs is None:
            raise InputError(f"project '{pid}' has no grid CRS; give ?crs=EPSG:... to export",
                             field="crs")
        measurements = [pt.result for pt in points if pt.result is not None]
        by_id = {pt.id: pt.record for pt in points}
        grid_crs = project.crs
    if not measurements:
        raise InputError(f"project '{pid}' has no solved points to export")

    proj = replace(project, crs=grid_crs,
                   vertical=project.vertical if grid_crs == project.crs else None)
    kept: dict[str, list[JSONObject]] = {"line": [], "polygon": []}
    skipped: list[str] = []
    for kind in ("line", "polygon"):
        for f, _ in svc.list_features(pid, kind):
            ms = feature_measures(f, by_id, proj)
            if "error" in ms:
                skipped.append(f"{kind} {f.id}: {ms['error']}")
            else:
                kept[kind].append({"id": f.id, "points": f.point_ids})
    cps = svc.list_check_points(pid)
    check = []
    if cps:
        xyz = check_points_in_grid(cps, project, grid_crs, svc.data_dir)
        check = [{"id": c.id, "easting": float(x[0]), "northing": float(x[1]),
                  "height": None if x[2] != x[2] else float(x[2])} for c, x in zip(cps, xyz,
                                                                                  strict=True)]
    path = outdir / f"{pid}{SUFFIX[fmt]}"
    write_measurements(path, measurements, lines=kept["line"], polygons=kept["polygon"],
                       check_points=check, fmt=fmt)
    return path, skipped
