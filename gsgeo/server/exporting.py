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
from gsgeo.store import Projects
from gsgeo.store.measuring import measure, session_point
from gsgeo.store.projects import check_points_in_grid, feature_measures, validate_settings

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
        measurements, by_id = [], {}
        for pt in points:
            try:
                m = measure(session_point(pt.id, pt.rays, pt.code, pt.description), settings,
                            pt.excluded, svc.data_dir)
            except GsgeoError:
                continue
            measurements.append(m)
            by_id[pt.id] = m.record()
        grid_crs = settings["crs"]
    else:
        if project.crs is None:
            raise InputError(f"project '{pid}' has no grid CRS; give ?crs=EPSG:... to export",
                             field="crs")
        measurements = [pt.result for pt in points if pt.result is not None]
        by_id = {pt.id: pt.record for pt in points if pt.record is not None}
        grid_crs = project.crs
    if not measurements:
        raise InputError(f"project '{pid}' has no solved points to export")

    proj = replace(project, crs=grid_crs,
                   vertical=project.vertical if grid_crs == project.crs else None)
    recs = {pt.id: replace(pt, record=by_id.get(pt.id)) for pt in points}
    kept: dict[str, list] = {"line": [], "polygon": []}
    skipped: list[str] = []
    for kind in ("line", "polygon"):
        for f, _ in svc.list_features(pid, kind):
            ms = feature_measures(f, recs, proj)
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
