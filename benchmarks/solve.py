"""Benchmark of gsgeo.solve: batch throughput, single-point latency, and a per-point numpy loop.

    python benchmarks/solve.py [--points 1000000] [--rays 5] [--repeat 3]

Prints a markdown table (paste it into benchmarks/README.md). All three are measured in one
run on the same synthetic rays (gsgeo.solve.simulate: drone-like views, 1 px aiming noise).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time

import numpy as np

from gsgeo.solve import intersect, intersect_batch
from gsgeo.solve.simulate import aim_with_noise, camera_network

IFOV = 2 * np.tan(np.radians(30)) / 1080


def per_point_loop(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The plain way: one np.linalg call per point (unweighted point, covariance, residuals)."""
    out = np.empty((origins.shape[0], 3))
    eye = np.eye(3)
    for i in range(origins.shape[0]):
        o, d = origins[i], directions[i]
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        proj = eye[None] - d[:, :, None] * d[:, None, :]
        nmat = proj.sum(axis=0)
        x = np.linalg.solve(nmat, np.einsum("kij,kj->i", proj, o))
        r = np.einsum("kij,kj->ki", proj, x - o)
        s0 = np.sum(r * r) / (2 * len(o) - 3)
        _cov = s0 * np.linalg.inv(nmat)
        out[i] = x
    return out


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--rays", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--loop-points", type=int, default=20_000)
    ap.add_argument("--single-calls", type=int, default=2_000)
    args = ap.parse_args()

    rng = np.random.default_rng(1)
    m, n = args.points, args.rays
    print(f"generating {m} points x {n} rays ...", file=sys.stderr)
    o, d = camera_network(rng, m, n)
    d = aim_with_noise(rng, d / np.linalg.norm(d, axis=-1, keepdims=True), IFOV, 1.0)
    ifov = np.full((m, n), IFOV)

    rows = []
    t_unw = best_of(lambda: intersect_batch(o, d), args.repeat)
    rows.append(("intersect_batch, unweighted", f"{m / t_unw:,.0f} points/s", f"{t_unw:.3f} s for {m:,}"))
    t_ang = best_of(lambda: intersect_batch(o, d, ifov=ifov), args.repeat)
    rows.append(("intersect_batch, angular (iterated)", f"{m / t_ang:,.0f} points/s",
                 f"{t_ang:.3f} s for {m:,}"))

    k = args.loop_points
    t_loop = best_of(lambda: per_point_loop(o[:k], d[:k]), 1)
    loop_rate = k / t_loop
    rows.append(("per-point numpy loop, unweighted", f"{loop_rate:,.0f} points/s",
                 f"{t_loop:.3f} s for {k:,}"))
    rows.append(("batch / loop (unweighted)", f"{(m / t_unw) / loop_rate:.0f} x", ""))

    lat = []
    for i in range(args.single_calls):
        t = time.perf_counter()
        intersect(o[i], d[i], ifov=IFOV, sigma_px=1.0)
        lat.append(time.perf_counter() - t)
    lat_ms = np.array(lat) * 1e3
    rows.append(("intersect, angular + outlier test", f"median {statistics.median(lat_ms):.3f} ms",
                 f"p99 {np.percentile(lat_ms, 99):.3f} ms over {args.single_calls:,} calls"))

    print(f"\nMachine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, numpy {np.__version__}; M = {m:,}, N = {n}\n")
    print("| measurement | rate | detail |")
    print("| --- | --- | --- |")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
