"""Benchmark the OGC API – Features of `gsgeo serve`: 10⁵ points read by GDAL in pages of 10 000.

    python benchmarks/ogc.py [--points 100000] [--page 10000] [--repeat 3] [--data DIR]

1. A project of `--points` points in EPSG:27700 is stored quickly: one point is measured
   through the service (4 rays), then its stored result is inserted `--points` times straight
   into the store with shifted coordinates (E, N and lon, lat), as a re-measure would store
   them (about 3 KB of JSON per point). The store is reused when DIR already holds it.
2. `gsgeo serve --data DIR` runs on loopback; GDAL's OAPIF driver (pyogrio) reads the layer
   `bench.points` with open option PAGE_SIZE=`--page`, in the grid CRS (storageCrs, the
   default) and in CRS84:
   - whole: pyogrio.raw.read of every feature and attribute (open, schema request, all pages);
   - first page: pyogrio.raw.read with max_features=`--page` (open + first page);
   - one HTTP page: a plain GET of the first page (limit=`--page`), the server's time alone.
   Best of `--repeat` runs each. Targets: whole <= 5 s, first page <= 0.5 s.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from benchdata import store_copies  # noqa: E402
from servertools import LONDON, ecef_of, rays_at, start_server  # noqa: E402

from gsgeo.service import open_projects  # noqa: E402

PID = "bench"


def build(data: Path, n: int) -> None:
    """The project ``bench`` with ``n`` points (skipped when it holds them already)."""
    svc = open_projects(data)
    try:
        if any(p.id == PID for p in svc.list_projects()):
            with svc.store.transaction(write=False) as tx:
                if tx.count_point_records(PID) == n:
                    return
            svc.delete_project(PID)
        svc.create_project(name="benchmark", id=PID, crs="EPSG:27700")
        seed = svc.add_point(PID, {"id": "P0", "code": "seed",
                                   "rays": rays_at(ecef_of(*LONDON), 4)})
        assert seed.result is not None
        t0 = time.perf_counter()
        store_copies(svc, PID, seed, n, np.random.default_rng(1))
        print(f"stored {n} points in {time.perf_counter() - t0:.1f} s")
    finally:
        svc.store.close()


def best(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--page", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--data", type=Path, default=None, help="data directory (kept)")
    args = ap.parse_args()
    import pyogrio
    from pyogrio.raw import read

    tmp = None
    data = args.data
    if data is None:
        tmp = Path(tempfile.mkdtemp(prefix="gsgeo-ogc-bench-"))
        data = tmp
    try:
        build(data, args.points)
        proc, base = start_server(data)
        try:
            url = f"OAPIF:{base}/ogc"
            layer = f"{PID}.points"
            print(f"GDAL {pyogrio.__gdal_version_string__}, {args.points} points, "
                  f"pages of {args.page}, best of {args.repeat}")
            for label, crs in (("grid (EPSG:27700)", None), ("CRS84", "OGC:CRS84")):
                opts = {"PAGE_SIZE": str(args.page)} | ({"CRS": crs} if crs else {})
                t_all, got = best(lambda o=opts: read(url, layer=layer, **o), args.repeat)
                n = len(got[2])  # type: ignore[index]
                t_first, _ = best(lambda o=opts: read(url, layer=layer, max_features=args.page,
                                                     **o), args.repeat)
                print(f"{label:18s} whole {t_all:6.2f} s ({n} features)   "
                      f"first page {t_first:5.2f} s")
            page_url = f"{base}/ogc/collections/{layer}/items?limit={args.page}"
            t_http, r = best(lambda: httpx.get(page_url, timeout=60), args.repeat)
            print(f"one HTTP page (server alone): {t_http:.3f} s, "
                  f"{len(r.content) / 1e6:.1f} MB")  # type: ignore[attr-defined]
        finally:
            proc.terminate()
            proc.communicate(timeout=30)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
