"""Selected point features as the body of POST /api/projects/{pid}/checkpoints.

Each point's id is its point_id, id or name attribute (the first the layer has and the
feature fills), else the QGIS feature id; x, y, z are the geometry's in the layer's CRS.
A WGS 84 layer with heights (OGC:CRS84 or EPSG:4326, as OAPIF layers are) is sent as
EPSG:4979, its 3D form: OGC API - Features heights are WGS 84 ellipsoidal (RFC 7946), and
the server reads x as longitude and y as latitude for a geographic CRS.
"""

from __future__ import annotations

import math
from typing import Any

from qgis.core import QgsCoordinateReferenceSystem, QgsVectorLayer, QgsWkbTypes
from qgis.PyQt.QtCore import QVariant

from .styles import NAME_FIELDS

#: CRSs whose 3D counterpart with ellipsoidal heights is EPSG:4979.
WGS84_2D = frozenset({"EPSG:4326", "OGC:CRS84"})


def crs_text(crs: QgsCoordinateReferenceSystem, has_z: bool) -> str:
    """How the server is told the layer's CRS: its authority id, else its WKT."""
    authid = crs.authid()
    if authid in WGS84_2D and has_z:
        return "EPSG:4979"
    return authid or crs.toWkt(QgsCoordinateReferenceSystem.WKT_PREFERRED)


def payload(points: list[dict[str, Any]], crs: str, role: str,
            source: str = "") -> dict[str, Any]:
    """The request body: ``points`` as [{id, x, y[, z]}], their CRS, role and source."""
    if role not in ("check", "control"):
        raise ValueError(f"role must be 'check' or 'control', got '{role}'")
    body: dict[str, Any] = {"crs": crs, "role": role, "points": points}
    if source:
        body["source"] = source[:300]
    return body


def describe(p: dict[str, Any], crs: str, role: str, source: str) -> str:
    """One point as the user is shown it: role, coordinates, CRS and source."""
    z = "" if p.get("z") is None else f", {p['z']}"
    return f"{role} ({p['x']}, {p['y']}{z}) in {crs}" + (f", source '{source}'" if source else "")


def replacement_question(body: dict[str, Any], stored: list[dict[str, Any]],
                         ids: list[str]) -> str:
    """What the user is asked before ``ids`` of ``stored`` are replaced by ``body``'s points:
    each id's stored and new values."""
    old = {str(c["id"]): c for c in stored}
    new = {str(p["id"]): p for p in body["points"]}
    lines = [f"{len(ids)} of these ids are already stored in the project. Replace them?", ""]
    for i in ids:
        lines.append(f"{i}:")
        if i in old:
            c = old[i]
            lines.append("  stored: " + describe(c, str(c.get("crs")), str(c.get("role")),
                                                 str(c.get("source") or "")))
        if i in new:
            lines.append("  new:    " + describe(new[i], str(body["crs"]), str(body["role"]),
                                                 str(body.get("source") or "")))
    lines += ["", "No: nothing is sent."]
    return "\n".join(lines)


def feature_name(feature: Any, fields: list[str]) -> str:
    """The feature's id for the server: a filled name field, else its QGIS feature id."""
    for f in fields:
        value = feature[f]
        if value is None or (isinstance(value, QVariant) and value.isNull()):
            continue  # a NULL attribute (QGIS 3.22 gives a null QVariant)
        if str(value).strip():
            return str(value).strip()
    return str(feature.id())


def selected_points(layer: QgsVectorLayer) -> tuple[list[dict[str, Any]], int]:
    """([{id, x, y[, z]}] of the selected point features, how many selected were skipped:
    not a single point, or without finite coordinates)."""
    names = layer.fields().names()
    fields = [f for f in NAME_FIELDS if f in names]
    out: list[dict[str, Any]] = []
    skipped = 0
    for feat in layer.getSelectedFeatures():
        geom = feat.geometry()
        if geom.isNull() or QgsWkbTypes.geometryType(geom.wkbType()) != QgsWkbTypes.PointGeometry:
            skipped += 1
            continue
        parts = list(geom.constGet().vertices())
        if len(parts) != 1 or not (math.isfinite(parts[0].x()) and math.isfinite(parts[0].y())):
            skipped += 1
            continue
        p = parts[0]
        row: dict[str, Any] = {"id": feature_name(feat, fields), "x": p.x(), "y": p.y()}
        if p.is3D() and math.isfinite(p.z()):
            row["z"] = p.z()
        out.append(row)
    return out, skipped


def layer_payload(layer: QgsVectorLayer, role: str) -> tuple[dict[str, Any] | None, int]:
    """(body for the selected points of ``layer`` or None when none qualifies, skipped)."""
    points, skipped = selected_points(layer)
    if not points:
        return None, skipped
    has_z = any("z" in p for p in points)
    return payload(points, crs_text(layer.crs(), has_z), role, f"QGIS layer '{layer.name()}'"), \
        skipped
