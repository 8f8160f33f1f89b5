"""Auto-aim's server side per call: depth hint, suggested views, and matching.

    python benchmarks/aim.py [--data DIR] [--repeat N]

Scenes: the demo scene (built into DIR by `gsgeo demo --no-serve` when missing; default a
temporary folder) and ../shared/data/white-sculpture when present. On each scene: the first
call (reading the splats) and then per-call times of POST /depth's and /views' work
(gsgeo.service.aiming, no HTTP) for rays at 20 targets from several directions. Matching: a
synthetic 1280x720 pair (a textured plane rendered by two cameras 40 degrees apart with the
exact homography), the epipolar segment 0.5 m, 10 m and 100 m long.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from gsgeo.aim.camera import Camera
from gsgeo.aim.match import View, match_feature
from gsgeo.aim.splatindex import scene_index
from gsgeo.aim.views import local_axes
from gsgeo.measure import Rays
from gsgeo.service.aiming import depth_on_ray, views_for_point

REPO = Path(__file__).resolve().parents[1]
WHITE = REPO.parent / "shared" / "data" / "white-sculpture"


def ms(xs: list[float]) -> str:
    xs = sorted(xs)
    p95 = xs[min(len(xs) - 1, int(round(0.95 * (len(xs) - 1))))]
    return f"median {1000 * statistics.median(xs):6.1f} ms, p95 {1000 * p95:6.1f} ms, " \
           f"max {1000 * xs[-1]:6.1f} ms (n={len(xs)})"


def targets_of(tileset: Path, n: int, rng: np.random.Generator) -> np.ndarray:
    """n opaque, small splats' centres (tileset ECEF) near the middle of the scene."""
    idx = scene_index(tileset)
    pos = idx.offsets.T.astype(np.float64) + idx.centre
    mid = np.median(pos, axis=0)
    r = np.linalg.norm(pos - mid, axis=1)
    ok = np.flatnonzero((idx.alpha > 0.8) & (idx.reach < 0.1) & (r < np.quantile(r, 0.3)))
    return pos[rng.choice(ok, size=n, replace=False)]


def bench_scene(name: str, folder: Path, repeat: int, rng: np.random.Generator) -> None:
    tileset = folder / "tileset.json"
    t0 = time.perf_counter()
    index = scene_index(tileset)
    print(f"\n{name}: {index.count:,} splats; first call (read the tileset) "
          f"{time.perf_counter() - t0:.2f} s")
    targets = targets_of(tileset, 20, rng)
    depth_t, views_t, errors, hits = [], [], [], 0
    for _ in range(repeat):
        for p in targets:
            enu = local_axes(p)
            a, e = rng.uniform(0, 2 * math.pi), math.radians(rng.uniform(15, 50))
            back = np.array([math.cos(e) * math.sin(a), math.cos(e) * math.cos(a),
                             math.sin(e)]) @ enu
            o = p + 20.0 * back
            rays = Rays(o[None], (p - o)[None], np.array([1e-3]))
            t0 = time.perf_counter()
            hint = depth_on_ray(folder, rays)
            depth_t.append(time.perf_counter() - t0)
            if hint["hit"]:
                hits += 1
                errors.append(abs(hint["depth_m"] - 20.0))
            t0 = time.perf_counter()
            views_for_point(folder, rays, p, 4, math.radians(60), 1280, 720)
            views_t.append(time.perf_counter() - t0)
    print(f"  depth  {ms(depth_t)}; hits {hits}/{len(depth_t)}, median |depth - target| "
          f"{1000 * statistics.median(errors):.0f} mm (occluders included)")
    print(f"  views  {ms(views_t)} (k = 4)")


def bench_match(repeat: int) -> None:
    rng = np.random.default_rng(3)
    noise = cv2.GaussianBlur(rng.uniform(0, 255, (1024, 1024)).astype(np.float32), (0, 0), 3)
    tex = (noise - noise.mean()) / noise.std() * 45 + 128
    origin = np.array([3_980_000.0, 10_000.0, 4_966_000.0])
    enu = local_axes(origin)
    e, n, u = enu

    def to_ecef(local: np.ndarray) -> np.ndarray:
        return origin + np.asarray(local, dtype=np.float64) @ enu

    def texel(ab: np.ndarray) -> np.ndarray:
        return to_ecef(np.stack([(ab[:, 0] - 511.5) * 0.01, (511.5 - ab[:, 1]) * 0.01,
                                 np.zeros(len(ab))], axis=1))

    def render(cam: Camera) -> np.ndarray:
        corners = np.array([[0.0, 0.0], [1023.0, 0.0], [1023.0, 1023.0], [0.0, 1023.0]])
        xy, _ = cam.project(texel(corners))
        hom = cv2.getPerspectiveTransform(corners.astype(np.float32),
                                          (xy - 0.5).astype(np.float32))
        return cv2.warpPerspective(tex, hom, (1280, 720))

    fovy = math.radians(60)
    ref = Camera.look_at(to_ecef([0.4, -0.3, 8.0]), to_ecef([0.4, -0.3, 0]), n, fovy, 1280, 720)
    a = math.radians(40)
    tgt = Camera.look_at(to_ecef([9 * math.sin(a) + 0.4, -0.3, 9 * math.cos(a)]),
                         to_ecef([0.4, -0.3, 0]), u, fovy, 1280, 720)
    ri, ti = View(render(ref), np.zeros(2), ref), View(render(tgt), np.zeros(2), tgt)
    click = np.array([652.3, 371.8])
    d = ref.pick_ray(click)[0]
    t = float(((origin - ref.position) @ u) / (d @ u))
    truth, _ = tgt.project(ref.position + t * d)
    print("\nmatch (1280x720 pair, 40 degrees apart, 25 px patch):")
    for near, far in ((t - 0.25, t + 0.25), (t - 2, t + 8), (0.5, t + 100)):
        times, err = [], []
        for _ in range(repeat * 10):
            t0 = time.perf_counter()
            res = match_feature(ri, click, ti, near, far, t)
            times.append(time.perf_counter() - t0)
            err.append(float(np.linalg.norm(res.pixel - truth[0])) if res.ok else math.nan)
        print(f"  segment {far - near:6.1f} m: {ms(times)}; ok {res.ok}, "
              f"error {max(err):.3f} px")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=None,
                    help="data folder holding (or to hold) the demo scene")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, numpy {np.__version__}, OpenCV {cv2.__version__}; "
          f"load average {os.getloadavg()[0]:.1f}")
    data = args.data or Path(tempfile.mkdtemp(prefix="gsgeo-aim-bench-"))
    demo = data / "scenes" / "demo"
    if not (demo / "tileset.json").is_file():
        from gsgeo.demo.build import build_demo

        build_demo(data, progress=None)
    rng = np.random.default_rng(20)
    bench_scene("demo", demo, args.repeat, rng)
    if (WHITE / "tileset.json").is_file():
        bench_scene("white-sculpture", WHITE, args.repeat, rng)
    else:
        print("\n../shared/data/white-sculpture is not present: skipped")
    bench_match(args.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
