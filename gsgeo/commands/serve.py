"""`gsgeo serve`: the web viewer, the scenes and the JSON API in one process."""

from __future__ import annotations

import argparse
import os
import secrets
import sys
from pathlib import Path

from gsgeo.commands.argtypes import integer
from gsgeo.errors import InputError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="serve the web viewer, scenes and the JSON API",
        description="Serve the web viewer at /, scenes from DATA/scenes/<name>/ at "
                    "/scenes/<name>/, the JSON API under /api (OpenAPI at /docs). Projects "
                    "are kept in DATA/gsgeo.sqlite, or with --store in a PostgreSQL + PostGIS "
                    "database.",
    )
    p.add_argument("--data", default="gsgeo-data", metavar="DIR",
                   help="data directory with scenes/ and the project store "
                        "(default: ./gsgeo-data, as for gsgeo demo)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default 127.0.0.1; any other address requires a "
                        "token: GSGEO_TOKEN or one generated and printed at start)")
    p.add_argument("--port", type=integer, default=8000, help="port (default 8000)")
    p.add_argument("--web", default=None, metavar="DIR",
                   help="web client directory (default: the repository's web/)")
    p.add_argument("--workers", type=integer, default=1,
                   help="worker processes (default 1; more use more CPU cores, sharing the "
                        "SQLite store)")
    p.add_argument("--solver-threads", type=integer, default=1, metavar="N",
                   help="threads (per worker process) that run POST /api/intersect (default 1; "
                        "they keep their PROJ objects for the server's lifetime)")
    p.add_argument("--store-threads", type=integer, default=4, metavar="N",
                   help="threads (per worker process) that store new points, POST "
                        "/api/projects/{pid}/points (default 4; kept warm for the server's "
                        "lifetime; 0: FastAPI's pool, which starts threads on demand)")
    p.add_argument("--log-level", default="warning",
                   choices=["critical", "error", "warning", "info", "debug"])
    p.add_argument("--store", default=None, metavar="URL",
                   help="keep projects in a PostgreSQL + PostGIS database, "
                        "postgresql://USER[:PASSWORD]@HOST:PORT/DATABASE, which several servers "
                        "may share (default: $GSGEO_STORE, else DATA/gsgeo.sqlite)")
    p.add_argument("--scenes", default=None, metavar="URL",
                   help="http(s) URL of a static host or object store holding a copy of the "
                        "scene folders: the viewer fetches the tiles of DATA/scenes/<name> from "
                        "URL/<name>/ (the host must allow the viewer's origin: CORS); "
                        "tileset.json, with the georeference, is still served from DATA")
    p.add_argument("--scene-url", action="append", default=[], metavar="NAME=URL",
                   help="the folder URL of one scene's tiles (overrides --scenes for it; "
                        "repeatable)")
    p.set_defaults(run=run)


def resolve_token(host: str, environ: dict | None = None) -> tuple[str | None, bool]:
    """(token, generated): GSGEO_TOKEN when set; off loopback a fresh one; else none.

    Loopback means every address ``host`` resolves to is a loopback address
    (gsgeo.server.hosts); a name that does not resolve is not loopback."""
    from gsgeo.server.hosts import is_loopback

    env = os.environ if environ is None else environ
    token = (env.get("GSGEO_TOKEN") or "").strip() or None
    if token is None and not is_loopback(host):
        return secrets.token_urlsafe(24), True
    return token, False


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from gsgeo.server.app import CONFIG_ENV, ServerConfig, config_to_env, create_app

    if not 0 <= args.port <= 65535:
        raise InputError(f"--port must be between 0 and 65535, got {args.port}")
    data = Path(args.data)
    if data.exists() and not data.is_dir():
        raise InputError(f"--data {data}: is not a directory")
    from gsgeo.server.hosts import resolved_addresses
    from gsgeo.server.scenehosts import parse_scene_url, scene_hosts

    # callers such as `gsgeo demo` may leave these out; a bad URL exits 2 before anything starts
    scene_urls = dict(parse_scene_url(s) for s in getattr(args, "scene_url", None) or [])
    hosts = scene_hosts(getattr(args, "scenes", None), scene_urls)
    if not resolved_addresses(args.host):
        raise InputError(f"--host {args.host}: does not resolve to an address to bind")
    token, generated = resolve_token(args.host)
    log_level = getattr(args, "log_level", "warning")
    if generated:
        print(f"gsgeo serve: bound to {args.host}: API token {token}\n"
              f"  send it as 'Authorization: Bearer {token}' or open "
              f"http://{args.host}:{args.port}/#token={token}", file=sys.stderr, flush=True)
    workers = getattr(args, "workers", 1)  # callers such as `gsgeo demo` may leave it out
    if not 1 <= workers <= 64:
        raise InputError(f"--workers must be between 1 and 64, got {workers}")
    solver_threads = getattr(args, "solver_threads", 1)
    if not 1 <= solver_threads <= 64:
        raise InputError(f"--solver-threads must be between 1 and 64, got {solver_threads}")
    store_threads = getattr(args, "store_threads", 4)
    if not 0 <= store_threads <= 64:
        raise InputError(f"--store-threads must be between 0 and 64, got {store_threads}")
    from gsgeo.store import STORE_ENV

    # callers such as `gsgeo demo` may leave it out; a bad URL or an unreachable server is a
    # StoreError (exit 2) raised by create_app before anything is served
    store_url = getattr(args, "store", None) or os.environ.get(STORE_ENV, "").strip() or None
    config = ServerConfig(data_dir=data, host=args.host, port=args.port, token=token,
                          store_url=store_url,
                          web_dir=Path(args.web) if args.web else None,
                          solver_threads=solver_threads, store_threads=store_threads,
                          scenes_url=hosts.base,
                          scene_urls=dict(hosts.folders))
    app = create_app(config)  # opens (and migrates) the store before accepting requests
    common = {"host": args.host, "port": args.port, "log_level": log_level,
              "server_header": False, "limit_concurrency": 1000, "timeout_keep_alive": 30}
    print(f"gsgeo serve: data {data.resolve()}; http://{args.host}:{args.port}/ "
          "(API docs at /docs)", file=sys.stderr, flush=True)
    for where in ([hosts.base + "<name>/"] if hosts.base else []) + list(hosts.folders.values()):
        print(f"gsgeo serve: scene tiles from {where}: that host must answer "
              f"'Access-Control-Allow-Origin: http://{args.host}:{args.port}' (or *)",
              file=sys.stderr, flush=True)
    if workers == 1:
        uvicorn.Server(uvicorn.Config(app, **common)).run()
    else:
        os.environ[CONFIG_ENV] = config_to_env(config)
        uvicorn.run("gsgeo.server.app:app_from_env", factory=True, workers=workers,
                    **common)
    return 0
