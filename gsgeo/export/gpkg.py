"""GeoPackage writer (pyogrio): layers points, rays, lines, polygons, error_ellipses,
check_points and buildings (one PolygonZ per surface of an LoD2 building).

Layers with nothing to hold are not created. The CRS is registered by its EPSG code when it
has one (a compound such as EPSG:27700+5701 is EPSG:7405); a compound without a code of its
own (e.g. EPSG:32630+5773) is stored with its WKT2 definition (GeoPackage extension
gpkg_crs_wkt), so it reads back equal either way. The 2-D layer error_ellipses uses the
horizontal CRS.

Field types: TEXT for ids and labels, REAL for numbers (NULL where unknown), MEDIUMINT for
counts, BOOLEAN for flags.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import cast

import numpy as np
import shapely

from gsgeo.crs.resolve import parse_crs
from gsgeo.errors import InputError
from gsgeo.export import wkb
from gsgeo.export.arrow import GEOMETRY, table_stream
from gsgeo.export.tables import ExportData, Table

SYNC_OPTION = "OGR_SQLITE_SYNCHRONOUS"


def gpkg_crs(text: str) -> tuple[str, dict[str, str]]:
    """CRS text for GDAL and dataset options: 'EPSG:code' when the CRS has one, else WKT2."""
    crs = parse_crs(text)
    auth = crs.to_authority(min_confidence=100)
    if auth:
        return f"{auth[0]}:{auth[1]}", {}
    return crs.to_wkt(), {"CRS_WKT_EXTENSION": "YES"}


def arrow_write_available() -> bool:
    """pyogrio's Arrow write path needs GDAL >= 3.8 (pyogrio's wheels bring a newer one)."""
    import pyogrio

    return tuple(pyogrio.__gdal_version__) >= (3, 8, 0)


def write_layer(path: Path, name: str, geometry: tuple[np.ndarray, np.ndarray], table: Table,
                geometry_type: str, crs: str, append: bool, description: str) -> None:
    """One layer: through pyogrio's Arrow path (GDAL inserts the whole batch in C) where GDAL
    has it, else feature by feature with pyogrio's `write`; the files are the same."""
    from pyogrio.raw import write, write_arrow

    crs_text, ds_opts = gpkg_crs(crs)
    common = {"layer": name, "driver": "GPKG", "geometry_type": geometry_type, "crs": crs_text,
              "append": append, "dataset_options": None if append else (ds_opts or None),
              "layer_options": {"DESCRIPTION": description}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        if arrow_write_available():
            write_arrow(table_stream(geometry, table), str(path), geometry_name=GEOMETRY, **common)
        else:
            offsets, data = geometry
            wkb_items = np.array([data[a:b].tobytes() for a, b in
                                  zip(offsets[:-1].tolist(), offsets[1:].tolist(), strict=True)],
                                 dtype=object)
            write(str(path), wkb_items, *_raw_fields(table), nan_as_null=True, **common)


def _raw_fields(table: Table) -> tuple[list[np.ndarray], list[str]]:
    kinds = {"str": object, "int": np.int32, "bool": bool, "float": np.float64}
    data = [np.asarray(col, dtype=kinds[table.types[k]]) for k, col in table.columns.items()]
    return data, list(table.columns)


def write_gpkg(path: Path, data: ExportData) -> None:
    """Write every non-empty layer of `data` into a new GeoPackage at `path`.

    WKB is assembled with numpy for the large layers (points, rays, ellipses); the few lines,
    polygons and check points go through shapely.
    """
    from pyogrio.errors import DataLayerError, DataSourceError, FieldError, GeometryError

    unit = f"heights {data.height_type}: {data.vertical_datum}"
    layers = [("points", lambda: wkb.points(data.point_xyz), data.points, "Point Z", data.crs,
               f"gsgeo measured points; {unit}; sigmas 1 sigma (m), covariances m^2, "
               "ellipses 95 % (m, bearing from grid north)")]
    # collect sets each layer's geometry array together with its table
    if data.rays is not None:
        ray_xyz = cast(np.ndarray, data.ray_xyz)
        layers.append(("rays", lambda: wkb.linestrings(ray_xyz), data.rays, "LineString Z",
                       data.crs, "gsgeo rays: camera centre to the measured point; residuals "
                       "in pixels and metres; ray_index 0-based"))
    if data.lines is not None:
        layers.append(("lines", lambda: _shapely_wkb(
            [shapely.linestrings(data.point_xyz[i]) for i in data.line_index], 3),
            data.lines, "LineString Z", data.crs,
            "gsgeo lines through measured points; grid lengths (m) with 1 sigma"))
    if data.polygons is not None:
        layers.append(("polygons", lambda: _shapely_wkb(
            [shapely.polygons(data.point_xyz[np.append(i, i[0])]) for i in data.polygon_index], 3),
            data.polygons, "Polygon Z", data.crs, "gsgeo polygons of measured points; grid "
            "area (m^2) and perimeter (m) with 1 sigma"))
    if data.ellipses is not None:
        ellipse_xy = cast(np.ndarray, data.ellipse_xy)
        layers.append(("error_ellipses", lambda: wkb.polygons(ellipse_xy), data.ellipses,
                       "Polygon", data.horizontal_crs,
                       "gsgeo 95 % horizontal error ellipses of the points (true size)"))
    if data.check_points is not None:
        check_xyz = cast(np.ndarray, data.check_xyz)
        z3 = bool(np.all(np.isfinite(check_xyz[:, 2])))
        layers.append(("check_points",
                       lambda: wkb.points(check_xyz if z3 else check_xyz[:, :2]),
                       data.check_points, "Point Z" if z3 else "Point",
                       data.crs if z3 else data.horizontal_crs,
                       "check points (ground truth); d_* = measured - check"))
    if data.buildings is not None:
        layers.append(("buildings", lambda: _shapely_wkb(
            [shapely.polygons(np.vstack([r, r[:1]])) for r in data.building_rings], 3),
            data.buildings, "Polygon Z", data.crs, "gsgeo LoD2 buildings: one surface per row "
            "(RoofSurface, WallSurface, GroundSurface), outward; the building's volume (m^3), "
            "footprint area (m^2) and heights with 1 sigma"))
    try:
        with _no_sqlite_sync():
            for k, (name, geometry, table, gtype, crs, desc) in enumerate(layers):
                write_layer(path, name, geometry(), table, gtype, crs, append=k > 0,
                             description=desc)
    except (DataSourceError, DataLayerError, FieldError, GeometryError) as exc:
        raise InputError(f"GDAL could not write the GeoPackage: {exc}") from None


def _shapely_wkb(geoms: list, dims: int) -> tuple[np.ndarray, np.ndarray]:
    return wkb.from_bytes(shapely.to_wkb(np.array(geoms, dtype=object), output_dimension=dims,
                                         flavor="iso", byte_order=1))


@contextlib.contextmanager
def _no_sqlite_sync() -> Iterator[None]:
    """SQLite without fsync per commit: the file is a temporary one that gsgeo.export.atomic
    fsyncs once before renaming it, so durability is kept at a fraction of the cost.
    (A GDAL config option is process-wide; either value is safe for a concurrent write.)"""
    from pyogrio import get_gdal_config_option, set_gdal_config_options

    old = get_gdal_config_option(SYNC_OPTION)
    set_gdal_config_options({SYNC_OPTION: "OFF"})
    try:
        yield
    finally:
        set_gdal_config_options({SYNC_OPTION: old})
