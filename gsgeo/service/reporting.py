"""The survey report's data: one project gathered from a :class:`Projects` service.

:func:`report_data` returns a plain JSON object (no store records, no numpy) that
gsgeo.report renders as HTML or PDF: the project and its solving settings, the reference
frames (grid CRS, the datum operation the points took with its stated accuracy, the vertical
datum or geoid), the scene's georeference (the applied fit with its control residuals, when
the service knows it), the accuracy against independent check points per ASPRS Edition 2
(gsgeo.measure.accuracy.asprs_accuracy) and the measured points with their total and
measurement-only sigmas. Coordinates are in the project's grid (its units), sigmas and
differences in metres.
"""

from __future__ import annotations

import math
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from gsgeo import __version__
from gsgeo.errors import GsgeoError, InputError
from gsgeo.jsontypes import JSONObject
from gsgeo.measure.accuracy import asprs_accuracy
from gsgeo.pointschema import provenance
from gsgeo.service.audit import audit_page
from gsgeo.service.measuring import json_ready
from gsgeo.service.projects import Projects
from gsgeo.store.records import CheckPointRecord, PointRecord, Project

#: Point-schema columns of the measured-points table, in order.
POINT_COLUMNS = ("point_id", "code", "easting", "northing", "height", "sigma_e", "sigma_n",
                 "sigma_h", "sigma_e_meas", "sigma_n_meas", "sigma_h_meas", "n_rays", "sigma0",
                 "max_angle_deg")


def _now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _crs_facts(code: str | None, source: str) -> JSONObject | None:
    """Name, datum, ellipsoid, projection of a CRS (None without one; an ``error`` entry
    when PROJ cannot describe it)."""
    if not code:
        return None
    from gsgeo.crs.discovery import describe_crs

    try:
        d = describe_crs(code, source)
    except GsgeoError as exc:
        return {"code": code, "error": str(exc)}
    axes = d.get("axes") or [{}]
    return {k: d.get(k) for k in ("code", "name", "type", "datum", "ellipsoid", "projection")} \
        | {"area_of_use": (d.get("area_of_use") or {}).get("name"), "unit": axes[0].get("unit")}


def _frames(p: Project, points: list[PointRecord]) -> JSONObject:
    """Reference frames: the CRSs and what the measured points actually went through."""
    recs = [q.record for q in points if q.record is not None]
    ops = Counter((r.get("operation"), r.get("operation_accuracy_m")) for r in recs
                  if r.get("operation"))
    heights = Counter((r.get("height_type"), r.get("vertical_datum")) for r in recs)
    return {
        "source_crs": _crs_facts(p.source_crs, p.source_crs),
        "grid_crs": _crs_facts(p.crs, p.source_crs),
        "vertical_crs": _crs_facts(p.vertical, p.source_crs),
        "geoid": p.geoid,
        "operations": [{"operation": op, "accuracy_m": acc, "points": n}
                       for (op, acc), n in ops.most_common()],
        "heights": [{"height_type": ht, "vertical_datum": vd, "points": n}
                    for (ht, vd), n in heights.most_common()],
    }


def _georeference(svc: Projects, pid: str, fit: JSONObject | None) -> JSONObject:
    """The scene's georeference as the service reports it: {"status": ..., "note": ...}.

    ``fit``: a georeference result to report instead of the applied one (e.g. a fit just
    computed and not applied); ``status["current_applied"]`` says which it is.
    ``Projects.georeference_status`` exists once georeferencing by control points is part of
    the service; without it (or when the project cannot have one) the note says why.
    """
    status_of = getattr(svc, "georeference_status", None)
    status: JSONObject | None = None
    note = None
    if status_of is None:
        note = "this gsgeo has no georeferencing by control points"
    else:
        try:
            status = dict(status_of(pid))
        except GsgeoError as exc:
            note = str(exc)
    if fit is not None:
        status = (status or {}) | {"current": fit, "current_applied": bool(fit.get("applied"))}
        note = None
    elif status is not None:
        status["current_applied"] = True
    current = (status or {}).get("current") or {}
    return {"status": status, "note": note,
            "frame_precision": frame_precision(current.get("frame_covariance"))}


