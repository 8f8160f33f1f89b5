"""A project's points, lines, polygons, buildings and check points as a GeoPackage, GeoJSON or
CSV file, or its buildings as CityJSON 2.0.

Stored results are exported as they are when the project's grid CRS is wanted; another CRS
re-measures every point from its rays (rays are the source of truth). Lines and polygons
whose measures cannot be computed (a failed point, a self-intersecting ring) are left out
and named in the ``skipped`` list rather than failing the whole export; so are buildings that
cannot be built (gsgeo.service.buildings), which the GeoPackage holds as a layer of surfaces.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from gsgeo.buildings.model import BuildingModel
from gsgeo.buildings.spec import parse_building
from gsgeo.errors import GsgeoError, InputError
from gsgeo.export import write_measurements
from gsgeo.export.atomic import atomic_path
from gsgeo.jsontypes import JSONObject
from gsgeo.measure import Measurement
from gsgeo.pointschema import provenance
from gsgeo.service.buildings import building_model, dtm_in_data_dir, reference_crs
from gsgeo.service.measuring import measure, stored_rays
from gsgeo.service.projects import (
    Projects,
    check_points_in_grid,
    feature_measures,
    validate_settings,
)

SUFFIX = {"gpkg": ".gpkg", "geojson": ".geojson", "geojson-grid": ".geojson", "csv": ".csv",
          "cityjson": ".city.json"}
#: The formats that hold buildings (GeoJSON and CSV do not).
BUILDING_FORMATS = ("gpkg", "cityjson")


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
        first_failure: GsgeoError | None = None
        for pt in points:
            try:
                m = measure(stored_rays(pt.rays), settings, pt.excluded, svc.data_dir,
                            point_id=pt.id, code=pt.code, description=pt.description)
            except GsgeoError as exc:
                by_id[pt.id] = None
                first_failure = first_failure or exc.within(f"point {pt.id}")
                continue
            measurements.append(m)
            by_id[pt.id] = m.record()
        grid_crs = settings["crs"]
        if not measurements and first_failure is not None:  # the cause, e.g. a missing geoid
            raise first_failure.part_of("crs", f"no point of project '{pid}' can be measured "
                                               f"in {grid_crs}")
    else:
        if project.crs is None:
            raise InputError(f"project '{pid}' has no grid CRS; give ?crs=EPSG:... to export",
                             field="crs")
        measurements = [pt.result for pt in points if pt.result is not None]
        by_id = {pt.id: pt.record for pt in points}
        grid_crs = project.crs
    if not measurements:
        failed = [pt for pt in points if pt.error]
        why = (f": its {len(failed)} point(s) could not be measured in {grid_crs}, e.g. "
               f"{failed[0].id}: {failed[0].error}" if failed else "")
        raise InputError(f"project '{pid}' has no solved points to export{why}")
    models: list[BuildingModel] = []
    skipped: list[str] = []
    if fmt in BUILDING_FORMATS:
        models, skipped = project_buildings(
            svc, pid, by_id, grid_crs, project.vertical if grid_crs == project.crs else None)
    path = outdir / f"{pid}{SUFFIX[fmt]}"
    if fmt == "cityjson":
        if not models:
            raise InputError(f"project '{pid}' has no buildings to export as CityJSON"
                             + (f" ({'; '.join(skipped)})" if skipped else ""), field="format")
        from gsgeo.buildings.cityjson import city_json_bytes, reference_system_uri

        data = city_json_bytes(models, reference_system_uri(reference_crs(
            grid_crs, project.vertical if grid_crs == project.crs else None)),
            title=project.name)
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
        return path, skipped

    proj = replace(project, crs=grid_crs,
                   vertical=project.vertical if grid_crs == project.crs else None)
    kept: dict[str, list[JSONObject]] = {"line": [], "polygon": []}
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
        check = [{"id": c.id, "role": c.role, "description": c.description,
                  "easting": float(x[0]), "northing": float(x[1]),
                  "height": None if x[2] != x[2] else float(x[2])} for c, x in zip(cps, xyz,
                                                                                  strict=True)]
    write_measurements(path, measurements, lines=kept["line"], polygons=kept["polygon"],
                       check_points=check, buildings=models, fmt=fmt,
                       provenance={pt.id: provenance(pt.rays, pt.measured_by) for pt in points})
    return path, skipped


def project_buildings(svc: Projects, pid: str, records: dict[str, JSONObject | None],
                      crs: str, vertical: str | None) -> tuple[list[BuildingModel], list[str]]:
    """The project's buildings built from ``records`` (point id -> record in ``crs``), and
    the descriptions of those that cannot be built (left out of an export)."""
    models: list[BuildingModel] = []
    skipped: list[str] = []
    for b in svc.list_building_records(pid):
        try:
            models.append(building_model(parse_building(b.spec), records, crs, vertical,
                                         dtm_in_data_dir(svc.data_dir)))
        except GsgeoError as exc:
            skipped.append(f"building {b.id}: {exc}")
    return models, skipped
