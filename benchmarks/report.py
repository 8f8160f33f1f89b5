"""Benchmark the survey report of a large project: `GET /api/projects/{pid}/report` of a real
`gsgeo serve` on loopback.

    python benchmarks/report.py [--points 5000] [--lines 1000] [--concurrent 3]
        [--settle SECONDS] [--profile FILE.prof]

The project ``bench`` (built once in a temporary data directory, as benchmarks/ogc.py builds
its own: one measured point copied ``--points`` times across 1 km, every tenth of them a check
point 1-2 cm off, ``--lines`` two-point lines) is reported by the server:

1. one PDF, then one HTML, each timed from request to the last byte (target: the PDF of 5 000
   points in <= 10 s); ``--settle S``: the first request S seconds after the server answers
   (default 0: at once, before its background warm-up of the report renderer is done);
2. ``--concurrent`` PDF requests at once (as a viewer's users might click "Report"), each
   timed, and the server's resident memory (RSS, /proc) before, at its peak and 5 s after;
3. one more PDF request after them, which may reuse the report just made (unchanged project);
4. one PDF alone after another change: a later report on a warm server.

``--profile FILE``: instead, render the PDF in this process under cProfile and write the
statistics to FILE (the top 25 by cumulative time are printed).
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from benchdata import rss_mb, store_copies  # noqa: E402
from servertools import LONDON, ecef_of, rays_at, start_server  # noqa: E402

from gsgeo.service import open_projects  # noqa: E402
from gsgeo.service.checkpoints import CheckPointRow  # noqa: E402

PID = "bench"
CRS = "EPSG:27700"


def build(data: Path, n: int, n_lines: int) -> None:
    """The project ``bench``: ``n`` points, every tenth a check point, ``n_lines`` lines."""
    svc = open_projects(data)
    try:
        svc.create_project(name="report benchmark", id=PID, crs=CRS)
        seed = svc.add_point(PID, {"id": "P0", "code": "seed",
                                   "rays": rays_at(ecef_of(*LONDON), 4, ifov=0.0005)})
        assert seed.result is not None
        rng = np.random.default_rng(1)
        de, dn = store_copies(svc, PID, seed, n, rng)
        e0, n0, h0 = (seed.record or {})["easting"], seed.record["northing"], seed.record["height"]
        off = rng.normal(0.0, 0.015, (n, 3))
        svc.add_check_points(PID, [CheckPointRow(f"P{i + 1}", e0 + de[i] + off[i, 0],
                                                 n0 + dn[i] + off[i, 1], h0 + off[i, 2], 0.005,
                                                 0.008) for i in range(0, n, 10)], CRS)
        for k in range(n_lines):
            svc.add_feature(PID, "line", {"id": f"L{k + 1}",
                                           "points": [f"P{k % n + 1}", f"P{(k + 7) % n + 1}"]})
    finally:
        svc.store.close()


def get(base: str, fmt: str) -> tuple[float, int, int]:
    t0 = time.perf_counter()
    r = httpx.get(f"{base}/api/projects/{PID}/report?format={fmt}", timeout=900)
    return time.perf_counter() - t0, r.status_code, len(r.content)


def change(base: str) -> None:
    """A change to the project (a new description each time, also in a kept --data project):
    the next reports cannot reuse those made before."""
    httpx.patch(f"{base}/api/projects/{PID}", json={"description": f"changed {time.time()}"},
                timeout=60).raise_for_status()


def profile(data: Path, out: str) -> None:
    from gsgeo.report import render
    from gsgeo.service.reporting import report_data

    svc = open_projects(data)
    try:
        prof = cProfile.Profile()
        t0 = time.perf_counter()
        prof.enable()
        body = render(report_data(svc, PID), "pdf")
        prof.disable()
        print(f"PDF in process: {time.perf_counter() - t0:.1f} s, {len(body) / 1e6:.1f} MB")
    finally:
        svc.store.close()
    prof.dump_stats(out)
    pstats.Stats(out).sort_stats("cumulative").print_stats(25)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=5000)
    ap.add_argument("--lines", type=int, default=1000)
    ap.add_argument("--concurrent", type=int, default=3)
    ap.add_argument("--settle", type=float, default=0.0, metavar="SECONDS",
                    help="wait this long after the server answers before the first request")
    ap.add_argument("--profile", metavar="FILE.prof")
    ap.add_argument("--data", metavar="DIR", help="keep the project in DIR (built there once) "
                                                  "instead of a temporary directory")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(args.data or tmp)
        if not (data / "gsgeo.sqlite").is_file():
            t0 = time.perf_counter()
            build(data, args.points, args.lines)
            print(f"built {args.points} points, {args.lines} lines in "
                  f"{time.perf_counter() - t0:.1f} s")
        if args.profile:
            profile(data, args.profile)
            return 0
        proc, base = start_server(data)
        try:
            print(f"server RSS at start: {rss_mb(proc.pid):.0f} MB")
            time.sleep(args.settle)
            for fmt in ("pdf", "html"):
                dt, status, size = get(base, fmt)
                print(f"{fmt}: {dt:.1f} s, HTTP {status}, {size / 1e6:.2f} MB; "
                      f"server RSS {rss_mb(proc.pid):.0f} MB")
            # a change to the project: the next reports cannot reuse the ones just made
            change(base)
            before = rss_mb(proc.pid)
            peak = [before]
            stop = threading.Event()

            def watch() -> None:
                while not stop.wait(0.2):
                    peak[0] = max(peak[0], rss_mb(proc.pid))

            w = threading.Thread(target=watch)
            w.start()
            t0 = time.perf_counter()
            with ThreadPoolExecutor(args.concurrent) as pool:
                res = list(pool.map(lambda _: get(base, "pdf"), range(args.concurrent)))
            wall = time.perf_counter() - t0
            stop.set()
            w.join()
            print(f"{args.concurrent} concurrent PDFs: "
                  + ", ".join(f"{dt:.1f} s (HTTP {st})" for dt, st, _ in res)
                  + f"; all done in {wall:.1f} s")
            time.sleep(5)
            print(f"server RSS before {before:.0f} MB, peak {peak[0]:.0f} MB, "
                  f"5 s after {rss_mb(proc.pid):.0f} MB")
            dt, status, _ = get(base, "pdf")
            print(f"one more PDF of the unchanged project: {dt:.2f} s (HTTP {status})")
            change(base)
            dt, status, _ = get(base, "pdf")
            print(f"a later PDF, alone (project changed again): {dt:.1f} s (HTTP {status})")
        finally:
            proc.terminate()
            proc.wait(30)
    return 0


if __name__ == "__main__":
    sys.exit(main())
