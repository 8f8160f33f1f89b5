"""The FastAPI application: web client at /, Cesium at /cesium/, scenes at /scenes/, API at /api.

``create_app(ServerConfig(data_dir=...))`` builds it; ``gsgeo serve`` runs it with uvicorn.
Of the web directory only the app is served (``WEB_FILES`` and ``js/``), not its package
files or node_modules; a known path asked with a method it does not serve gets 405 with
``Allow``.
"""

from __future__ import annotations

import json
import logging
import os
import sqlite3
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, RedirectResponse, Response
from starlette.exceptions import HTTPException as StarletteHTTPException

from gsgeo import __version__
from gsgeo.errors import GsgeoError, InputError
from gsgeo.server.etags import precondition_failed
from gsgeo.server.faults import CatchAll
from gsgeo.server.files import file_response
from gsgeo.server.guard import BodyTooLarge, Guard, MiB
from gsgeo.server.hosts import is_loopback
from gsgeo.server.intersect_pool import IntersectPool
from gsgeo.server.jobs import Busy, JobPool
from gsgeo.server.routing import allowed_methods, body_limiter
from gsgeo.server.scenehosts import hosted_tileset_response, scene_hosts
from gsgeo.server.scenes import SceneFolders
from gsgeo.service import (
    ConflictError,
    NotFoundError,
    PreconditionFailed,
    Store,
    StoreError,
    open_projects,
)

log = logging.getLogger("gsgeo.server")

REPO_WEB = Path(__file__).resolve().parents[2] / "web"
LOOPBACK_HOSTS = {"127.0.0.1", "localhost", "[::1]", "::1"}


@dataclass
class ServerConfig:
    """How the server runs. ``token`` None: no token (only sensible on loopback)."""

    data_dir: Path
    host: str = "127.0.0.1"
    port: int = 8000
    token: str | None = None
    web_dir: Path | None = None  # default: the repository's web/ (its dist/ when built)
    cesium_dir: Path | None = None  # default: web/node_modules/cesium/Build/Cesium
    max_body: int = 4 * MiB
    max_upload: int = 64 * MiB
    solver_threads: int = 1  # long-lived threads for POST /api/intersect (gsgeo.server.intersect_pool)
    # long-lived threads for POST /api/projects/{pid}/points (0: FastAPI's on-demand pool)
    store_threads: int = 4
    # heavy jobs (gsgeo.server.jobs): image matches (/api/match, /api/scenes/{scene}/match)
    # and survey reports at once, and how many more may wait before 503
    image_jobs: int = 2
    image_queue: int = 16
    report_jobs: int = 1
    report_queue: int = 8
    store_url: str | None = None  # postgresql://... (gsgeo.store.open_store); None: DATA/gsgeo.sqlite
    allowed_hosts: set[str] | None = field(default=None)  # None: derived from host
    # Tiles on a static host (gsgeo.server.scenehosts): the base URL of the scene folders,
    # and folder URLs of single scenes (name -> URL). None / empty: tiles from /scenes/.
    scenes_url: str | None = None
    scene_urls: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.data_dir = Path(self.data_dir)
        if self.web_dir is None:
            self.web_dir = REPO_WEB / "dist" if (REPO_WEB / "dist" / "index.html").is_file() \
                else REPO_WEB
        if self.cesium_dir is None:
            self.cesium_dir = REPO_WEB / "node_modules" / "cesium" / "Build" / "Cesium"
            if not self.cesium_dir.is_dir() and (Path(self.web_dir) / "cesium").is_dir():
                self.cesium_dir = Path(self.web_dir) / "cesium"
        if self.allowed_hosts is None and is_loopback(self.host):
            self.allowed_hosts = LOOPBACK_HOSTS | {self.host.lower()}


def _loc(loc: tuple | list) -> str:
    parts = list(loc[1:]) if loc and loc[0] in ("body", "query", "path", "header") else list(loc)
    if not parts:
        return str(loc[0]) if loc else ""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def _error(status: int, message: str, field: str | None = None, detail: Any = None) -> JSONResponse:
    return JSONResponse({"detail": message if detail is None else detail, "message": message,
                         "field": field}, status_code=status)


