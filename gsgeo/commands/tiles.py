"""`gsgeo tiles INPUT -o OUTDIR`: 3DGS PLY/SPZ to georeferenced 3D Tiles of SPZ splats."""

from __future__ import annotations

import argparse
import gc
import json
import os
import sys

from gsgeo.commands.argtypes import integer, number
from gsgeo.errors import InputError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tiles",
        help="convert a 3DGS PLY/SPZ scene into georeferenced 3D Tiles",
        description="Convert a 3D Gaussian Splatting scene (INRIA PLY or SPZ) into OGC 3D Tiles "
                    "1.1 whose glTF tiles hold SPZ-compressed splats (KHR_gaussian_splatting), "
                    "placed on the Earth by one of --origin, --crs/--offset or --transform.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Without a georeference the scene is put at lat 0, lon 0, h 0 with a warning.\n"
               "Parents hold the most prominent splats of their subtree (refine ADD); all tiles "
               "together hold every input splat.")
    p.add_argument("input", help="INPUT.ply (INRIA 3DGS, SH degree 0-3) or INPUT.spz (v2/v3)")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                   help="output directory (tileset.json + tiles/*.glb)")
    g = p.add_argument_group("georeference (choose one)")
    g.add_argument("--origin", metavar="LAT,LON,H",
                   help="the input is a local ENU frame at this point (degrees, metres)")
    g.add_argument("--heading", type=number, default=0.0, metavar="DEG",
                   help="with --origin: azimuth of the input +y axis, degrees clockwise from "
                        "true north (default 0)")
    g.add_argument("--crs", metavar="CRS",
                   help="the input is projected-CRS coordinates minus --offset (e.g. EPSG:32617)")
    g.add_argument("--offset", metavar="E,N,H", default=None,
                   help="with --crs: offset added to the input coordinates (metres)")
    h = g.add_mutually_exclusive_group()
    h.add_argument("--height", choices=["ellipsoidal"], default=None,
                   help="with --crs: heights are ellipsoidal (the default for a 2-D CRS)")
    h.add_argument("--vertical", metavar="CRS",
                   help="with --crs: heights are in this vertical CRS (e.g. EPSG:5703); "
                        "its geoid grid must be installed")
    h.add_argument("--geoid", metavar="FILE.tif",
                   help="with --crs: heights are orthometric; this geoid grid gives N (h = H + N)")
    g.add_argument("--transform", metavar="M.json",
                   help="a 4x4 local-to-ECEF matrix (16 numbers column-major, or 4 rows)")
    p.add_argument("--axes", choices=["z-up", "y-up", "y-down"], default="z-up",
                   help="axis convention of the input, turned to Z-up before georeferencing: "
                        "z-up (ENU, default), y-up (glTF/three.js, SPZ's RUB), "
                        "y-down (COLMAP/OpenCV)")
    p.add_argument("--max-splats", type=integer, default=131_072,
                   help="splats per tile at most (default 131072)")
    p.add_argument("--spz-version", type=integer, choices=[2, 3], default=3,
                   help="SPZ gzip file version (default 3)")
    p.add_argument("--level", type=integer, default=1, choices=range(10), metavar="0-9",
                   help="gzip level of the SPZ payloads (default 1: fast; 9: ~10%% smaller, "
                        "many times slower)")
    p.add_argument("--workers", type=integer, default=None,
                   help="worker processes (default: the number of CPUs; inputs under "
                        "200 000 splats use one)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace OUTDIR if it is a tileset written by gsgeo tiles (it is "
                        "swapped only once complete)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    # A bounded batch job that makes no reference cycles worth collecting: without this the
    # cyclic collector walks the objects numpy's import creates again and again (20-30 ms of
    # a one-second run). Collection resumes afterwards (tests call run() in their process).
    enabled = gc.isenabled()
    gc.disable()
    try:
        return _run(args)
    finally:
        if enabled:
            gc.enable()


def _run(args: argparse.Namespace) -> int:
    # Before numpy loads: its OpenBLAS would otherwise start a spinning thread per CPU in
    # every worker process for matrices of a few elements (the work is split by processes).
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import numpy as np

    from gsgeo.tiles.build import build_tileset
    from gsgeo.tiles.georef import Georeference
    from gsgeo.tiles.workers import keep_freed_memory

    keep_freed_memory()

    if args.workers is not None and args.workers < 1:
        raise InputError("--workers must be at least 1")
    georef = Georeference.from_options(
        origin=args.origin, heading=args.heading, crs=args.crs, offset=args.offset,
        transform=args.transform, height=args.height, vertical=args.vertical, geoid=args.geoid,
        axes=args.axes)

    def started() -> None:
        # the georeference's warnings, once the input and the output are known to be usable
        for w in georef.warnings:
            print(f"gsgeo tiles: warning: {w}", file=sys.stderr)
        georef.warnings.clear()

    # Values out of range are dropped (NaN/inf) or refused with a message by the build;
    # numpy's floating-point warnings about them would only add noise to that one message
    # (the workers fork inside, so they inherit the setting).
    with np.errstate(all="ignore"):
        summary = build_tileset(args.input, args.output, georef, max_splats=args.max_splats,
                                spz_version=args.spz_version, level=args.level,
                                workers=args.workers, overwrite=args.overwrite,
                                progress=None if args.quiet else sys.stderr, on_start=started)
    for w in summary.warnings:
        print(f"gsgeo tiles: warning: {w}", file=sys.stderr)
    if args.json:
        json.dump(summary.to_dict(), sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(summary.text())
    return 0
