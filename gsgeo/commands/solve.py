"""`gsgeo solve SESSION.json`: intersect the rays of every point in a session.

With a grid CRS (``--crs`` or the session's ``crs``) every point goes through
gsgeo.session.measure_session (gsgeo.measure.measure_points) and is printed as
easting, northing, height with sigmas and the PROJ operation used; without one the points
are printed in the rays' own frame.

A session's LoD2 buildings (roof faces of its points, gsgeo.buildings) are built from the
grid results; ``-o OUT.city.json`` (or ``--export-format cityjson``) writes them as CityJSON
2.0, and a GeoPackage export holds their surfaces as a layer. A building that names a point
the session does not have, or that cannot be built, stops the command (exit 2) before any file
is written.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from gsgeo import limits
from gsgeo.commands.argtypes import number
from gsgeo.errors import GsgeoError, InputError
from gsgeo.export.atomic import atomic_path, check_target
from gsgeo.export.writer import FORMATS as EXPORT_FORMATS
from gsgeo.export.writer import format_for, write_session_results
from gsgeo.measure import Measurement, MeasurementFailure
from gsgeo.service.buildings import building_model, dtm_beside, reference_crs
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
    p.add_argument("--sigma-px", type=number, default=None,
                   help="a-priori aiming precision in pixels, "
                        f"{limits.SIGMA_PX_MIN:g} to {limits.SIGMA_PX_MAX:g} "
                        "(overrides the session's sigma_px)")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("-o", "--output", default=None,
                   metavar="OUT.gpkg|OUT.geojson|OUT.csv|OUT.city.json",
                   help="also export points, rays, lines, polygons and buildings (format from "
                        "the suffix; .city.json: the buildings as CityJSON 2.0; needs a grid "
                        "CRS); written atomically")
    p.add_argument("--export-format", default=None, choices=(*EXPORT_FORMATS, CITYJSON),
                   help="override the suffix; geojson-grid = legacy grid GeoJSON, not RFC 7946; "
                        "cityjson = the session's buildings as CityJSON 2.0")
    p.set_defaults(run=run)


CITYJSON = "cityjson"
CITYJSON_SUFFIX = ".city.json"


def _plain(value: object) -> object:
    """JSON of numpy values in a building's dict (json.dump's default)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"not JSON: {type(value).__name__}")


def solve_session(session: Session) -> list[dict]:
    """Solve every point; a point that cannot be solved gets an 'error' entry instead."""
    out = []
    for pt in session.points:
        entry: dict = {"id": pt.id, "code": pt.code, "description": pt.description,
                       "n_rays": len(pt.rays)}
        try:
            rays = pt.to_rays()
            res = intersect(rays.origins, rays.directions, ifov=rays.angular_ifov(),
                            sigma_px=session.sigma_px, auto=rays.auto)
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


def is_cityjson(path: str, fmt: str | None) -> bool:
    """Whether the export is CityJSON: ``--export-format cityjson``, or a name ending in
    .city.json without a format given."""
    if fmt is not None:
        return str(fmt).lower().lstrip(".") == CITYJSON
    return Path(path).name.lower().endswith(CITYJSON_SUFFIX)


def check_output(path: str, fmt: str | None) -> Path:
    """The export target, checked before anything is solved: a known format (suffix or
    --export-format), an existing writable directory, and not a directory itself."""
    if not is_cityjson(path, fmt):
        format_for(path, fmt)
    target = check_target(path)
    parent = target.parent if str(target.parent) else Path(".")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"cannot write {target}: the directory {parent} is not writable")
    return target


def check_buildings(session: Session) -> None:
    """Every point a building of the session names is a point of the session; InputError
    naming the building, the face and the point otherwise (before anything is solved)."""
    known = {p.id for p in session.points}
    for i, b in enumerate(session.buildings):
        at = f"buildings[{i}]"
        for name, rings in (("roofs", b.roofs), ("walls", b.walls)):
            for k, ring in enumerate(rings):
                for j, q in enumerate(ring):
                    if q not in known:
                        raise InputError(f"building '{b.id}': point '{q}' is not a point of "
                                         "the session", field=f"{at}.{name}[{k}][{j}]")
        if b.ground.point_id is not None and b.ground.point_id not in known:
            raise InputError(f"building '{b.id}': ground point '{b.ground.point_id}' is not "
                             "a point of the session", field=f"{at}.ground")