def _install_error_handlers(app: FastAPI) -> None:
    @app.exception_handler(RequestValidationError)
    async def validation(_req: Request, exc: RequestValidationError) -> JSONResponse:
        errs = exc.errors()
        msgs = []
        for e in errs:
            if e.get("type") == "json_invalid":
                pos = e.get("loc", ("body", "?"))[-1]
                err = (e.get("ctx") or {}).get("error", "")
                e["loc"] = ("body",)
                e["msg"] = f"not valid JSON at character {pos}" + (f": {err}" if err else "")
        for e in errs[:5]:
            where = _loc(e.get("loc", ()))
            msgs.append(f"{where}: {e.get('msg', 'invalid')}" if where else e.get("msg", "invalid"))
        first = _loc(errs[0].get("loc", ())) if errs else None
        detail = [{"loc": list(e.get("loc", ())), "msg": str(e.get("msg", "")),
                   "type": str(e.get("type", ""))} for e in errs]
        return _error(422, "; ".join(msgs) or "invalid request", first or None, detail)

    @app.exception_handler(NotFoundError)
    async def not_found(_req: Request, exc: NotFoundError) -> JSONResponse:
        return _error(404, str(exc))

    @app.exception_handler(ConflictError)
    async def conflict(_req: Request, exc: ConflictError) -> JSONResponse:
        out = _error(409, str(exc), exc.field)
        if exc.ids:  # the stored items the change clashes with, for the client to show
            out = JSONResponse({"detail": str(exc), "message": str(exc), "field": exc.field,
                                "ids": exc.ids}, status_code=409)
        return out

    app.add_exception_handler(PreconditionFailed, precondition_failed)  # 412, a ConflictError

    @app.exception_handler(StoreError)
    async def store_error(_req: Request, exc: StoreError) -> JSONResponse:
        log.error("store error: %s", exc)
        return _error(503, f"the project store is unavailable: {exc}")

    @app.exception_handler(sqlite3.OperationalError)
    async def store_busy(_req: Request, exc: sqlite3.OperationalError) -> JSONResponse:
        log.error("store: %s", exc)
        return _error(503, f"the project store is busy or unavailable ({exc}); try again")

    @app.exception_handler(Busy)
    async def busy(_req: Request, exc: Busy) -> JSONResponse:
        resp = _error(503, str(exc))
        resp.headers["Retry-After"] = str(exc.retry_after)
        return resp

    @app.exception_handler(GsgeoError)
    async def gsgeo_error(_req: Request, exc: GsgeoError) -> JSONResponse:
        return _error(422, str(exc), exc.field)

    @app.exception_handler(BodyTooLarge)
    async def too_large(_req: Request, exc: BodyTooLarge) -> JSONResponse:
        return _error(413, str(exc), "body")

    @app.exception_handler(StarletteHTTPException)
    async def http_error(req: Request, exc: StarletteHTTPException) -> Response:
        if isinstance(exc.__cause__, BodyTooLarge):
            return _error(413, str(exc.__cause__), "body")
        if isinstance(exc.__cause__, GsgeoError):  # a body's text refused where it is parsed
            return _error(422, str(exc.__cause__), exc.__cause__.field)
        msg = exc.detail if isinstance(exc.detail, str) else str(exc.detail)
        status, field = exc.status_code, None
        if status == 400 and "parsing the body" in msg:  # Starlette's words for a bad body
            bad = InputError("cannot be parsed (malformed JSON, not UTF-8, or bad form data)",
                             field="body")
            status, msg, field = 422, str(bad), bad.field
        headers = dict(exc.headers or {})
        if status == 405:  # every method of the path, not only those of the first route
            allow = allowed_methods(app.router.routes, req.scope)
            headers["Allow"] = ", ".join(allow)
            msg = f"method {req.method} is not allowed here; allowed: {', '.join(allow)}"
        resp = _error(status, msg, field)
        resp.headers.update(headers)
        return resp


#: The files of the web directory served at the root, besides index.html and js/.
WEB_FILES = ("style.css", "favicon.svg")
WEB_CACHE = "no-cache"
CESIUM_CACHE = "public, max-age=86400"
SCENE_CACHE = "no-cache"  # tiles revalidate by ETag: a regenerated scene is never stale

PLACEHOLDER = """<!doctype html><html><head><meta charset="utf-8"><title>gsgeo</title></head>
<body><h1>gsgeo {version}</h1><p>The web client is not built (web/index.html is missing).
The API is at <a href="/docs">/docs</a>; scenes are listed at
<a href="/api/scenes">/api/scenes</a>.</p></body></html>"""


