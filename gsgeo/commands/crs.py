"""`gsgeo crs search TEXT` and `gsgeo crs info CRS`: find and describe coordinate systems."""

from __future__ import annotations

import argparse
import json
import sys

from gsgeo.commands.argtypes import integer
from gsgeo.commands.argtypes import text as text_arg
from gsgeo.crs.discovery import KINDS, describe_crs, search_crs
from gsgeo.errors import InputError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("crs", help="find and describe coordinate reference systems",
                       description="Find CRSs by name or code, and describe one.")
    csub = p.add_subparsers(dest="crs_command", metavar="ACTION")
    csub.required = True
    s = csub.add_parser("search", help="list CRSs whose code or name matches TEXT",
                        description="List projected and compound CRSs (or --kind ...) whose "
                                    "code equals TEXT or whose name contains every word of it.")
    s.add_argument("text", nargs="+", type=text_arg,
                   help="words of the name, or a code such as 27700")
    s.add_argument("--kind", action="append", choices=sorted(KINDS),
                   help="kinds to list (repeatable); default projected and compound")
    s.add_argument("--all", action="store_true", help="include deprecated CRSs and every authority")
    s.add_argument("--limit", type=integer, default=40, help="at most this many rows (default 40)")
    s.add_argument("--json", action="store_true", help="print JSON")
    s.set_defaults(run=run_search)
    i = csub.add_parser("info", help="units, axes, datum, area and the operation from WGS 84",
                        description="Describe a CRS: units, axes, datum, area of use and the "
                                    "operation(s) from the scene's source CRS with their accuracy.")
    i.add_argument("crs", help="e.g. EPSG:27700 or EPSG:27700+5701")
    i.add_argument("--source-crs", default="EPSG:4978",
                   help="geocentric CRS of the scene (default EPSG:4978, WGS 84)")
    i.add_argument("--json", action="store_true", help="print JSON")
    i.set_defaults(run=run_info)


def run_search(args: argparse.Namespace) -> int:
    if args.limit <= 0:
        raise InputError("--limit must be a positive number of rows")
    text = " ".join(args.text)
    kinds = tuple(args.kind or ("projected", "compound"))
    rows = search_crs(text, kinds, include_deprecated=args.all,
                      authority=None if args.all else "EPSG")
    if not rows:  # a search that finds nothing is an answer, not an error: exit 0
        print(f"no {' or '.join(kinds)} CRS matches '{text}'", file=sys.stderr)
    if args.json:
        json.dump([r.__dict__ for r in rows[:args.limit]], sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    if not rows:
        return 0
    print(f"{'code':<16} {'kind':<10} {'name':<48} area of use")
    for r in rows[:args.limit]:
        dep = " (deprecated)" if r.deprecated else ""
        print(f"{r.code:<16} {r.kind:<10} {r.name[:48]:<48} {r.area[:60]}{dep}")
    if len(rows) > args.limit:
        print(f"... {len(rows) - args.limit} more; add words to narrow the search or raise --limit")
    return 0


def run_info(args: argparse.Namespace) -> int:
    info = describe_crs(args.crs, args.source_crs)
    if args.json:
        json.dump(info, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    print(f"{info['code']}  {info['name']}  ({info['type']})")
    if info.get("components"):
        print("  components: " + "; ".join(info["components"]))
    for ax in info["axes"]:
        print(f"  axis {ax['abbrev']:<4} {ax['name']} ({ax['direction']}), {ax['unit']}"
              + ("" if ax["metres_per_unit"] in (None, 1.0) or ax["unit"] == "degree"
                 else f" = {ax['metres_per_unit']:.12g} m"))
    print(f"  datum: {info['datum']}; ellipsoid: {info['ellipsoid']}")
    if info.get("projection"):
        print(f"  projection: {info['projection']}")
    a = info["area_of_use"]
    if a:
        print(f"  area of use: {a['name']} (lon {a['west']:g}..{a['east']:g}, "
              f"lat {a['south']:g}..{a['north']:g})")
    ops = info["operations"]
    if ops:
        print(f"  operations from {info['from']} (best first):")
        for op in ops:
            if op["available"]:
                acc = "unknown accuracy" if op["accuracy_m"] is None else f"accuracy {op['accuracy_m']:g} m"
                if op["accuracy_m"] == 0:
                    acc = "exact conversion"
                flags = []
                if op.get("ballpark"):
                    flags.append("BALLPARK: no real datum or geoid correction")
                if not op.get("covers_area_centre", True):
                    flags.append("partial area")
                print(f"    - {op['operation']} [{acc}{'; ' + '; '.join(flags) if flags else ''}]")
            else:
                print(f"    - not installed: {op['operation']} "
                      f"[needs {', '.join(op['missing_grids']) or 'grids'}]")
        usable = [o for o in ops if o["available"] and not o.get("ballpark")]
        if usable and usable[0]["accuracy_m"] not in (None, 0) and usable[0]["accuracy_m"] >= 1:
            print(f"  note: from {info['from']} this is a {usable[0]['accuracy_m']:g} m "
                  "transformation; declare the scene's real realisation with --source-crs "
                  "(e.g. EPSG:4936 ETRS89) if it has one")
    return 0
