"""Benchmark `POST /api/match` under a burst of worst-case requests: the server's memory and
the latency of an unrelated GET meanwhile, against a real `gsgeo serve` on loopback.

    python benchmarks/match_load.py [--concurrent 12] [--rounds 2]

Two kinds of worst case, each sent ``--concurrent`` times at once, ``--rounds`` times:

- "bomb": a flat grey PNG of 5792 x 5792 pixels (2^25, 33 kB sent) as the target view: a
  decompression bomb, at the old per-view limit;
- "largest": the largest pair a request may send, flat (a few kB): a 3840 x 2160 target beside a
  1024 x 1024 reference (gsgeo.aim.images.MAX_MATCH_PIXELS).

Meanwhile a client GETs /api/projects every 50 ms and records each latency. Reported per kind:
the answers' status codes, the wall time of the burst, the server's resident memory (RSS, from
/proc) before and at its peak, and the GET latencies (p50, max).
"""

from __future__ import annotations

import argparse
import base64
import statistics
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from benchdata import rss_mb  # noqa: E402
from servertools import start_server  # noqa: E402


def flat_png(w: int, h: int) -> str:
    ok, buf = cv2.imencode(".png", np.full((h, w), 90, np.uint8))
    assert ok
    return base64.b64encode(buf.tobytes()).decode("ascii")


def camera(w: int, h: int) -> dict:
    return {"position": [6378137.0 + 10.0, 0.0, 0.0], "direction": [-1.0, 0.0, 0.0],
            "up": [0.0, 0.0, 1.0], "fovy": 0.8, "width": w, "height": h}


def body(ref_wh: tuple[int, int], tgt_wh: tuple[int, int]) -> dict:
    (rw, rh), (tw, th) = ref_wh, tgt_wh
    return {"reference": {"image": flat_png(rw, rh), "camera": camera(rw, rh),
                          "pixel": [rw / 2, rh / 2]},
            "target": {"image": flat_png(tw, th), "camera": camera(tw, th)},
            "depth": {"near_m": 5.0, "far_m": 15.0, "depth_m": 10.0}}


def burst(base: str, pid: int, doc: dict, n: int) -> None:
    lat: list[float] = []
    peak = [rss_mb(pid)]
    before = peak[0]
    stop = threading.Event()

    def getter() -> None:
        with httpx.Client(timeout=60) as c:
            while not stop.is_set():
                t0 = time.perf_counter()
                c.get(base + "/api/projects")
                lat.append(time.perf_counter() - t0)
                peak[0] = max(peak[0], rss_mb(pid))
                stop.wait(0.05)

    g = threading.Thread(target=getter)
    g.start()
    time.sleep(0.3)
    t0 = time.perf_counter()
    with ThreadPoolExecutor(n) as pool:
        codes = list(pool.map(lambda _: httpx.post(base + "/api/match", json=doc,
                                                   timeout=600).status_code, range(n)))
    wall = time.perf_counter() - t0
    time.sleep(0.3)
    stop.set()
    g.join()
    counts = {c: codes.count(c) for c in sorted(set(codes))}
    print(f"  answers {counts} in {wall:.1f} s; server RSS {before:.0f} -> peak "
          f"{peak[0]:.0f} MB (+{peak[0] - before:.0f}); GET p50 "
          f"{statistics.median(lat) * 1000:.0f} ms, max {max(lat) * 1000:.0f} ms "
          f"({len(lat)} GETs)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--concurrent", type=int, default=12)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()
    kinds = {"bomb": body((512, 512), (5792, 5792)),
             "largest": body((1024, 1024), (3840, 2160))}
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        proc, base = start_server(Path(tmp))
        try:
            print(f"server RSS at start: {rss_mb(proc.pid):.0f} MB")
            for name, doc in kinds.items():
                for r in range(args.rounds):
                    print(f"{name}, round {r + 1}: {args.concurrent} requests at once")
                    burst(base, proc.pid, doc, args.concurrent)
        finally:
            proc.terminate()
            proc.wait(30)
    return 0


if __name__ == "__main__":
    sys.exit(main())
