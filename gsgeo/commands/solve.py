"""`gsgeo solve SESSION.json`: intersect the rays of every point in a session."""

from __future__ import annotations

import argparse
import json
import sys

from gsgeo.errors import GsgeoError, InputError
from gsgeo.session import Session, load_session, ray_arrays
from gsgeo.solve import SCALE_95_1D, intersect


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "solve",
        help="intersect the rays of a session JSON file",
        description="Intersect the rays of every point in a session JSON file by least squares.",
    )
    p.add_argument("session", help="session JSON file (DESIGN.md, 'Session JSON')")
    p.add_argument("--sigma-px", type=float, default=None,
                   help="a-priori aiming precision in pixels (overrides the session's sigma_px)")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.set_defaults(run=run)


def solve_session(session: Session) -> list[dict]:
    """Solve every point; a point that cannot be solved gets an 'error' entry instead."""
    out = []
    for pt in session.points:
        entry: dict = {"id": pt.id, "code": pt.code, "description": pt.description,
                       "n_rays": len(pt.rays)}
        try:
            o, d, ifov = ray_arrays(pt)
            res = intersect(o, d, ifov=ifov, sigma_px=session.sigma_px)
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


def run(args: argparse.Namespace) -> int:
    session = load_session(args.session)
    if args.sigma_px is not None:
        if not args.sigma_px > 0:
            raise InputError("--sigma-px must be a positive number of pixels")
        session.sigma_px = args.sigma_px
    if not session.points:
        raise InputError(f"{args.session}: the session has no points")
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
