"""Parsing and classifying coordinate reference systems, with errors in the user's terms.

Every CRS enters gsgeo through these functions, so an unknown code, a geographic CRS where a
projected one is needed, or a geocentric source that is not geocentric gives one clear
:class:`~gsgeo.errors.CRSError`. PROJ never goes to the network from gsgeo: parse_crs and the
transformer factory call :func:`network_off` (an explicit call, not an import side effect).
"""

from __future__ import annotations

import functools
import os
import sqlite3
from dataclasses import dataclass

import pyproj
from pyproj import CRS
from pyproj.exceptions import CRSError as ProjCRSError

from gsgeo.errors import CRSError
from gsgeo.limits import text_problem

_network = {"off": False}


def network_off() -> None:
    """Keep PROJ off the network (no grid downloads from cdn.proj.org at run time).

    Idempotent and cheap after the first call. :func:`parse_crs` and every factory of
    :mod:`gsgeo.crs.transformers` call it before PROJ is used; code that hands PROJ work to
    another library (GDAL through pyogrio) calls it first itself. Sets PROJ_NETWORK=OFF for
    PROJ contexts created later (GDAL's, worker processes') and turns pyproj's off.
    """
    if _network["off"]:
        return
    os.environ["PROJ_NETWORK"] = "OFF"
    pyproj.network.set_network_enabled(False)
    _network["off"] = True


def parse_crs(crs: object) -> CRS:
    """A pyproj CRS from anything pyproj accepts: a :class:`pyproj.CRS` (returned as it is),
    an EPSG code as an int (27700) or digits ("27700"), user text ("EPSG:27700",
    "EPSG:27700+5701", WKT, a PROJ string, PROJ JSON) or a PROJ JSON dict.

    Text and codes are parsed once (cached). Raises CRSError naming the input when PROJ does
    not know it. Turns PROJ's network off first (:func:`network_off`).
    """
    network_off()
    if isinstance(crs, CRS):
        return crs
    if isinstance(crs, int) and not isinstance(crs, bool):
        return _parse_text(f"EPSG:{crs}")
    if isinstance(crs, str):
        if not crs.strip():
            raise CRSError("a CRS must be given as text such as EPSG:27700")
        problem = text_problem(crs)  # PROJ would read up to a NUL, or fail to encode
        if problem is not None:
            raise CRSError(f"a CRS text {problem}")
        return _parse_text(crs)
    if crs is None or isinstance(crs, bool | float):
        raise CRSError("a CRS must be given as text such as EPSG:27700")
    try:
        return CRS.from_user_input(crs)
    except (ProjCRSError, TypeError, ValueError):
        raise CRSError(_unknown(str(crs))) from None


def _unknown(text: str) -> str:
    return (f"unknown CRS '{text}': PROJ does not know it; give an authority code such as "
            "EPSG:27700 (try `gsgeo crs search NAME`)")


@functools.lru_cache(maxsize=256)
def _parse_text(text: str) -> CRS:
    s = text.strip()
    if s.isdigit():
        s = f"EPSG:{s}"
    try:
        return CRS.from_user_input(s)
    except ProjCRSError:
        raise CRSError(_unknown(text)) from None


def crs_id(crs: CRS, fallback: str | None = None) -> str:
    """Short identifier, 'EPSG:27700' or 'EPSG:27700+5701' where possible, else the name."""
    auth = crs.to_authority(min_confidence=100)
    if auth:
        return f"{auth[0]}:{auth[1]}"
    if crs.is_compound:
        parts = [crs_id(c) for c in crs.sub_crs_list]
        if all(":" in p for p in parts) and len({p.split(":")[0] for p in parts}) == 1:
            return parts[0] + "+" + "+".join(p.split(":")[1] for p in parts[1:])
    return fallback or crs.name


@dataclass(frozen=True)
class GridCRS:
    """A target grid: its projected horizontal CRS and optional vertical CRS."""

    horizontal: CRS
    vertical: CRS | None
    id: str  # of the horizontal CRS, e.g. "EPSG:27700"
    vertical_id: str | None  # e.g. "EPSG:5701"
    unit_factor: float  # metres per unit of easting/northing
    vertical_unit_factor: float  # metres per unit of height


def projected_crs(text: str) -> CRS:
    """The projected CRS of `text` (a compound CRS's horizontal part); CRSError otherwise."""
    crs = parse_crs(text)
    horiz = crs.sub_crs_list[0] if crs.is_compound else crs
    if horiz.is_projected:
        return horiz
    if horiz.is_geographic:
        raise CRSError(
            f"'{text}' ({crs.name}) is a geographic CRS (latitude, longitude in degrees); "
            "gsgeo needs a projected CRS with easting and northing in metres or feet, "
            "e.g. a national grid or UTM zone (try `gsgeo crs search NAME`)"
        )
    raise CRSError(
        f"'{text}' ({crs.name}) is a {crs.type_name} CRS, not a projected one; give a "
        "projected CRS with easting and northing (try `gsgeo crs search NAME`)"
    )