def create_app(config: ServerConfig, store: Store | None = None) -> FastAPI:
    """The application; ``store`` defaults to the SQLite store of ``config.data_dir``."""
    hosts = scene_hosts(config.scenes_url, config.scene_urls)  # InputError on a bad URL
    projects = open_projects(config.data_dir, store, config.store_url)  # store_url: None: SQLite
    store = projects.store
    intersect_pool = IntersectPool(config.solver_threads)
    store_pool = IntersectPool(config.store_threads, "gsgeo-store") \
        if config.store_threads else None
    image_jobs = JobPool("image matches", config.image_jobs, config.image_queue)
    report_jobs = JobPool("reports", config.report_jobs, config.report_queue, retry_after=10)

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        from gsgeo.server.api import warm_intersect

        await intersect_pool.warm_up(warm_intersect)
        if store_pool is not None:
            await store_pool.warm_up(warm_intersect)
        yield
        intersect_pool.close()
        image_jobs.close()
        report_jobs.close()
        if store_pool is not None:
            store_pool.close()
        store.close()

    app = FastAPI(title="gsgeo", version=__version__, lifespan=lifespan,
                  description="Survey-grade point measurement in georeferenced 3D Gaussian "
                              "Splatting scenes. Rays in, grid coordinates with covariance out.")
    app.state.config = config
    app.state.store = store
    app.state.intersect_pool = intersect_pool
    app.state.store_pool = store_pool
    app.state.image_jobs = image_jobs
    app.state.report_jobs = report_jobs
    app.state.projects = projects
    _install_error_handlers(app)

    from gsgeo.server.api import router

    app.include_router(router)
    from gsgeo.server.report import router as report_router

    app.include_router(report_router)
    from gsgeo.server.ogc import router as ogc_router

    app.include_router(ogc_router)
    from gsgeo.server.aim import router as aim_router

    app.include_router(aim_router)

    scene_folders = SceneFolders(config.data_dir)
    app.state.scene_hosts = hosts
    # ServerConfig.__post_init__ always sets both folders.
    web_dir, cesium_dir = Path(cast(Path, config.web_dir)), Path(cast(Path, config.cesium_dir))

    # Static files are read in the thread pool (on the event loop they serialised behind each
    # other and halved tile throughput with 8 clients).
    @app.api_route("/scenes/{name}/{rel:path}", methods=["GET", "HEAD"], include_in_schema=False)
    def scene_file(name: str, rel: str, request: Request) -> Response:
        folder = scene_folders.folder(name)
        if folder is None:
            return _error(404, "no such scene")
        tiles_url = hosts.folder(name)
        if rel == "tileset.json" and tiles_url is not None:
            return hosted_tileset_response(request, folder, tiles_url, SCENE_CACHE,
                                           scene_folders.refused())
        return file_response(request, folder, rel, SCENE_CACHE, refuse=scene_folders.refused())

    @app.api_route("/cesium/{rel:path}", methods=["GET", "HEAD"], include_in_schema=False)
    def cesium_file(rel: str, request: Request) -> Response:
        return file_response(request, cesium_dir, rel, CESIUM_CACHE)

    @app.api_route("/", methods=["GET", "HEAD"], include_in_schema=False)
    def index(request: Request) -> Response:
        if (web_dir / "index.html").is_file():
            return file_response(request, web_dir, "index.html", WEB_CACHE)
        return HTMLResponse(PLACEHOLDER.format(version=__version__))

    @app.api_route("/api", methods=["GET"], include_in_schema=False)
    def api_root() -> Response:
        return RedirectResponse("/docs")

    @app.api_route("/index.html", methods=["GET", "HEAD"], include_in_schema=False)
    def index_html(request: Request) -> Response:
        return index(request)

    def web_file(name: str) -> None:
        def serve(request: Request) -> Response:
            return file_response(request, web_dir, name, WEB_CACHE)

        app.add_api_route(f"/{name}", serve, methods=["GET", "HEAD"], include_in_schema=False,
                          name=f"web {name}")

    for name in WEB_FILES:
        web_file(name)

    @app.api_route("/js/{rel:path}", methods=["GET", "HEAD"], include_in_schema=False)
    def js_file(rel: str, request: Request) -> Response:
        return file_response(request, web_dir / "js", rel, WEB_CACHE)

    from gsgeo.server.api import UPLOAD_ENDPOINTS

    # Uploads exist only under /api: the API router's own routes, in order, decide the limit.
    app.add_middleware(Guard, token=config.token, allowed_hosts=config.allowed_hosts,
                       body_limit=body_limiter(router.routes, config.max_body,
                                               config.max_upload, UPLOAD_ENDPOINTS))
    app.add_middleware(CatchAll)  # outermost: also catches what the guard lets through
    return app


CONFIG_ENV = "GSGEO_SERVE_CONFIG"


def config_to_env(config: ServerConfig) -> str:
    """The config as JSON, for worker processes started by uvicorn (``app_from_env``)."""
    return json.dumps({"data_dir": str(config.data_dir), "host": config.host,
                       "port": config.port, "token": config.token,
                       "web_dir": str(config.web_dir), "cesium_dir": str(config.cesium_dir),
                       "max_body": config.max_body, "max_upload": config.max_upload,
                       "solver_threads": config.solver_threads,
                       "store_threads": config.store_threads, "store_url": config.store_url,
                       "scenes_url": config.scenes_url, "scene_urls": config.scene_urls,
                       "allowed_hosts": sorted(config.allowed_hosts)
                       if config.allowed_hosts is not None else None})


def app_from_env() -> FastAPI:
    """Application factory for uvicorn worker processes (``gsgeo serve --workers N``)."""
    doc = json.loads(os.environ[CONFIG_ENV])
    for key in ("data_dir", "web_dir", "cesium_dir"):
        doc[key] = Path(doc[key])
    if doc["allowed_hosts"] is not None:
        doc["allowed_hosts"] = set(doc["allowed_hosts"])
    return create_app(ServerConfig(**doc))


__all__ = ["ServerConfig", "app_from_env", "config_to_env", "create_app"]
