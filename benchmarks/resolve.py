"""Benchmark of re-solving stored points: gsgeo.measure.batch.measure_batch vs measure_point.

    python benchmarks/resolve.py [--points 10000] [--rays 4] [--repeat 3] [--loop-points N]

After a georeference change every stored point of a scene is measured again from its rays
(issue 16's target: apply <= 1 s including the re-solve of 10 000 points). Points are spread
over 600 m at a site in London, each seen by --rays cameras 20-45 m away with 1 px aiming
noise (angular model, ifov 0.8 mrad), grid EPSG:27700. Prints a markdown table of the best
wall and CPU times (paste it into benchmarks/README.md, section "Re-solving stored points")
and checks that both paths give the same points.

Rows: measure_batch on the plain points; measure_batch with a georeference's frame covariance
and 5 % of the points excluding one ray (what a re-solve after `gsgeo georef --apply` sees);
measure_batch on rays that carry the viewer's (identity) model_matrix, as stored points do (a
settings change re-solves them unmapped); the per-point loop (measure_point with its error
handling, as measure_points does) over --loop-points points (all by default), scaled to the
same count.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Callable

import numpy as np

from gsgeo.crs.ellipsoid import enu_rotation
from gsgeo.crs.frames import geodetic_to_ecef
from gsgeo.errors import GsgeoError
from gsgeo.measure.batch import BatchPoint, measure_batch
from gsgeo.measure.framecov import FrameCovariance
from gsgeo.measure.point import measure_point
from gsgeo.measure.rays import Rays, SolveSettings
from gsgeo.measure.schema import Measurement

IFOV = 0.0008
LON, LAT = -0.1276, 51.5072


def best(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Best wall-clock and best CPU time (s) of `repeat` runs (the machine is shared)."""
    wall, cpu = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return min(wall), min(cpu)


def make_points(m: int, n: int, seed: int = 16) -> list[BatchPoint]:
    """m points of n noisy rays each around (LON, LAT), rays in ECEF."""
    rng = np.random.default_rng(seed)
    lon = LON + rng.uniform(-0.004, 0.004, m)
    lat = LAT + rng.uniform(-0.003, 0.003, m)
    p = geodetic_to_ecef(lon, lat, rng.uniform(0, 60, m))
    rot = enu_rotation(lon, lat)  # ECEF -> ENU per point
    az = np.linspace(0, 2 * np.pi, n, endpoint=False)[None] + rng.uniform(0, 2 * np.pi, (m, 1))
    el = np.radians(rng.uniform(10, 40, (m, n)))
    r = rng.uniform(20, 45, (m, n))
    enu = np.stack([r * np.cos(el) * np.sin(az), r * np.cos(el) * np.cos(az), r * np.sin(el)], -1)
    o = p[:, None] + np.einsum("mji,mkj->mki", rot, enu)
    d = p[:, None] - o
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    d += rng.normal(0, IFOV / np.sqrt(3), d.shape)  # ~1 px perpendicular scatter
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    f = np.full(n, IFOV)
    return [(f"P{k}", "", "", Rays(o[k], d[k], f), ()) for k in range(m)]


def loop(points: list[BatchPoint], settings: SolveSettings) -> list[Measurement | None]:
    """The per-point path: measure_point on each point, errors caught as measure_points does."""
    out: list[Measurement | None] = []
    for pid, code, description, rays, exclude in points:
        try:
            out.append(measure_point(rays, settings, point_id=pid, code=code,
                                     description=description, exclude=exclude))
        except GsgeoError:
            out.append(None)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--rays", type=int, default=4)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--loop-points", type=int, default=None,
                    help="points timed through measure_point (default: all)")
    args = ap.parse_args()
    m, n = args.points, args.rays
    points = make_points(m, n)
    settings = SolveSettings(crs="EPSG:27700")
    centre = geodetic_to_ecef(LON, LAT, 30.0)
    frame = FrameCovariance(centre, np.diag([0.01, 0.01, 0.02, 2e-6, 2e-6, 3e-6, 1e-5]) ** 2)
    with_frame = SolveSettings(crs="EPSG:27700", frame=frame)
    excluded = [(pid, code, desc, rays, (k % n,) if k % 20 == 0 else ())
                for k, (pid, code, desc, rays, _) in enumerate(points)]
    with_matrix = [(pid, code, desc, Rays(r.origins, r.directions, r.ifov,
                                          model_matrices=np.repeat(np.eye(4)[None], n, axis=0)),
                    ex) for pid, code, desc, r, ex in points]
    measure_batch(points[:10], settings)  # PROJ transformers built and cached, as in a server

    rows = []
    t_batch = best(lambda: measure_batch(points, settings), args.repeat)
    rows.append(("measure_batch", m, t_batch))
    t_frame = best(lambda: measure_batch(excluded, with_frame), args.repeat)
    rows.append(("measure_batch, frame covariance, 5 % with a ray excluded", m, t_frame))
    t_matrix = best(lambda: measure_batch(with_matrix, settings), args.repeat)
    rows.append(("measure_batch, every ray with the viewer's model_matrix", m, t_matrix))
    k = m if args.loop_points is None else min(args.loop_points, m)
    w, c = best(lambda: loop(points[:k], settings), args.repeat)
    rows.append((f"per-point measure_point loop ({k:,} points timed, scaled)", m,
                 (w * m / k, c * m / k)))

    # the two paths agree (a sample when the loop was cut short)
    got = measure_batch(points[:k], settings)
    ref = loop(points[:k], settings)
    worst = 0.0
    for a, b in zip(got, ref, strict=True):
        assert isinstance(a, Measurement) and b is not None and a.grid and b.grid
        worst = max(worst, abs(a.grid.easting - b.grid.easting),
                    abs(a.grid.northing - b.grid.northing), abs(a.grid.height - b.grid.height))

    print(f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f} at start, Python {sys.version.split()[0]}, "
          f"numpy {np.__version__}; {m:,} points of {n} rays, EPSG:27700, best of "
          f"{args.repeat}\n")
    print("| path | points | wall time | points/s (wall) | CPU time |")
    print("|---|---:|---:|---:|---:|")
    for name, count, (wall, cpu) in rows:
        print(f"| {name} | {count:,} | {wall:.3f} s | {count / wall:,.0f} | {cpu:.3f} s |")
    print(f"\nspeed-up (wall): {rows[-1][2][0] / t_batch[0]:.0f}x; largest E/N/H difference "
          f"between the paths over {k:,} points: {worst:.1e} m")


if __name__ == "__main__":
    main()
