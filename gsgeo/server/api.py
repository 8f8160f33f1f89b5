"""The JSON API under /api (README "API"); shapes are documented at /docs.

Endpoints are plain (sync) functions: FastAPI runs them in its thread pool, so the event loop
keeps parsing and answering (static files, other requests) while numpy and PROJ work, and
each store call is one SQLite transaction. POST /intersect, the one the viewer calls at every
click, runs on the server's long-lived threads instead (gsgeo.server.intersect_pool: warm PROJ
objects), and never on the event loop itself (a solve there stalls every other request, and
the latency tail with it when the machine is busy).
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Annotated, Any, Literal

import orjson
from fastapi import APIRouter, Body, File, Form, Query, Request, Response, UploadFile
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from gsgeo import __version__
from gsgeo.errors import InputError
from gsgeo.server import models as m
from gsgeo.server.etags import IfMatch, if_match_versions, with_etag
from gsgeo.server.hosts import is_loopback
from gsgeo.server.scenes import list_scenes
from gsgeo.server.textbody import TextCheckedRoute
from gsgeo.service import CheckPointRecord, FeatureRecord, PointRecord, Project, Projects
from gsgeo.service.audit import audit_page
from gsgeo.service.checkpoints import CheckPointRow
from gsgeo.service.measuring import measure
from gsgeo.service.projects import intersect_point
from gsgeo.service.projects import intersect_request as check_intersect


class ErrorBody(m.BaseModel):
    """Every error: ``message`` names the field first ("rays[1].direction: ...")."""

    detail: Any
    message: str
    field: str | None = None


router = APIRouter(prefix="/api", route_class=TextCheckedRoute, responses={
    400: {"model": ErrorBody, "description": "Host header not served, or bad Content-Length"},
    401: {"model": ErrorBody, "description": "token missing or wrong (server bound off loopback)"},
    403: {"model": ErrorBody, "description": "cross-origin request, or a change asked for "
                                             "with a viewer's token"},
    404: {"model": ErrorBody, "description": "no such project, point, line, polygon, building "
                                             "or check point"},
    409: {"model": ErrorBody, "description": "id already taken, or the point is still in use"},
    412: {"model": ErrorBody, "description": "If-Match names a version of the item that is no "
                                             "longer stored (changed by someone else); the "
                                             "answer's ETag is the current one"},
    413: {"model": ErrorBody, "description": "request body over the size limit"},
    422: {"model": ErrorBody, "description": "malformed request; message names the field"},
    503: {"model": ErrorBody, "description": "the project store is busy or unavailable"},
})

PID = Annotated[str, m.Field(description="project id", max_length=64)]
ITEM = Annotated[str, m.Field(description="point, line, polygon or check point id",
                              max_length=100)]
EXPORT_TYPES = {"gpkg": "application/geopackage+sqlite3", "geojson": "application/geo+json",
                "geojson-grid": "application/json", "csv": "text/csv; charset=utf-8",
                "cityjson": "application/city+json"}


#: The schema of the handlers that answer through ``fast_json`` (a Response the route passes on
#: as it is): what the OpenAPI document states they return.
JSON_OBJECT = dict[str, Any]
CrsKind = Literal["projected", "compound", "vertical", "geocentric"]
DEFAULT_KINDS: list[CrsKind] = ["projected", "compound"]


def fast_json(obj: Any, status_code: int = 200) -> Response:
    """JSON (UTF-8) of plain dicts, lists, numbers and numpy values, through orjson.

    Skips FastAPI's generic encoder. NaN and infinities become null, as ``json_ready`` makes
    them (JSON has no NaN).
    """
    body = orjson.dumps(obj, option=orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS)
    return Response(body, status_code=status_code, media_type="application/json")


def svc(request: Request) -> Projects:
    return request.app.state.projects


def project_json(p: Project) -> dict[str, Any]:
    return {"id": p.id, "name": p.name, "description": p.description, "scene": p.scene,
            "crs": p.crs, "vertical": p.vertical, "geoid": p.geoid, "source_crs": p.source_crs,
            "sigma_px": p.sigma_px, "settings_rev": p.settings_rev,
            "created_at": p.created_at, "updated_at": p.updated_at}


def point_json(pt: PointRecord) -> dict[str, Any]:
    return {"id": pt.id, "code": pt.code, "description": pt.description, "rays": pt.rays,
            "excluded": pt.excluded, "status": "solved" if pt.result is not None else "failed",
            "error": pt.error, "record": pt.record, "result": pt.result,
            "frame": pt.frame, "created_at": pt.created_at, "updated_at": pt.updated_at,
            "version": pt.version, "measured_by": pt.measured_by}


def feature_json(f: FeatureRecord, measures: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"id": f.id, "kind": f.kind, "points": f.point_ids, "code": f.code,
            "description": f.description, "measures": measures,
            "created_at": f.created_at, "updated_at": f.updated_at, "version": f.version}


# info, intersect, crs, scenes --------------------------------------------------------------
@router.get("/info", summary="Server version, limits, whether a token is required, who asks")
def info(request: Request) -> dict[str, Any]:
    cfg = request.app.state.config
    state = request.scope.get("state") or {}
    # a token is required where a request without one is refused: with the server's own
    # token, and off loopback for everyone (a user's or the server's token)
    return {"version": __version__,
            "token_required": cfg.token is not None or not is_loopback(str(cfg.host)),
            "user": state.get("gsgeo_user"), "role": state.get("gsgeo_role"),
            "max_body_bytes": cfg.max_body, "max_upload_bytes": cfg.max_upload,
            "cesium_url": "/cesium/", "scenes_url": "/scenes/"}


@router.post("/intersect", response_model=JSON_OBJECT, summary="Intersect one point's rays (stateless)")
async def intersect(body: m.IntersectRequest, request: Request) -> dict[str, Any] | Response:
    """One point's rays (session-JSON shape) and solving options -> the solved point:
    grid coordinates and covariance (when ``crs`` is given), WGS 84 position, sigma0,
    residuals per ray, outlier flags and warnings (gsgeo.measure.point ``to_dict``)."""
    state = request.app.state
    return await state.intersect_pool.run(intersect_request, body, state.config.data_dir)


def warm_intersect() -> None:
    """A solve of two synthetic rays (no grid CRS): imports the pipeline and builds the PROJ
    objects every request needs on the calling thread."""
    up = [3978000.0, -8700.0, 4968000.0]  # ECEF, metres: near London, ~50 m up
    body = m.IntersectRequest(id="warm-up", rays=[
        m.Ray(origin=[up[0] + 30.0 * k, up[1], up[2] + 40.0], direction=[-k, 0.0, -1.0])
        for k in (1, -1)])
    intersect_point(body.to_input(), {"source_crs": "EPSG:4978"}, None).to_dict()


def intersect_request(body: m.IntersectRequest, data_dir: Path) -> Response:
    """The work of POST /intersect, on a thread of gsgeo.server.intersect_pool."""
    point = body.to_input()
    excluded, settings = check_intersect(point, body.settings(), data_dir)
    out = measure(point.rays, settings, excluded, data_dir, point_id=body.id, code=body.code,
                  description=body.description).to_dict()
    for ray, given in zip(out["rays"], point.provenance, strict=False):
        ray.update(given)  # the ray's auto / score, returned as given
    return fast_json(out)


@router.get("/crs", summary="Search coordinate reference systems by name, area or code")
def crs_search(q: Annotated[str, Query(min_length=1, max_length=200,
                                       description="words of the name or area, or a code")],
               kind: Annotated[list[CrsKind],
                               Query(description="kinds of CRS to search")] = DEFAULT_KINDS,
               limit: Annotated[int, Query(ge=1, le=500)] = 50) -> dict[str, Any]:
    from gsgeo.crs.discovery import search_crs

    hits = search_crs(q, kinds=tuple(dict.fromkeys(kind or ["projected", "compound"])))
    return {"query": q, "total": len(hits),
            "results": [{"code": h.code, "name": h.name, "kind": h.kind, "area": h.area}
                        for h in hits[:limit]]}


@router.get("/scenes", summary="Scenes in DATA/scenes with their georeference")
def scenes(request: Request) -> dict[str, Any]:
    return {"scenes": list_scenes(request.app.state.config.data_dir,
                                  request.app.state.scene_hosts)}


# projects --------------------------------------------------------------------------------
@router.get("/projects", summary="List projects")
def list_projects(request: Request) -> dict[str, Any]:
    return {"projects": [project_json(p) for p in svc(request).list_projects()]}


@router.get("/projects/{pid}/audit",
            summary="The project's audit trail: who changed what, when, before and after")
def project_audit(pid: PID, request: Request,
                  item: Annotated[str | None, Query(max_length=100, description=(
                      "only the entries of this point, line, polygon, building or check "
                      "point id"))] = None,
                  offset: Annotated[int, Query(ge=0, le=10**9)] = 0,
                  limit: Annotated[int, Query(ge=1, le=1000)] = 100,
                  order: Annotated[Literal["newest", "oldest"], Query(
                      description="newest first (default) or oldest first")] = "newest",
                  ) -> dict[str, Any]:
    return audit_page(svc(request).store, pid, item=item, offset=offset, limit=limit,
                      newest_first=order == "newest")


@router.post("/projects", status_code=201, summary="Create a project")
def create_project(body: m.ProjectCreate, request: Request) -> dict[str, Any]:
    p = svc(request).create_project(**body.model_dump())
    return project_json(p)


@router.get("/projects/{pid}", summary="One project with its counts")
def get_project(pid: PID, request: Request) -> dict[str, Any]:
    s = svc(request).project_summary(pid)
    p = s.pop("project")
    return project_json(p) | {"counts": s}


@router.patch("/projects/{pid}", summary="Change a project; new solving settings re-measure all points")
def patch_project(pid: PID, body: m.ProjectPatch, request: Request) -> dict[str, Any]:
    changes = body.model_dump(exclude_unset=True)
    for key in ("name", "source_crs", "sigma_px"):
        if key in changes and changes[key] is None:
            raise InputError("must not be null", field=key)
    return project_json(svc(request).update_project(pid, changes))


@router.post("/projects/{pid}/resolve", summary="Re-measure every point from its rays")
def remeasure_project(pid: PID, request: Request) -> dict[str, Any]:
    s = svc(request)
    p = s.remeasure_all(pid)
    return project_json(p) | {"counts": {k: v for k, v in s.project_summary(pid).items()
                                         if k != "project"}}


@router.delete("/projects/{pid}", status_code=204, summary="Delete a project and all it holds")
def delete_project(pid: PID, request: Request) -> Response:
    svc(request).delete_project(pid)
    return Response(status_code=204)


@router.get("/projects/{pid}/session", summary="The project as a session JSON document")
def get_session(pid: PID, request: Request) -> dict[str, Any]:
    s = svc(request)
    p = s.get_project(pid)
    return {"source_crs": p.source_crs, "crs": p.crs, "vertical": p.vertical,
            "sigma_px": p.sigma_px,
            "points": [{"id": q.id, "code": q.code, "description": q.description, "rays": q.rays,
                        "measured_by": q.measured_by} for q in s.list_points(pid)],
            "lines": [{"id": f.id, "points": f.point_ids} for f, _ in s.list_features(pid, "line")],
            "polygons": [{"id": f.id, "points": f.point_ids}
                         for f, _ in s.list_features(pid, "polygon")],
            "buildings": [b["spec"] for b in s.list_buildings(pid)]}


@router.post("/projects/{pid}/session", status_code=201,
             summary="Import a session JSON document (points with rays, lines, polygons)")
def import_session(pid: PID, request: Request,
                   body: Annotated[dict[str, Any], Body(description=(
                       "session JSON (README, \"Session JSON\"); points are solved with the project's "
                       "settings; all or nothing"))]) -> dict[str, Any]:
    return {"imported": svc(request).import_session(pid, body)}


# points ----------------------------------------------------------------------------------
@router.get("/projects/{pid}/points", response_model=JSON_OBJECT,
            summary="List points with their solved results")
def list_points(pid: PID, request: Request,
                summary: Annotated[bool, Query(description=(
                    "leave out rays and the full result (record only)"))] = False,
                ) -> dict[str, Any] | Response:
    pts = [point_json(q) for q in svc(request).list_points(pid)]
    if summary:
        for q in pts:
            del q["rays"], q["result"]
    return fast_json({"points": pts})


@router.post("/projects/{pid}/points", status_code=201, response_model=JSON_OBJECT,
             summary="Solve and store a point")
async def create_point(pid: PID, body: m.PointCreate,
                       request: Request) -> dict[str, Any] | Response:
    pool = request.app.state.store_pool  # long-lived threads, warm (gsgeo serve --store-threads)
    if pool is None:
        return await run_in_threadpool(store_point, svc(request), pid, body)
    return await pool.run(store_point, svc(request), pid, body)


def store_point(projects: Projects, pid: str, body: m.PointCreate) -> Response:
    """The work of POST /projects/{pid}/points, on a thread of the store pool."""
    pt = projects.add_point(pid, body.to_input())
    return with_etag(fast_json(point_json(pt), 201), pt.version)


@router.get("/projects/{pid}/points/{point_id}", response_model=JSON_OBJECT,
            summary="One point (ETag: its version)")
def get_point(pid: PID, point_id: ITEM, request: Request) -> dict[str, Any] | Response:
    pt = svc(request).get_point(pid, point_id)
    return with_etag(fast_json(point_json(pt)), pt.version)


@router.patch("/projects/{pid}/points/{point_id}", response_model=JSON_OBJECT,
              summary="Rename, recode, exclude or restore a ray, or replace rays (re-solves)")
def patch_point(pid: PID, point_id: ITEM, body: m.PointPatch, request: Request,
                if_match: IfMatch = None) -> dict[str, Any] | Response:
    changes = {k: v for k, v in body.model_dump(exclude_unset=True).items() if v is not None}
    if body.rays is not None:  # session-JSON rays: their auto / score are kept
        changes["rays"] = [r.model_dump(exclude_none=True) for r in body.rays]
    pt = svc(request).update_point(pid, point_id, changes, if_match_versions(if_match))
    return with_etag(fast_json(point_json(pt)), pt.version)


@router.delete("/projects/{pid}/points/{point_id}", status_code=204, summary="Delete a point")
def delete_point(pid: PID, point_id: ITEM, request: Request,
                 if_match: IfMatch = None) -> Response:
    svc(request).delete_point(pid, point_id, if_match_versions(if_match))
    return Response(status_code=204)


# lines and polygons ------------------------------------------------------------------------
def _feature_routes(kind: str, plural: str) -> None:
    def list_(pid: PID, request: Request) -> dict[str, Any]:
        return {plural: [feature_json(f, ms) for f, ms in svc(request).list_features(pid, kind)]}

    def create(pid: PID, body: m.FeatureCreate, request: Request,
               response: Response) -> dict[str, Any]:
        s = svc(request)
        f = s.add_feature(pid, kind, body.model_dump())
        f, measures = s.get_feature(pid, kind, f.id)
        with_etag(response, f.version)
        return feature_json(f, measures)

    def get(pid: PID, fid: ITEM, request: Request, response: Response) -> dict[str, Any]:
        f, measures = svc(request).get_feature(pid, kind, fid)
        with_etag(response, f.version)
        return feature_json(f, measures)

    def patch(pid: PID, fid: ITEM, body: m.FeaturePatch, request: Request, response: Response,
              if_match: IfMatch = None) -> dict[str, Any]:
        s = svc(request)
        changes = {k: v for k, v in body.model_dump(exclude_unset=True).items() if v is not None}
        f = s.update_feature(pid, kind, fid, changes, if_match_versions(if_match))
        f, measures = s.get_feature(pid, kind, f.id)
        with_etag(response, f.version)
        return feature_json(f, measures)

    def delete(pid: PID, fid: ITEM, request: Request, if_match: IfMatch = None) -> Response:
        svc(request).delete_feature(pid, kind, fid, if_match_versions(if_match))
        return Response(status_code=204)

    what = "lengths" if kind == "line" else "area and perimeter"
    base = f"/projects/{{pid}}/{plural}"
    router.add_api_route(base, list_, methods=["GET"], summary=f"List {plural} with {what}",
                         operation_id=f"list_{plural}")
    router.add_api_route(base, create, methods=["POST"], status_code=201,
                         summary=f"Create a {kind} from point ids", operation_id=f"create_{kind}")
    router.add_api_route(base + "/{fid}", get, methods=["GET"],
                         summary=f"One {kind} (ETag: its version)",
                         operation_id=f"get_{kind}")
    router.add_api_route(base + "/{fid}", patch, methods=["PATCH"],
                         summary=f"Change a {kind}", operation_id=f"patch_{kind}")
    router.add_api_route(base + "/{fid}", delete, methods=["DELETE"], status_code=204,
                         summary=f"Delete a {kind}", operation_id=f"delete_{kind}")


_feature_routes("line", "lines")
_feature_routes("polygon", "polygons")


# buildings ---------------------------------------------------------------------------------
@router.get("/projects/{pid}/buildings", response_model=JSON_OBJECT,
            summary="List LoD2 buildings with their models (built from the points now)")
def list_buildings(pid: PID, request: Request) -> dict[str, Any] | Response:
    return fast_json({"buildings": svc(request).list_buildings(pid)})


@router.post("/projects/{pid}/buildings", status_code=201, response_model=JSON_OBJECT,
             summary="Create an LoD2 building from roof faces of measured points")
def create_building(pid: PID, body: m.BuildingCreate,
                    request: Request) -> dict[str, Any] | Response:
    """The answer: the model (adjusted vertices in the grid, surfaces, adjustment, measures,
    warnings) and ``vertices_ecef`` (ECEF metres, in the order of ``vertices``)."""
    b = svc(request).add_building(pid, body.model_dump(exclude_unset=True))
    return with_etag(fast_json(b, 201), b["version"])


@router.get("/projects/{pid}/buildings/{bid}", response_model=JSON_OBJECT,
            summary="One building with its model (ETag: its version)")
def get_building(pid: PID, bid: ITEM, request: Request) -> dict[str, Any] | Response:
    b = svc(request).get_building(pid, bid)
    return with_etag(fast_json(b), b["version"])


@router.patch("/projects/{pid}/buildings/{bid}", response_model=JSON_OBJECT,
              summary="Change a building (roofs, ground, attributes, id); rebuilds it")
def patch_building(pid: PID, bid: ITEM, body: m.BuildingPatch, request: Request,
                   if_match: IfMatch = None) -> dict[str, Any] | Response:
    changes = body.model_dump(exclude_unset=True)
    for key, value in changes.items():
        if value is None:
            raise InputError("must not be null", field=key)
    b = svc(request).update_building(pid, bid, changes, if_match_versions(if_match))
    return with_etag(fast_json(b), b["version"])


@router.delete("/projects/{pid}/buildings/{bid}", status_code=204, summary="Delete a building")
def delete_building(pid: PID, bid: ITEM, request: Request,
                    if_match: IfMatch = None) -> Response:
    svc(request).delete_building(pid, bid, if_match_versions(if_match))
    return Response(status_code=204)


# check points ------------------------------------------------------------------------------
def check_point_json(c: CheckPointRecord) -> dict[str, Any]:
    return {"id": c.id, "x": c.x, "y": c.y, "z": c.z, "crs": c.crs, "role": c.role,
            "sigma_h": c.sigma_h, "sigma_v": c.sigma_v, "source": c.source,
            "description": c.description, "created_at": c.created_at}


@router.get("/projects/{pid}/checkpoints", summary="List check points (as given, in their CRS)")
def list_check_points(pid: PID, request: Request) -> dict[str, Any]:
    """Each point as given, with ``ecef``: its position (m) in ECEF on the project's source
    CRS, the frame a georeferenced scene is drawn in (null without a height)."""
    return {"check_points": [check_point_json(c) | {"ecef": e}
                             for c, e in svc(request).check_points_ecef(pid)]}


@router.post("/projects/{pid}/checkpoints", status_code=201,
             summary="Add check points given as JSON in a stated CRS")
def add_check_points(pid: PID, body: m.CheckPointsCreate, request: Request) -> dict[str, Any]:
    rows = [CheckPointRow(c.id, c.x, c.y, c.z, c.sigma_h, c.sigma_v, c.description.strip())
            for c in body.points]
    n = svc(request).add_check_points(pid, rows, body.crs, role=body.role, replace=body.replace,
                                      overwrite=body.overwrite, source=body.source)
    return {"imported": n}


@router.post("/projects/{pid}/checkpoints/import", status_code=201,
             summary="Import check points from a CSV, GeoJSON or GeoPackage file")
def import_check_points(
    pid: PID, request: Request,
    file: Annotated[UploadFile, File(description="CSV, GeoJSON or GeoPackage")],
    crs: Annotated[str | None, Form(max_length=20000, description=(
        "CRS of the coordinates; GeoPackage: defaults to the layer's CRS, GeoJSON: EPSG:4979"))] = None,
    format: Annotated[Literal["csv", "geojson", "gpkg"] | None, Form(
        description="file format; from the file name when absent")] = None,
    role: Annotated[Literal["check", "control"], Form()] = "check",
    replace: Annotated[bool, Form(description="drop the project's existing check points first")] = False,
    overwrite: Annotated[list[str] | None, Form(description=(
        "ids of stored check points this import may replace (the field repeated); any other "
        "id already stored is refused with 409"))] = None,
) -> dict[str, Any]:
    n, crs, fmt = svc(request).import_check_point_file(
        pid, file.file.read(), file.filename, crs=crs, fmt=format, role=role, replace=replace,
        overwrite=overwrite or ())
    return {"imported": n, "crs": crs, "format": fmt}


#: Endpoints that take files: their bodies may reach ServerConfig.max_upload, not max_body.
UPLOAD_ENDPOINTS = frozenset({import_check_points})


@router.delete("/projects/{pid}/checkpoints", summary="Delete all check points of a project")
def delete_check_points(pid: PID, request: Request) -> dict[str, Any]:
    return {"deleted": svc(request).delete_all_check_points(pid)}


@router.delete("/projects/{pid}/checkpoints/{cid}", status_code=204,
               summary="Delete one check point")
def delete_check_point(pid: PID, cid: ITEM, request: Request) -> Response:
    svc(request).delete_check_point(pid, cid)
    return Response(status_code=204)


@router.post("/projects/{pid}/locate",
             summary="Points the viewer shows (rendered ECEF) in the project's grid: E, N, H")
def locate(pid: PID, body: m.LocateRequest, request: Request) -> dict[str, Any]:
    return svc(request).locate(pid, body.points, body.model_matrix)


@router.get("/projects/{pid}/accuracy",
            summary="Measured points against check points: dE dN dH, RMSE, ME, SD, counts")
def accuracy(pid: PID, request: Request,
             role: Annotated[Literal["check", "control"], Query()] = "check") -> dict[str, Any]:
    return svc(request).accuracy(pid, role)


# georeference ----------------------------------------------------------------------------------
@router.get("/projects/{pid}/georeference",
            summary="The scene's georeference: version, history, the applied fit, control")
def georeference_status(pid: PID, request: Request) -> dict[str, Any]:
    return svc(request).georeference_status(pid)


@router.post("/projects/{pid}/georeference",
             summary="Fit the scene's georeference from the measured control (apply: write it)")
def georeference(pid: PID, body: m.GeoreferenceRequest, request: Request) -> dict[str, Any]:
    from gsgeo.georef.scale import Distance

    distances = None if body.scale_only is None else [
        Distance(d.from_, d.to, d.distance, d.sigma) for d in body.scale_only.distances]
    return svc(request).georeference(pid, exclude=body.exclude, apply=body.apply,
                                     accept_outliers=body.accept_outliers, distances=distances)


@router.post("/projects/{pid}/georeference/undo",
             summary="Restore the scene's previous georeference and re-measure its points")
def undo_georeference(pid: PID, request: Request) -> dict[str, Any]:
    return svc(request).undo_georeference(pid)


# export ----------------------------------------------------------------------------------------
@router.get("/projects/{pid}/export",
            summary="Download points, lines, polygons and buildings (or buildings as CityJSON)",
            response_class=FileResponse,
            responses={200: {"content": {t: {} for t in EXPORT_TYPES.values()},
                             "description": "the file; header X-Gsgeo-Skipped lists features "
                                            "left out (failed points, invalid rings)"}})
def export(pid: PID, request: Request,
           format: Annotated[Literal["gpkg", "geojson", "geojson-grid", "csv", "cityjson"], Query(
               description="gpkg, geojson (RFC 7946), geojson-grid (legacy, grid "
                           "coordinates), csv or cityjson (the buildings, CityJSON 2.0)")] = "gpkg",
           crs: Annotated[str | None, Query(max_length=20000, description=(
               "grid CRS; the project's when absent (another CRS re-measures from the rays)"))]
           = None,
           ) -> FileResponse:
    from gsgeo.service.exporting import export_project  # the writers load on first export

    tmpdir = Path(tempfile.mkdtemp(prefix="gsgeo-export-"))
    try:
        path, skipped = export_project(svc(request), pid, tmpdir, format, crs)
    except BaseException:
        shutil.rmtree(tmpdir, ignore_errors=True)
        raise
    headers = {"X-Gsgeo-Skipped": "; ".join(skipped).encode("ascii", "replace").decode()[:2000]} \
        if skipped else None
    return FileResponse(path, media_type=EXPORT_TYPES[format], filename=path.name,
                        headers=headers,
                        background=BackgroundTask(shutil.rmtree, tmpdir, ignore_errors=True))
