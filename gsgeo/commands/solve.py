"""`gsgeo solve SESSION.json`: intersect the rays of every point in a session.

With a grid CRS (``--crs`` or the session's ``crs``) every point goes through
gsgeo.session.measure_session (gsgeo.measure.measure_points) and is printed as
easting, northing, height with sigmas and the PROJ operation used; without one the points
are printed in the rays' own frame.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from gsgeo import limits
from gsgeo.errors import GsgeoError, InputError
from gsgeo.export.atomic import check_target
from gsgeo.export.writer import FORMATS as EXPORT_FORMATS
from gsgeo.export.writer import format_for, write_session_results
from gsgeo.measure import MeasurementFailure
from gsgeo.session import Session, load_session, measure_session
from gsgeo.solve import SCALE_95_1D, intersect


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "solve",
        help="intersect the rays of a session JSON file",
        description="Intersect the rays of every point in a session JSON file by least squares.",
    )
    p.add_argument("session", help="session JSON file (README, 'Session JSON')")
    p.add_argument("--crs", default=None,
                   help="projected grid CRS for the output, e.g. EPSG:27700 (overrides the "
                        "session's crs); a compound CRS such as EPSG:27700+5701 brings its heights")
    vg = p.add_mutually_exclusive_group()
    vg.add_argument("--vertical", default=None,
                    help="vertical CRS for orthometric heights, e.g. EPSG:5701; needs its geoid "
                         "grid in PROJ's data directory (never PROJ's silent H = h)")
    vg.add_argument("--geoid", default=None, metavar="FILE.tif",
                    help="geoid undulation raster (metres; GeoTIFF or .gtx): H = h - N")
    p.add_argument("--source-crs", default=None,
                   help="geocentric CRS the scene is georeferenced in (default the session's, "
                        "EPSG:4978 WGS 84; e.g. EPSG:4936 ETRS89 for a pure conversion)")
    p.add_argument("--sigma-px", type=float, default=None,
                   help="a-priori aiming precision in pixels, "
                        f"{limits.SIGMA_PX_MIN:g} to {limits.SIGMA_PX_MAX:g} "
                        "(overrides the session's sigma_px)")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("-o", "--output", default=None, metavar="OUT.gpkg|OUT.geojson|OUT.csv",
                   help="also export points, rays, lines and polygons (format from the suffix; "
                        "needs a grid CRS); written atomically")
    p.add_argument("--export-format", default=None, choices=EXPORT_FORMATS,
                   help="override the suffix; geojson-grid = legacy grid GeoJSON, not RFC 7946")
    p.set_defaults(run=run)


def solve_session(session: Session) -> list[dict]:
    """Solve every point; a point that cannot be solved gets an 'error' entry instead."""
    out = []
    for pt in session.points:
        entry: dict = {"id": pt.id, "code": pt.code, "description": pt.description,
                       "n_rays": len(pt.rays)}
        try:
            rays = pt.to_rays()
            res = intersect(rays.origins, rays.directions, ifov=rays.angular_ifov(),
                            sigma_px=session.sigma_px)
        except GsgeoError as exc:
            entry["error"] = str(exc)
        else:
            entry.update(res.to_dict())
            entry["frame"] = "rays' own Cartesian frame (metres)"
        out.append(entry)
    return out


def _table(results: list[dict]) -> str:
    head = (f"{'id':<10} {'X':>15} {'Y':>15} {'Z':>15} {'sX':>7} {'sY':>7} {'sZ':>7} "
            f"{'sigma0':>7} {'N':>3} {'angle':>6}  flagged")
    lines = [head, "-" * len(head)]
    notes = []
    for r in results:
        if "error" in r:
            lines.append(f"{r['id']:<10} not solved: {r['error']}")
            continue
        x, s = r["point"], r["sigmas"]
        flagged = ",".join(str(i + 1) for i, f in enumerate(r["outliers"]) if f) or "-"
        lines.append(
            f"{r['id']:<10} {x[0]:15.4f} {x[1]:15.4f} {x[2]:15.4f} "
            f"{s[0]:7.4f} {s[1]:7.4f} {s[2]:7.4f} {r['sigma0']:7.3f} {r['n_rays']:3d} "
            f"{r['max_angle_deg']:6.1f}  {flagged}"
        )
        notes += [f"{r['id']}: {w}" for w in r["warnings"]]
    lines.append("")
    lines.append("Coordinates in metres in the rays' own frame; sigmas 1-sigma "
                 f"(x {SCALE_95_1D:.2f} for 95 %); angle = largest angle between rays, degrees.")
    lines += notes
    return "\n".join(lines)


def _grid_table(results: list) -> tuple[str, list[str]]:
    """Table of grid results and the (deduplicated) warnings to print."""
    head = (f"{'id':<10} {'Easting':>13} {'Northing':>13} {'Height':>10} {'sE':>7} {'sN':>7} "
            f"{'sH':>7} {'ell95':>7} {'sigma0':>7} {'N':>3} {'angle':>6}  flagged")
    lines = [head, "-" * len(head)]
    warnings: list[str] = []
    first = None
    for m in results:
        if isinstance(m, MeasurementFailure):
            lines.append(f"{m.point_id:<10} not solved: {m.error}")
            continue
        r = m.record()
        first = first or r
        flagged = ",".join(str(i + 1) for i, f in enumerate(m.outliers) if f) or "-"
        excl = ",".join(str(i + 1) for i, x in enumerate(m.excluded) if x)
        if excl:
            flagged += f" (excluded {excl})"
        lines.append(
            f"{m.point_id:<10} {r['easting']:13.4f} {r['northing']:13.4f} {r['height']:10.4f} "
            f"{r['sigma_e']:7.4f} {r['sigma_n']:7.4f} {r['sigma_h']:7.4f} "
            f"{r['ellipse_major_95']:7.4f} {r['sigma0']:7.3f} {r['n_rays']:3d} "
            f"{r['max_angle_deg']:6.1f}  {flagged}"
        )
        for w in m.warnings:
            if w not in warnings:
                warnings.append(w)
    lines.append("")
    if first is not None:
        acc = first["operation_accuracy_m"]
        acc_text = "unknown accuracy" if acc is None else (
            "exact conversion" if acc == 0 else f"accuracy {acc:g} m")
        lines.append(f"CRS {first['crs']}; heights {first['height_type']}: {first['vertical_datum']}")
        lines.append(f"operation: {first['operation']} ({acc_text})")
    lines.append("E, N, H in the CRS's units; sigmas 1-sigma in metres "
                 f"(x {SCALE_95_1D:.2f} for 95 %); ell95 = semi-major axis of the 95 % "
                 "horizontal ellipse; angle = largest angle between rays, degrees.")
    return "\n".join(lines), warnings


def check_output(path: str, fmt: str | None) -> Path:
    """The export target, checked before anything is solved: a known format (suffix or
    --export-format), an existing writable directory, and not a directory itself."""
    format_for(path, fmt)
    target = check_target(path)
    parent = target.parent if str(target.parent) else Path(".")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"cannot write {target}: the directory {parent} is not writable")
    return target


def run(args: argparse.Namespace) -> int:
    sigma_px = None if args.sigma_px is None else limits.sigma_px(args.sigma_px, "--sigma-px")
    session = load_session(args.session)
    if sigma_px is not None:
        session.sigma_px = sigma_px
    if not session.points:
        raise InputError("the session has no points", source=str(args.session))
    crs = getattr(args, "crs", None) or session.crs
    geoid = getattr(args, "geoid", None)
    if geoid and not Path(geoid).is_file():  # once, before solving, not once per point
        raise InputError(f"--geoid {geoid}: "
                         + ("is a directory" if Path(geoid).is_dir() else "no such file"))
    if getattr(args, "output", None):
        if not crs:
            raise InputError("-o/--output needs a grid CRS: give --crs (e.g. EPSG:27700)")
        check_output(args.output, getattr(args, "export_format", None))
    if crs:
        return _run_grid(args, session, crs)
    if getattr(args, "vertical", None) or getattr(args, "geoid", None):
        raise InputError("--vertical / --geoid need a grid CRS: give --crs (e.g. EPSG:27700)")
    results = solve_session(session)
    if args.json:
        json.dump({"points": results}, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(_table(results))
    failed = [r["id"] for r in results if "error" in r]
    if failed:
        print(f"gsgeo solve: {len(failed)} point(s) could not be solved: {', '.join(failed)}",
              file=sys.stderr)
        return 2
    return 0


def _run_grid(args: argparse.Namespace, session: Session, crs: str) -> int:
    results = measure_session(session, crs=crs, vertical=args.vertical, geoid=args.geoid,
                              source_crs=args.source_crs, sigma_px=session.sigma_px)
    table, warnings = _grid_table(results)
    if args.json:
        json.dump({"points": [m.to_dict() for m in results]}, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(table)
    for w in warnings:
        print(f"gsgeo solve: warning: {w}", file=sys.stderr)
    if getattr(args, "output", None):
        out = write_session_results(args.output, results, session, fmt=args.export_format)
        print(f"gsgeo solve: wrote {out}", file=sys.stderr)
    failed = [m.point_id for m in results if isinstance(m, MeasurementFailure)]
    if failed:
        print(f"gsgeo solve: {len(failed)} point(s) could not be solved: {', '.join(failed)}",
              file=sys.stderr)
        return 2
    return 0
