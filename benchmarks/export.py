"""Benchmark of gsgeo.export: 10^5 measured points to GeoPackage, GeoJSON and CSV.

    python benchmarks/export.py [--points 100000] [--rays 3] [--features 1000] [--repeat 2]

Builds M real Measurement objects (rays around each point in a 2 km square in London, solved
with gsgeo.solve.intersect_batch in one local ENU frame, put into EPSG:27700 by
gsgeo.crs.to_grid_many; setup not timed), plus `features` lines and polygons by point id, then
times write_measurements for each format: collecting the records, lengths/areas, geometry and
the atomic write. Wall-clock and CPU time (user + system of this process; on a shared machine
the CPU time is the better guide to the unloaded wall time). Prints a markdown table for
benchmarks/README.md; progress on stderr.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gsgeo.crs.frames import EnuFrame, geodetic_to_ecef
from gsgeo.crs.grid import to_grid_many
from gsgeo.export import write_measurements
from gsgeo.measure import Measurement
from gsgeo.solve import IntersectionResult, intersect_batch

CRS = "EPSG:27700"
IFOV = 0.0008


def build(m: int, n_rays: int, rng: np.random.Generator) -> list[Measurement]:
    """M measurements of a synthetic survey (vectorised maths; one object per point)."""
    centre = geodetic_to_ecef(-0.1276, 51.5072, 60.0).reshape(3)
    frame = EnuFrame(centre)
    side = int(np.ceil(np.sqrt(m)))
    g = (np.arange(side) - side / 2) * (2000.0 / side)
    ee, nn = np.meshgrid(g, g)
    pts = np.column_stack([ee.ravel()[:m], nn.ravel()[:m], rng.uniform(0, 20, m)])
    az = rng.uniform(0, 2 * np.pi, (m, 1)) + np.arange(n_rays) * 2 * np.pi / n_rays
    el = np.radians(rng.uniform(15, 45, (m, n_rays)))
    r = rng.uniform(20, 60, (m, n_rays))
    o = pts[:, None, :] + np.stack([r * np.cos(el) * np.sin(az), r * np.cos(el) * np.cos(az),
                                    r * np.sin(el)], axis=-1)
    d = pts[:, None, :] - o
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    d += rng.normal(0, IFOV, d.shape)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    ifov = np.full((m, n_rays), IFOV)
    res = intersect_batch(o, d, ifov=ifov)
    p_ecef = frame.to_ecef(res.points)
    c_ecef = frame.covariance_to_ecef(res.covariances)
    o_ecef = frame.to_ecef(o.reshape(-1, 3))
    print(f"  solved {m} points; to_grid_many ...", file=sys.stderr)
    gp = to_grid_many(p_ecef, c_ecef, CRS)
    go = to_grid_many(o_ecef, None, CRS)
    o_grid = np.stack([go.easting, go.northing, go.height], -1).reshape(m, n_rays, 3)
    d_ecef = frame.directions_to_ecef(d)
    out = []
    no_out = np.zeros(n_rays, dtype=bool)
    for i in range(m):
        if i % 20000 == 0:
            print(f"  building measurement objects {i}/{m}", file=sys.stderr)
        sol = IntersectionResult(
            point=res.points[i], covariance=res.covariances[i], sigma0=float(res.sigma0[i]),
            dof=res.dof, residuals_m=res.residuals_m[i], residuals_px=res.residuals_px[i],
            rms_m=float(np.sqrt(np.mean(res.residuals_m[i] ** 2))), max_angle_deg=60.0,
            condition=1.0, outliers=no_out, model="angular")
        out.append(Measurement(
            point_id=f"P{i}", code="corner", description="", solution=sol,
            enu_origin_ecef=frame.origin_ecef, point_ecef=p_ecef[i], cov_ecef=c_ecef[i],
            grid=gp.point(i), ray_origins_ecef=o_ecef[i * n_rays:(i + 1) * n_rays],
            ray_directions_ecef=d_ecef[i], ray_origins_grid=o_grid[i], excluded=no_out,
            measured_at="2026-11-22T12:00:00Z", residuals_m=res.residuals_m[i],
            residuals_px=res.residuals_px[i], outliers=no_out, ifov=ifov[i],
            lon=float(gp.lon[i]), lat=float(gp.lat[i]), h_wgs84=float(gp.h_wgs84[i])))
    return out


def features(m: int, k: int, side: int):
    """k lines (3 points) and k polygons (4 points: neighbouring grid cells) by point id."""
    lines, polys = [], []
    for j in range(k):
        i = (j * 97) % (m - side - 2)
        ring = [i, i + 1, i + 1 + side, i + side]
        polys.append({"id": f"A{j}", "points": [f"P{q}" for q in ring]})
        lines.append({"id": f"L{j}", "points": [f"P{q}" for q in ring[:3]]})
    return lines, polys


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--rays", type=int, default=3)
    ap.add_argument("--features", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    rng = np.random.default_rng(7)
    print(f"building {args.points} measurements ...", file=sys.stderr)
    t0 = time.perf_counter()
    ms = build(args.points, args.rays, rng)
    t_build = time.perf_counter() - t0
    side = int(np.ceil(np.sqrt(args.points)))
    lines, polys = features(args.points, args.features, side)
    import pyogrio.raw  # noqa: F401  (imports of pyogrio/pandas, ~1 s, are not export work)

    import gsgeo.export.gpkg as gp
    from gsgeo.export.tables import collect

    layer_cpu: dict[str, float] = {}
    real_write_layer = gp._write_layer

    def timed_write_layer(path, name, *a, **k):  # CPU per GeoPackage layer (GDAL insert + index)
        c0 = time.process_time()
        real_write_layer(path, name, *a, **k)
        layer_cpu[name] = min(layer_cpu.get(name, 1e9), time.process_time() - c0)

    gp._write_layer = timed_write_layer

    t0 = time.process_time()
    collect(ms, lines=lines, polygons=polys)
    t_collect = time.process_time() - t0
    rows = []
    with tempfile.TemporaryDirectory(prefix="gsgeo-bench-export-") as tmp:
        for fmt, suffix in (("gpkg", ".gpkg"), ("geojson", ".geojson"), ("csv", ".csv")):
            times, cpu = [], []
            for rep in range(args.repeat):
                print(f"writing {fmt} ({rep + 1}/{args.repeat}) ...", file=sys.stderr)
                path = Path(tmp) / f"out{suffix}"
                t0, c0 = time.perf_counter(), time.process_time()
                write_measurements(path, ms, lines=lines, polygons=polys)
                times.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            rows.append((fmt, min(times), max(times), min(cpu), path.stat().st_size / 2**20))
    print(f"\n{args.points} points x {args.rays} rays, {args.features} lines + "
          f"{args.features} polygons, EPSG:27700; best / worst of {args.repeat}; "
          f"{platform.python_version()}, {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f}; setup (not timed) {t_build:.0f} s; of each time, "
          f"{t_collect:.2f} s CPU is gathering and validating (gsgeo.export.tables.collect)\n")
    print("| format | wall best (s) | wall worst (s) | CPU best (s) | file (MiB) | target |")
    print("|---|---:|---:|---:|---:|---|")
    for fmt, best, worst, c, size in rows:
        target = "<= 5 s" if fmt in ("gpkg", "geojson") else "-"
        print(f"| {fmt} | {best:.2f} | {worst:.2f} | {c:.2f} | {size:.1f} | {target} |")
    print("\nGeoPackage, CPU (s) of writing each layer (best of the runs): "
          + ", ".join(f"{k} {v:.2f}" for k, v in layer_cpu.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
