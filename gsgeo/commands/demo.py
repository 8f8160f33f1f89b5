"""`gsgeo demo`: build the demo scene with ground truth, create the demo project, serve it."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from gsgeo.commands.argtypes import integer
from gsgeo.errors import InputError

#: How to measure a marker, in the README's words.
MEASURE_HINT = ("measure      press M, click a marker in 3-5 views from different directions, "
                "press Enter and give the point the marker's id (G1-G4, R1, B1-B6, T1-T5, "
                "S1-S4): the accuracy panel shows dE, dN, dH and the RMSE against the truth; "
                "V flies to a suggested view, A (after the first click) finds the marker in "
                "suggested views by itself")


def local_hint(data: Path) -> str:
    """How to georeference the local variant, in the README's words."""
    from gsgeo.demo.localbuild import CONTROL_IDS

    ids = ", ".join(CONTROL_IDS[:-1]) + f" and {CONTROL_IDS[-1]}"
    return (f"georeference press M, click a control target ({ids}) in 2-3 views, press Enter "
            "and give the point the target's id; with 3 or more measured the Georeference "
            "panel shows the residuals: Apply (or: gsgeo georef --project demo-local --data "
            f"{data} --apply). Then measure check points (G1, B1-B6, T1, T2, T5, S1-S4): "
            "the accuracy panel shows their RMSE")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="build the demo scene with ground truth and serve it (the quickest way in)",
        description="Build a synthetic georeferenced 3DGS scene (Parker's Piece, Cambridge, in "
                    "British National Grid EPSG:27700) with 20 surveyed validation points, "
                    "create the project 'demo' holding them as check points, and serve the "
                    "viewer. Measure a marker, name the point after it (e.g. G1) and the "
                    "accuracy panel shows the difference to the truth.",
    )
    p.add_argument("--data", default="gsgeo-data", metavar="DIR",
                   help="data directory (default: ./gsgeo-data); the scene goes to "
                        "DIR/scenes/demo, the ground truth to DIR/demo/checkpoints.csv")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=integer, default=8000, help="port (default 8000)")
    p.add_argument("--rebuild", action="store_true", help="rebuild the scene even if present")
    p.add_argument("--no-serve", action="store_true",
                   help="build the scene and the project, print where they are, and exit")
    p.add_argument("--local", action="store_true",
                   help="the un-georeferenced variant instead: the same scene in an arbitrary "
                        "local frame (scaled, turned, shifted, as 3DGS trainers leave a scene), "
                        "tiled without georeference to DIR/scenes/demo-local, and the project "
                        "'demo-local' with 6 control and 14 check points to georeference it by")
    p.set_defaults(run=run)


def check_port_free(host: str, port: int) -> None:
    """Raise InputError naming the port when a server listens on `host`:`port` (port 0: any
    free one). The port of a server stopped a moment ago is free: its closed connections
    (TIME_WAIT) do not count, as they do not for the server that binds it next (uvicorn sets
    SO_REUSEADDR)."""
    import socket

    if port == 0:
        return
    try:
        with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((host, port))
    except OSError as exc:
        raise InputError(f"cannot serve on {host}:{port} ({exc.strerror}); another server "
                         "may be running there: pass --port N, or --no-serve") from None


def _remeasured(data: Path, scene: str) -> None:
    """After a (re)build: points measured on the scene before (in a georeference applied to
    it since, say) are solved again in the frame it is built in."""
    from gsgeo.demo.project import remeasure_scene

    n = remeasure_scene(data, scene)
    if n:
        print(f"gsgeo demo: {n} point(s) measured on scene '{scene}' solved again in the "
              "rebuilt scene's frame", file=sys.stderr)


def _build(data: Path, rebuild: bool) -> tuple[str, str]:
    """Build (or reuse) the demo and its project, print where they are; (scene, project id)."""
    from gsgeo.demo.build import build_demo
    from gsgeo.demo.project import PROJECT_ID, ensure_project

    build = build_demo(data, force=rebuild)
    if not build.built:
        print(f"gsgeo demo: using the scene built in {build.tileset}", file=sys.stderr)
    project, n_check = ensure_project(data, build)
    if build.built:
        _remeasured(data, build.tileset.name)
    print(f"demo scene   {build.tileset / 'tileset.json'} ({build.splats:,} splats)")
    print(f"ground truth {build.checkpoints_csv} ({n_check} check points, EPSG:27700, "
          "WGS 84 ellipsoidal heights)")
    print(f"project      '{PROJECT_ID}' in {data.resolve() / 'gsgeo.sqlite'}")
    return build.tileset.name, project.id


def _build_local(data: Path, rebuild: bool) -> tuple[str, str]:
    """Build (or reuse) the local variant and its project, print where they are."""
    from gsgeo.demo.localbuild import build_local_demo
    from gsgeo.demo.project import LOCAL_PROJECT_ID, ensure_local_project

    build = build_local_demo(data, force=rebuild)
    if not build.built:
        print(f"gsgeo demo: using the scene built in {build.tileset}", file=sys.stderr)
    project, n_control, n_check = ensure_local_project(data, build)
    if build.built:
        _remeasured(data, build.tileset.name)
    print(f"local scene  {build.tileset / 'tileset.json'} ({build.splats:,} splats, not "
          "georeferenced: at lat 0, lon 0)")
    print(f"control      {build.control_csv} ({n_control} control points, EPSG:27700, WGS 84 "
          "ellipsoidal heights, with sigma_h/sigma_v)")
    print(f"check points {build.checkpoints_csv} ({n_check} check points)")
    print(f"project      '{LOCAL_PROJECT_ID}' in {data.resolve() / 'gsgeo.sqlite'}")
    return build.tileset.name, project.id


def run(args: argparse.Namespace) -> int:
    if not 0 <= args.port <= 65535:
        raise InputError(f"--port must be between 0 and 65535, got {args.port}")
    if not args.no_serve:
        check_port_free(args.host, args.port)
    data = Path(args.data)
    local = bool(args.local)
    scene_name, pid = (_build_local if local else _build)(data, args.rebuild)
    hint = local_hint(data) if local else MEASURE_HINT
    url = f"http://{args.host}:{args.port}/?scene={scene_name}&project={pid}"
    if args.no_serve:
        where = "".join([f" --host {args.host}" if args.host != "127.0.0.1" else "",
                         f" --port {args.port}" if args.port != 8000 else ""])
        print(f"serve it     gsgeo serve --data {data}{where} and open {url}")
        print(hint)
        return 0
    from gsgeo.commands import serve

    token, generated = serve.resolve_token(args.host)
    if generated and token is not None:
        # off loopback the API needs a token: make the one serve will use now, so that the
        # address printed here opens the viewer (it keeps the token after the first visit)
        os.environ["GSGEO_TOKEN"] = token
        url += f"#token={token}"
    elif token:
        url += "  (the first time with #token=<your GSGEO_TOKEN> at its end)"
    print(f"open         {url}")
    print(hint, flush=True)

    return serve.run(argparse.Namespace(data=str(data), host=args.host, port=args.port, web=None,
                                        log_level="warning"))