def frame_precision(frame: JSONObject | None) -> JSONObject | None:
    """A fit's frame covariance (about the control centroid, parameters dt 3 m, dw 3 rad,
    ds 1; ECEF axes) as a surveyor reads it: 1-sigma shift in east, north, up (m), rotation
    about east, north, up (arcseconds), scale (ppm), and where the centroid is (lon, lat in
    degrees, ellipsoidal h in m). None without a usable covariance."""
    from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form, enu_rotation

    try:
        c = np.asarray(frame["covariance"], dtype=float) if frame else None
        centre = np.asarray(frame["centre_ecef"], dtype=float) if frame else None
    except (KeyError, TypeError, ValueError):
        return None
    if c is None or centre is None or c.shape != (7, 7) or centre.shape != (3,) \
            or not np.all(np.isfinite(c)) or not np.all(np.isfinite(centre)):
        return None
    lon, lat, h = (float(v) for v in np.ravel(ecef_to_geodetic_closed_form(centre[None, :])))
    r = enu_rotation(lon, lat).reshape(3, 3)

    def sig(block: np.ndarray) -> list[float]:
        return np.sqrt(np.clip(np.diag(r @ block @ r.T), 0.0, None)).tolist()

    return {"shift_enu_m": sig(c[:3, :3]),
            "rotation_enu_arcsec": [math.degrees(v) * 3600 for v in sig(c[3:6, 3:6])],
            "scale_ppm": math.sqrt(max(float(c[6, 6]), 0.0)) * 1e6,
            "centre": {"lon": lon, "lat": lat, "h": h}}


def _check_sigmas(cps: list[CheckPointRecord], ids: list[str]) -> tuple[np.ndarray, np.ndarray]:
    by_id = {c.id: c for c in cps if c.role == "check"}

    def val(v: float | None) -> float:
        return math.nan if v is None else float(v)

    return (np.array([val(by_id[i].sigma_h) if i in by_id else math.nan for i in ids]),
            np.array([val(by_id[i].sigma_v) if i in by_id else math.nan for i in ids]))


def _accuracy(svc: Projects, pid: str, p: Project, cps: list[CheckPointRecord],
              records: dict[str, JSONObject]) -> JSONObject:
    """Measured minus check per point (with the point's grid position, for the plan) and the
    ASPRS Edition 2 statistics; ``note`` says why there are none."""
    if not any(c.role == "check" for c in cps):
        return {"points": [], "asprs": None, "counts": None,
                "note": "no check points (role 'check') in this project"}
    if p.crs is None:
        return {"points": [], "asprs": None, "counts": None,
                "note": "the project has no grid CRS to compare check points in"}
    try:
        acc = svc.accuracy(pid, "check")
    except GsgeoError as exc:
        return {"points": [], "asprs": None, "counts": None, "note": str(exc)}
    rows = acc.get("points") or []
    ids = [str(r["id"]) for r in rows]
    d = np.array([[math.nan if r.get(k) is None else float(r[k]) for k in ("dE", "dN", "dH")]
                  for r in rows], dtype=float).reshape(-1, 3)
    sh, sv = _check_sigmas(cps, ids)
    for r, s_h, s_v in zip(rows, sh, sv, strict=True):
        rec = records.get(str(r["id"])) or {}
        r["easting"], r["northing"] = rec.get("easting"), rec.get("northing")
        r["survey_sigma_h"] = None if math.isnan(s_h) else float(s_h)
        r["survey_sigma_v"] = None if math.isnan(s_v) else float(s_v)
    asprs = asprs_accuracy(d, sh, sv) if rows else None
    note = None if rows else "no measured point has the id of a check point"
    return {"points": rows, "asprs": asprs, "counts": acc.get("counts"), "note": note,
            "heights": acc.get("heights")}


def _ecef_row(q: PointRecord) -> JSONObject | None:
    """A point solved without a grid: its id, ECEF X, Y, Z (m) and their total 1-sigma (m)."""
    res = q.result or {}
    try:
        xyz = [float(v) for v in res["point_ecef"]]
        cov = np.asarray(res.get("cov_ecef_total") or res.get("cov_ecef"), dtype=float)
        sig = np.sqrt(np.clip(np.diag(cov.reshape(3, 3)), 0.0, None)).tolist()
    except (KeyError, TypeError, ValueError):
        return None
    return {"point_id": q.id, "code": q.code, "x": xyz[0], "y": xyz[1], "z": xyz[2],
            "sigma_x": sig[0], "sigma_y": sig[1], "sigma_z": sig[2],
            "n_rays": res.get("n_rays"), "sigma0": res.get("sigma0")}


def _point_rows(points: list[PointRecord]) -> tuple[list[JSONObject], list[JSONObject],
                                                     list[JSONObject]]:
    """(rows in the grid with POINT_COLUMNS, rows solved without a grid in ECEF, points that
    could not be solved with their reason); the solved rows with the points' provenance
    (gsgeo.pointschema.PROVENANCE_KEYS: who measured them, rays clicked and matched)."""
    grid: list[JSONObject] = []
    ecef: list[JSONObject] = []
    failed: list[JSONObject] = []
    for q in points:
        if q.record is not None and q.record.get("easting") is not None:
            grid.append({k: q.record.get(k) for k in POINT_COLUMNS}
                        | provenance(q.rays, q.measured_by))
        elif q.result is not None and (row := _ecef_row(q)) is not None:
            ecef.append(row | provenance(q.rays, q.measured_by))
        else:
            failed.append({"point_id": q.id, "code": q.code,
                           "error": q.error or "not solved with the current settings"})
    return grid, ecef, failed


