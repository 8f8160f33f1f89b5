"""Finding CRSs by name or code, and describing one (units, axes, datum, area, operation)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

from pyproj.database import query_crs_info
from pyproj.enums import PJType

from gsgeo.crs.resolve import crs_id, parse_crs, source_crs
from gsgeo.crs.transformers import accuracy_m, candidates, in_area

KINDS = {
    "projected": [PJType.PROJECTED_CRS],
    "compound": [PJType.COMPOUND_CRS],
    "vertical": [PJType.VERTICAL_CRS],
    "geocentric": [PJType.GEOCENTRIC_CRS],
}


@dataclass(frozen=True)
class CRSMatch:
    code: str  # "EPSG:27700"
    name: str
    kind: str
    area: str
    deprecated: bool


@functools.lru_cache(maxsize=8)
def _catalogue(kinds: tuple[str, ...]) -> tuple[CRSMatch, ...]:
    types = [t for k in kinds for t in KINDS[k]]
    rows = []
    for info in query_crs_info(pj_types=types, allow_deprecated=True):
        rows.append(CRSMatch(f"{info.auth_name}:{info.code}", info.name,
                             info.type.name.replace("_CRS", "").lower(),
                             (info.area_of_use.name or "") if info.area_of_use else "",
                             info.deprecated))
    return tuple(rows)


def search_crs(text: str, kinds: tuple[str, ...] = ("projected", "compound"),
               include_deprecated: bool = False, authority: str | None = "EPSG") -> list[CRSMatch]:
    """CRSs whose code equals `text` or whose name / area contains every word of it.

    Case-insensitive. Best first: exact code, then name matches, then area matches.
    """
    words = text.lower().split()
    if not words:
        return []
    code = text.strip().upper()
    if code.isdigit():
        code = f"EPSG:{code}"
    scored = []
    for m in _catalogue(tuple(kinds)):
        if m.deprecated and not include_deprecated:
            continue
        if authority and not m.code.startswith(authority + ":") and m.code != code:
            continue
        name = m.name.lower()
        hay = f"{name} {m.area.lower()} {m.code.lower()}"
        if m.code == code:
            scored.append((0, m))
        elif all(w in name or w in m.code.lower() for w in words):
            scored.append((1, m))
        elif all(w in hay for w in words):
            scored.append((2, m))
    scored.sort(key=lambda s: (s[0], s[1].name))
    return [m for _, m in scored]


def describe_crs(text: str, source: str = "EPSG:4978") -> dict:
    """Units, axes, datum, ellipsoid, area of use and the operation(s) from the source CRS."""
    crs = parse_crs(text)
    out: dict = {"code": crs_id(crs, text), "name": crs.name, "type": crs.type_name}
    out["axes"] = [
        {"name": a.name, "abbrev": a.abbrev, "direction": a.direction, "unit": a.unit_name,
         "metres_per_unit": a.unit_conversion_factor}
        for a in crs.axis_info
    ]
    datum = crs.datum
    out["datum"] = datum.name if datum is not None else None
    out["ellipsoid"] = crs.ellipsoid.name if crs.ellipsoid is not None else None
    if crs.is_compound:
        out["components"] = [f"{crs_id(c)} {c.name}" for c in crs.sub_crs_list]
    a = crs.area_of_use
    if a is None and crs.is_compound:
        a = crs.sub_crs_list[0].area_of_use
    out["area_of_use"] = None if a is None else {
        "name": a.name, "west": a.west, "south": a.south, "east": a.east, "north": a.north}
    try:
        proj = crs.coordinate_operation
        out["projection"] = None if proj is None else proj.method_name
    except Exception:  # noqa: BLE001
        out["projection"] = None
    ops: list[dict[str, object]] = []
    src = source_crs(source)
    target = crs_id(crs, crs.to_wkt())
    if (crs.is_projected or crs.is_compound or crs.is_geographic or crs.is_vertical) and a is not None:
        s3 = crs_id(src.geographic_3d, src.geographic_3d.to_wkt())
        lon0, lat0 = (a.west + a.east) / 2, (a.south + a.north) / 2
        c = candidates(s3, target)
        for t in c.available[:5]:
            ops.append({"operation": t.description, "accuracy_m": accuracy_m(t),
                        "available": True, "covers_area_centre": in_area(t, lon0, lat0),
                        "ballpark": "ballpark" in t.description.lower()})
        for op in c.unavailable[:5]:
            ops.append({"operation": op.name,
                        "accuracy_m": op.accuracy if op.accuracy and op.accuracy > 0 else None,
                        "available": False,
                        "missing_grids": [g.short_name for g in op.grids if not g.available]})
        out["from"] = src.id
    out["operations"] = ops
    return out