def build_session_buildings(session: Session, results: list, crs: str, vertical: str | None,
                            session_file: Path) -> list:
    """The models of the session's buildings from the grid results (a DTM is read relative to
    the session file); the first that cannot be built raises, naming it."""
    records = {m.point_id: (m.record() if isinstance(m, Measurement) else None)
               for m in results}
    models = []
    for i, spec in enumerate(session.buildings):
        try:
            models.append(building_model(spec, records, crs, vertical, dtm_beside(session_file)))
        except GsgeoError as exc:
            err = exc.within(f"buildings[{i}]")  # a copy: its problem names the building
            err.problem = f"building '{spec.id}': {err.problem}"
            raise err from None
        except (ValueError, ArithmeticError) as exc:  # numbers the maths cannot take
            raise InputError(f"building '{spec.id}' cannot be built: {exc}",
                             field=f"buildings[{i}]") from None
    return models


def _measure(ms: dict, key: str, unit: str = "") -> str:
    """'value ± sigma unit' of a building's measure (3 decimals), '-' when unknown."""
    v, s = ms.get(key), ms.get(f"sigma_{key}")
    if v is None:
        return "-"
    return (f"{v:.3f}" + ("" if s is None else f" ± {s:.3f}") + (f" {unit}" if unit else ""))


def _building_lines(models: list) -> list[str]:
    """One line per building (roof type, volume, footprint, eaves and ridge H); volumes m³,
    areas m², heights in the CRS's vertical units."""
    lines = []
    for b in models:
        ms = b.measures
        lines.append(f"building {b.id}: {ms.get('roof_type', '?')} roof, volume "
                     f"{_measure(ms, 'volume', 'm³')}, footprint "
                     f"{_measure(ms, 'footprint_area', 'm²')}, eaves H "
                     f"{_measure(ms, 'eaves_height')}, ridge H {_measure(ms, 'ridge_height')}")
    return lines


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
    check_buildings(session)
    if getattr(args, "output", None):
        if not crs:
            raise InputError("-o/--output needs a grid CRS: give --crs (e.g. EPSG:27700)")
        check_output(args.output, getattr(args, "export_format", None))
        if is_cityjson(args.output, getattr(args, "export_format", None)) \
                and not session.buildings:
            raise InputError("the session has no buildings to write as CityJSON",
                             source=str(args.session))
    if crs:
        return _run_grid(args, session, crs)
    if getattr(args, "vertical", None) or getattr(args, "geoid", None):
        raise InputError("--vertical / --geoid need a grid CRS: give --crs (e.g. EPSG:27700)")
    if session.buildings:
        print("gsgeo solve: warning: buildings are built in a grid CRS only; give --crs "
              "(e.g. EPSG:27700)", file=sys.stderr)
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
    models = build_session_buildings(session, results, crs, args.vertical,
                                     Path(args.session)) if session.buildings else []
    table, warnings = _grid_table(results)
    if args.json:
        doc: dict = {"points": [m.to_dict() for m in results]}
        if models:
            doc["buildings"] = [b.to_dict() for b in models]
        sys.stdout.write(json.dumps(doc, indent=2, default=_plain))
        sys.stdout.write("\n")
    else:
        print("\n".join([table, *_building_lines(models)]))
    warnings += [f"building {b.id}: {w}" for b in models for w in b.warnings]
    for w in warnings:
        print(f"gsgeo solve: warning: {w}", file=sys.stderr)
    if getattr(args, "output", None):
        if is_cityjson(args.output, args.export_format):
            from gsgeo.buildings.cityjson import city_json_bytes, reference_system_uri

            data = city_json_bytes(models, reference_system_uri(reference_crs(
                crs, args.vertical)))
            with atomic_path(check_target(args.output)) as tmp:
                tmp.write_bytes(data)
            out = Path(args.output)
        else:
            out = write_session_results(args.output, results, session, fmt=args.export_format,
                                        buildings=models)
        print(f"gsgeo solve: wrote {out}", file=sys.stderr)
    failed = [m.point_id for m in results if isinstance(m, MeasurementFailure)]
    if failed:
        print(f"gsgeo solve: {len(failed)} point(s) could not be solved: {', '.join(failed)}",
              file=sys.stderr)
        return 2
    return 0