def _feature_rows(svc: Projects, pid: str, kind: str) -> list[JSONObject]:
    """The project's lines or polygons: id, code, point ids and their measures (grid metres,
    1σ; gsgeo.service.projects.feature_measures), or the error that prevents them."""
    return [{"id": f.id, "code": f.code, "points": list(f.point_ids)} | dict(measures)
            for f, measures in svc.list_features(pid, kind)]


def _building_rows(svc: Projects, pid: str) -> list[JSONObject]:
    """The project's LoD2 buildings: id, roof type, measures with their 1σ (grid metres,
    gsgeo.buildings.measures) and warnings, or the error that keeps one from being built."""
    out: list[JSONObject] = []
    for b in svc.list_buildings(pid):
        if b.get("error"):
            out.append({"id": b["id"], "error": b["error"]})
            continue
        ms = b.get("measures")
        out.append({"id": b["id"], "measures": ms if isinstance(ms, dict) else {},
                    "warnings": b.get("warnings") or []})
    return out


#: How many of the latest audit entries the report lists (the counts cover all of them).
AUDIT_ROWS = 50


def report_data(svc: Projects, pid: str, *, generated_at: str | None = None,
                georeference: JSONObject | None = None) -> JSONObject:
    """Everything the survey report of project ``pid`` shows, as plain JSON.

    ``georeference``: a GeorefResult to show instead of the scene's applied one (a fit not
    yet applied). Raises NotFoundError for an unknown project. Parts that cannot be computed
    (no grid, no check points, no georeference) carry a ``note`` instead of failing.
    """
    p = svc.get_project(pid)
    points = svc.list_points(pid)
    cps = svc.list_check_points(pid)
    records = {q.id: q.record for q in points if q.record is not None}
    solved, ecef, failed = _point_rows(points)
    control = [c for c in cps if c.role == "control"]
    doc: dict[str, Any] = {
        "generated": {"at": generated_at or _now(), "by": f"gsgeo {__version__}"},
        "project": {"id": p.id, "name": p.name, "description": p.description,
                    "scene": p.scene, "crs": p.crs, "vertical": p.vertical, "geoid": p.geoid,
                    "source_crs": p.source_crs, "sigma_px": p.sigma_px,
                    "settings_rev": p.settings_rev, "created_at": p.created_at,
                    "updated_at": p.updated_at},
        "frames": _frames(p, points),
        "georeference": _georeference(svc, pid, georeference),
        "accuracy": _accuracy(svc, pid, p, cps, records),
        "points": solved,
        "ecef_points": ecef,
        "failed_points": failed,
        "check_points": {"check": sum(1 for c in cps if c.role == "check"),
                         "control": len(control)},
        "lines": _feature_rows(svc, pid, "line"),
        "polygons": _feature_rows(svc, pid, "polygon"),
        "buildings": _building_rows(svc, pid),
        # the latest changes (newest first) and how many of each action there are in all
        "audit": audit_page(svc.store, pid, limit=AUDIT_ROWS),
    }
    return dict(json_ready(doc))



def report_version(svc: Projects, pid: str) -> str | None:
    """A text that changes whenever project ``pid``'s report may change: the store's revision
    (any committed change, by any process) and the state of its scene's tileset.json (the
    georeference); None when the store cannot tell (then no report may be reused).
    NotFoundError for an unknown project."""
    rev = svc.store.revision()
    p = svc.get_project(pid)
    if rev is None:
        return None
    scene = ""
    if p.scene and svc.data_dir is not None:
        try:
            st = (svc.data_dir / "scenes" / p.scene / "tileset.json").stat()
            scene = f"{st.st_mtime_ns}.{st.st_size}"
        except OSError:
            scene = "none"
    return f"{rev}:{scene}"


def write_report(svc: Projects, pid: str, output: str | Path, *,
                 georeference: JSONObject | None = None) -> JSONObject:
    """Write project ``pid``'s survey report to ``output`` (.pdf, .html or .htm; atomically:
    a failure leaves an earlier file as it was). ``georeference`` as for :func:`report_data`.
    Returns the report's data. InputError for an unknown suffix or a path that cannot be
    written, NotFoundError for an unknown project; both before anything is rendered."""
    from gsgeo.export.atomic import atomic_path, check_target
    from gsgeo.report import FORMATS, format_from_suffix, render

    fmt = format_from_suffix(output)
    if fmt is None:
        known = ", ".join(s for sfx in FORMATS.values() for s in sfx)
        suffix = Path(output).suffix
        what = f"unknown report format '{suffix}'" if suffix else "no suffix to tell the format"
        raise InputError(f"{what}; use one of {known}", field="output")
    check_target(output)
    data = report_data(svc, pid, georeference=georeference)
    body = render(data, fmt)
    with atomic_path(output) as tmp:
        tmp.write_bytes(body)
    return data
