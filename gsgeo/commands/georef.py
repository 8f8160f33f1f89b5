"""`gsgeo georef`: georeference a local scene by control points (or fix its scale alone).

Two sources of measured control: a session JSON file (its points, solved here) with a control
file, or a stored project (``--project PID --data DIR``: its points and its control points,
or ``--control FILE`` instead of the stored ones). ``--apply`` writes the fit into the scene's
tileset.json root transform (for a project: its scene, re-measuring every point of every
project on it in one transaction); ``--undo`` restores the previous georeference.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from gsgeo.commands.argtypes import text as text_arg
from gsgeo.commands.storearg import add_store_argument, store_url
from gsgeo.errors import InputError
from gsgeo.jsontypes import JSONObject
from gsgeo.limits import number_text


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "georef",
        help="georeference a local scene by control points (7-parameter similarity)",
        description="Fit the similarity (scale, rotation, translation) that carries a scene's "
                    "frame onto control points, with blunder tests, check-point RMSE and the "
                    "parameters' sigmas; optionally write it into the scene's tileset.json.")
    p.add_argument("session", nargs="?", default=None,
                   help="session JSON whose points include the measured control (or use "
                        "--project)")
    p.add_argument("--project", default=None, type=text_arg, metavar="PID",
                   help="a stored project (its points and control points) instead of a session")
    p.add_argument("--data", default="gsgeo-data", metavar="DIR",
                   help="data directory of --project (as for gsgeo serve; default gsgeo-data)")
    add_store_argument(p)
    p.add_argument("--control", default=None, metavar="FILE",
                   help="control points (CSV, GeoJSON or GeoPackage; columns id, x/y/z or "
                        "easting/northing/height, optional sigma_h, sigma_v in metres)")
    p.add_argument("--control-crs", default=None, metavar="CRS",
                   help="CRS of --control (default: the file's, EPSG:4979 for GeoJSON)")
    p.add_argument("--check", default=None, metavar="FILE",
                   help="independent check points (same formats; never enter the fit)")
    p.add_argument("--check-crs", default=None, metavar="CRS", help="CRS of --check")
    p.add_argument("--crs", default=None,
                   help="grid CRS for residuals (session mode; a project uses its own)")
    vg = p.add_mutually_exclusive_group()
    vg.add_argument("--vertical", default=None, help="vertical CRS of the control's heights")
    vg.add_argument("--geoid", default=None, metavar="FILE.tif", help="geoid grid (H = h - N)")
    p.add_argument("--source-crs", default=None,
                   help="geocentric CRS of the scene (session mode; default EPSG:4978)")
    p.add_argument("--exclude", action="append", default=[], metavar="ID",
                   help="leave a control point out of the fit (repeatable)")
    p.add_argument("--accept-outliers", action="store_true",
                   help="apply although control points fail the blunder test")
    p.add_argument("--scale-only", action="store_true",
                   help="fix only the scale from --distance (no control, no grid)")
    p.add_argument("--distance", action="append", default=[], metavar="A,B,METRES[,SIGMA]",
                   help="a known distance between measured points A and B (repeatable)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("-o", "--output", default=None, metavar="REPORT.html|REPORT.pdf",
                   help="also write the survey report (needs --project)")
    p.add_argument("--apply", nargs="?", const="", default=None, metavar="SCENE_DIR",
                   help="write the fit into the scene's tileset.json (a project's own scene "
                        "when no folder is given)")
    p.add_argument("--undo", nargs="?", const="", default=None, metavar="SCENE_DIR",
                   help="restore the scene's previous georeference and stop")
    p.set_defaults(run=run)


def _distances(texts: list[str]) -> list[Any]:
    from gsgeo.georef.scale import Distance

    out = []
    for k, text in enumerate(texts):
        parts = [s.strip() for s in text.split(",")]
        if len(parts) not in (3, 4) or not parts[0] or not parts[1]:
            raise InputError(f"--distance {text!r}: expected A,B,METRES or A,B,METRES,SIGMA",
                             field=f"distance[{k}]")
        try:
            nums = [number_text(v, None) for v in parts[2:]]
        except InputError:
            raise InputError(f"--distance {text!r}: METRES and SIGMA must be numbers") from None
        out.append(Distance(parts[0], parts[1], nums[0], nums[1] if len(nums) > 1 else None))
    return out


def _read_points(path: str, crs: str | None, role: str) -> list[Any]:
    """The points of a control or check file as records in their CRS, with ``role``."""
    from gsgeo.service import CheckPointRecord
    from gsgeo.service.checkpoints import format_from_name, read_check_points

    fmt = format_from_name(path)
    if fmt is None:
        raise InputError(f"{path}: cannot tell the format (use .csv, .geojson or .gpkg)")
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    try:
        rows, file_crs = read_check_points(data, fmt, Path(path).name)
    except InputError as exc:
        raise InputError(f"{path}: {exc.problem}") from None
    crs = crs or file_crs or ("EPSG:4979" if fmt == "geojson" else None)
    if crs is None:
        raise InputError(f"{path}: state the CRS of its coordinates with --{role}-crs")
    return [CheckPointRecord("", r.id, r.x, r.y, r.z, crs, role, path, sigma_h=r.sigma_h,
                             sigma_v=r.sigma_v) for r in rows]


def _reference(args: argparse.Namespace) -> Any:
    """The --control file's points (and the --check file's) as the fit takes them."""
    from gsgeo.service.georeferencing import reference_from

    records = _read_points(args.control, args.control_crs, "control")
    if args.check:
        records += _read_points(args.check, args.check_crs, "check")
    return reference_from(records)


def _session_mode(args: argparse.Namespace) -> JSONObject:
    """Fit from a session file (and apply to a scene folder)."""
    from gsgeo.georef.fit import Measured, georeference
    from gsgeo.georef.scale import fit_scale, origin_of
    from gsgeo.measure import Measurement
    from gsgeo.measure.rays import SolveSettings
    from gsgeo.service.measuring import json_ready
    from gsgeo.session import load_session, measure_session
    from gsgeo.tiles.georefhistory import apply_similarity, read_scene_georef

    session = load_session(args.session)
    results = measure_session(session, crs=args.crs, vertical=args.vertical, geoid=args.geoid,
                              source_crs=args.source_crs)
    ok = [m for m in results if isinstance(m, Measurement)]
    measured = Measured([m.point_id for m in ok],
                        np.array([m.point_ecef for m in ok], dtype=float).reshape(-1, 3),
                        np.array([m.cov_ecef for m in ok], dtype=float).reshape(-1, 3, 3))
    scene = Path(args.apply) if args.apply else None
    state = read_scene_georef(scene) if scene is not None else None
    if args.scale_only:
        origin = origin_of(state.root_transform) if state is not None else \
            (measured.ecef.mean(axis=0) if measured.ids else np.zeros(3))
        sol: Any = fit_scale(measured, _distances(args.distance), origin)
    else:
        if not args.control:
            raise InputError("give the control points with --control FILE")
        ref = _reference(args)
        settings = SolveSettings.parse(crs=args.crs or session.crs,
                                       vertical=args.vertical or session.vertical,
                                       geoid=args.geoid,
                                       source_crs=args.source_crs or session.source_crs)
        sol = georeference(measured, ref, settings, exclude=args.exclude)
    report = dict(sol.report)
    if scene is not None and state is not None:
        if report.get("outliers") and not args.accept_outliers:
            raise InputError(f"control point(s) {', '.join(report['outliers'])} fail the "
                             "blunder test; --exclude them or --accept-outliers")
        new = apply_similarity(scene, sol.similarity.matrix(), kind=str(report["kind"]),
                               frame_covariance=sol.frame.to_json(),
                               summary=json_ready(report),
                               georeferenced=report["kind"] != "scale" or state.georeferenced,
                               expect_version=state.version)
        report["applied"] = True
        report["scene"] = {"name": scene.name, "version": new.version,
                           "root_transform": new.root_transform.T.reshape(-1).tolist()}
        report["warnings"] = list(report.get("warnings") or []) + [
            "projects stored on this scene are re-measured on their next read (their rays "
            "follow the new georeference)"]
    return report


def _project_mode(args: argparse.Namespace) -> JSONObject:
    from gsgeo.georef.fit import georeference
    from gsgeo.service import open_projects
    from gsgeo.service.measuring import json_ready, solve_settings

    data = Path(args.data)
    if not data.is_dir():
        raise InputError(f"--data {data}: no such directory")
    svc = open_projects(data, url=store_url(args))
    try:
        p = svc.get_project(args.project)
        if args.apply and Path(args.apply).resolve() != (data / "scenes" / str(p.scene)).resolve():
            raise InputError(f"--apply {args.apply}: project '{p.id}' is on scene "
                             f"'{p.scene}'; give no folder to apply to its own scene")
        if args.undo is not None:
            return svc.undo_georeference(p.id)
        distances = _distances(args.distance) if args.scale_only else None
        if args.control and not args.scale_only:
            from gsgeo.service.georeferencing import measured_from

            ref = _reference(args)
            if args.apply is not None:
                raise InputError("--apply with --project uses the project's stored control; "
                                 "import the file as control points first (viewer or API)")
            sol = georeference(measured_from(svc.list_points(p.id)), ref,
                               solve_settings(p.settings(), data), exclude=args.exclude)
            return json_ready(sol.report)
        report = svc.georeference(p.id, exclude=args.exclude, apply=args.apply is not None,
                                  accept_outliers=args.accept_outliers, distances=distances)
        if args.output:
            _write_report(svc, p.id, args.output, report)
        return report
    finally:
        svc.store.close()


def _write_report(svc: Any, pid: str, output: str, fit: JSONObject) -> None:
    """The survey report with this run's fit (shown as proposed unless it was applied)."""
    from gsgeo.service.reporting import write_report

    write_report(svc, pid, Path(output), georeference=None if fit.get("applied") else fit)