@functools.lru_cache(maxsize=64)
def grid_crs(crs: str, vertical: str | None = None) -> GridCRS:
    """Resolve the output grid: a projected CRS, optionally with a vertical CRS.

    A compound `crs` (e.g. "EPSG:27700+5701") supplies its vertical part unless `vertical`
    is also given, in which case the two must agree.
    """
    full = parse_crs(crs)
    horiz = projected_crs(crs)
    vert = None
    if full.is_compound and len(full.sub_crs_list) > 1:
        vert = full.sub_crs_list[1]
    if vertical is not None:
        v = parse_crs(vertical)
        if not v.is_vertical:
            raise CRSError(
                f"'{vertical}' ({v.name}) is not a vertical CRS; give a vertical datum's "
                "height CRS such as EPSG:5701 (ODN height) or EPSG:5703 (NAVD88 height)"
            )
        if vert is not None and not vert.equals(v):
            raise CRSError(f"'{crs}' already has the vertical CRS {vert.name}; do not also give '{vertical}'")
        vert = v
    for ax in horiz.axis_info[:2]:
        if ax.unit_conversion_factor is None or ax.unit_name == "unknown":
            raise CRSError(f"'{crs}' has no linear unit on its axes")
    unit = float(horiz.axis_info[0].unit_conversion_factor)
    vunit = float(vert.axis_info[0].unit_conversion_factor) if vert is not None else 1.0
    return GridCRS(horiz, vert, crs_id(horiz, crs), None if vert is None else crs_id(vert),
                   unit, vunit)


@dataclass(frozen=True)
class SourceCRS:
    """The scene's geocentric realisation and its geographic 2D / 3D companions."""

    geocentric: CRS
    geographic_2d: CRS
    geographic_3d: CRS
    id: str
    a: float  # semi-major axis, m
    f: float  # flattening
    is_wgs84: bool
    geographic_2d_id: str = ""  # "EPSG:4326", or WKT when the CRS has no code
    geographic_3d_id: str = ""


def _proj_db() -> str:
    return os.path.join(pyproj.datadir.get_data_dir().split(os.pathsep)[0], "proj.db")


def _companions(crs: CRS) -> tuple[CRS, CRS] | None:
    """Geographic 2D and 3D CRSs of the same datum, by authority code from PROJ's database."""
    auth = crs.to_authority(min_confidence=100)
    if not auth:
        return None
    try:
        con = sqlite3.connect(f"file:{_proj_db()}?mode=ro", uri=True)
    except sqlite3.Error:
        return None
    try:
        row = con.execute(
            "SELECT datum_auth_name, datum_code FROM geodetic_crs WHERE auth_name=? AND code=?",
            auth,
        ).fetchone()
        if row is None:
            return None
        found = {}
        for kind in ("geographic 2D", "geographic 3D"):
            r = con.execute(
                "SELECT auth_name, code FROM geodetic_crs WHERE datum_auth_name=? AND "
                "datum_code=? AND type=? AND deprecated=0 AND auth_name=? ORDER BY code LIMIT 1",
                (row[0], row[1], kind, auth[0]),
            ).fetchone()
            if r is None:
                return None
            found[kind] = CRS.from_authority(r[0], r[1])
        return found["geographic 2D"], found["geographic 3D"]
    except sqlite3.Error:
        return None
    finally:
        con.close()


@functools.lru_cache(maxsize=32)
def source_crs(text: str = "EPSG:4978") -> SourceCRS:
    """The scene's geocentric CRS (EPSG:4978 WGS 84, EPSG:4936 ETRS89, EPSG:7842 GDA2020, ...)."""
    crs = parse_crs(text)
    if not crs.is_geocentric:
        raise CRSError(
            f"source CRS '{text}' ({crs.name}) is not geocentric; the scene's rays are in "
            "Earth-centred Cartesian coordinates, so give a geocentric CRS such as EPSG:4978 "
            "(WGS 84), EPSG:4936 (ETRS89), EPSG:7842 (GDA2020) or EPSG:6317 (NAD83(2011))"
        )
    comp = _companions(crs)
    if comp is None:
        from pyproj.crs import GeographicCRS
        from pyproj.crs.coordinate_system import Ellipsoidal3DCS

        comp = (GeographicCRS(datum=crs.datum),
                GeographicCRS(datum=crs.datum, ellipsoidal_cs=Ellipsoidal3DCS()))
    ell = crs.ellipsoid
    assert ell is not None  # geographic and geocentric CRSs have one
    a = float(ell.semi_major_metre)
    f = 1.0 / float(ell.inverse_flattening) if ell.inverse_flattening else 0.0
    ids = [crs_id(c, c.to_wkt()) if c.to_authority(min_confidence=100) else c.to_wkt()
           for c in comp]
    return SourceCRS(crs, comp[0], comp[1], crs_id(crs, text), a, f,
                     is_wgs84=crs_id(crs) == "EPSG:4978",
                     geographic_2d_id=ids[0], geographic_3d_id=ids[1])