def _table(r: JSONObject) -> str:
    lines = []
    if r.get("kind") == "scale":
        lines.append(f"scale {r['scale']:.8f} ± {r['scale_sigma']:.2e} "
                     f"({r['scale_ppm']:+.1f} ppm)")
        for d in r.get("distances") or []:
            lines.append(f"  {d['from']}-{d['to']}: true {d['distance']:.4f} m, scaled "
                         f"{d['scaled']:.4f} m, residual {d['residual']:+.4f} m")
    else:
        rot = np.asarray(r["rotation"])
        ang = np.degrees(np.arccos(np.clip((np.trace(rot) - 1) / 2, -1, 1)))
        lines.append(f"scale {r['scale']:.8f} ± {r['scale_sigma']:.2e} "
                     f"({r['scale_ppm']:+.1f} ppm); rotation {ang:.6f} deg "
                     f"(sigmas {', '.join(f'{v:.2e}' for v in r['rotation_sigma_deg'])} deg); "
                     f"sigma0 {r['sigma0']:.3f} ({r['dof']} dof, global test "
                     f"p = {r['global_test_p']:.3g})")
        lines.append(f"{'control':<12} {'dE':>9} {'dN':>9} {'dH':>9} {'w':>7}  status "
                     f"(metres, measured minus control)")
        for c in r["control"]:
            status = ("OUTLIER" if c["outlier"] else "excluded" if c["excluded"]
                      else "" if c["used"] else "unused")
            w = "" if c.get("w") is None else f"{c['w']:.2f}"
            lines.append(f"{c['id']:<12} {c['dE']:>9.4f} {c['dN']:>9.4f} {c['dH']:>9.4f} "
                         f"{w:>7}  {status}")
        for name in ("rmse_control", "rmse_check"):
            e = r.get(name)
            if e:
                lines.append(f"{name.replace('_', ' ')}: E {e['e']:.4f}  N {e['n']:.4f}  "
                             f"H {e['h'] if e['h'] is None else round(e['h'], 4)}  "
                             f"3D {e['3d'] if e['3d'] is None else round(e['3d'], 4)} m "
                             f"({e['count']} points)")
        alt = r.get("without_outliers")
        if alt:
            lines.append(f"without {', '.join(alt['excluded'])}: scale {alt['scale']:.8f}, "
                         f"rmse control 3D {alt['rmse_control']['3d']:.4f} m")
    for w in r.get("warnings") or []:
        lines.append(f"warning: {w}")
    if r.get("applied"):
        lines.append(f"applied: scene version {r['scene']['version']}"
                     + (f", {r['remeasured_points']} points re-measured"
                        if r.get("remeasured_points") is not None else ""))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    if (args.session is None) == (args.project is None):
        raise InputError("give either a session file or --project PID")
    if args.scale_only and not args.distance:
        raise InputError("--scale-only needs at least one --distance A,B,METRES")
    if args.output and not args.output.lower().endswith((".html", ".pdf")):
        raise InputError(f"-o {args.output}: the report is .html or .pdf")
    if args.output and args.project is None:
        raise InputError("-o (the survey report) needs --project")
    if args.project is not None:
        report = _project_mode(args)
    elif args.undo is not None:
        from gsgeo.tiles.georefhistory import undo

        if not args.undo:
            raise InputError("--undo needs the scene folder in session mode")
        state, _ = undo(args.undo)
        report = {"version": state.version, "georeferenced": state.georeferenced}
    else:
        report = _session_mode(args)
    if args.json or "control" not in report and "distances" not in report:
        json.dump(report, sys.stdout, indent=1)
        print()
    else:
        print(_table(report))
    return 0
