"""Helpers for the web workplace tests: a scene made by `gsgeo tiles`, `gsgeo serve`, Chromium,
and JavaScript that places the camera and projects a world point to its window position."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyproj

from tests.e2e.scene import write_scene_ply

REPO = Path(__file__).resolve().parents[2]
CESIUM_JS = REPO / "web" / "node_modules" / "cesium" / "Build" / "Cesium" / "Cesium.js"
CHROMIUM = Path("/usr/bin/chromium")
#: The software renderer the browser tests draw with: "llvmpipe" (Mesa's, through ANGLE on
#: EGL; the default: the browser tests take 382 s alone on two cores against 630 s) or
#: "swiftshader" (Chromium's own, what it uses where there is no GPU); GSGEO_TEST_GL picks.
GL = os.environ.get("GSGEO_TEST_GL", "llvmpipe")
GL_ARGS = {"swiftshader": ["--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
           "llvmpipe": ["--use-angle=gl-egl", "--ignore-gpu-blocklist"]}
CHROMIUM_ARGS = ["--headless", "--no-sandbox", *GL_ARGS[GL], "--disable-background-networking",
                 "--disable-component-update", "--no-first-run"]
ARTIFACTS = REPO / "artifacts"

#: Where the scene's local ENU frame sits: latitude, longitude (degrees), ellipsoidal height (m).
ORIGIN = (51.5, -0.12, 45.0)
SCENE = "box"


def enu_to_ecef(enu) -> np.ndarray:
    """Local ENU coordinates at ORIGIN (metres) -> ECEF (EPSG:4978) (docs/architecture.md's rotation)."""
    lat, lon, h = ORIGIN
    o = np.array(pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
                 .transform(lon, lat, h))
    phi, lam = np.radians(lat), np.radians(lon)
    r = np.array([[-np.sin(lam), np.cos(lam), 0.0],
                  [-np.sin(phi) * np.cos(lam), -np.sin(phi) * np.sin(lam), np.cos(phi)],
                  [np.cos(phi) * np.cos(lam), np.cos(phi) * np.sin(lam), np.sin(phi)]])
    return o + r.T @ np.asarray(enu, dtype=float)


def up_vector() -> np.ndarray:
    lat, lon, _ = ORIGIN
    phi, lam = np.radians(lat), np.radians(lon)
    return np.array([np.cos(phi) * np.cos(lam), np.cos(phi) * np.sin(lam), np.sin(phi)])


def make_data_dir(root: Path) -> Path:
    """DATA dir with scenes/box made by `gsgeo tiles` from the generated PLY."""
    ply = write_scene_ply(root / "scene.ply")
    data = root / "data"
    lat, lon, h = ORIGIN
    subprocess.run([sys.executable, "-m", "gsgeo", "tiles", str(ply), "-o",
                    str(data / "scenes" / SCENE), "--origin", f"{lat},{lon},{h}", "--quiet"],
                   cwd=REPO, check=True, capture_output=True, text=True)
    return data


#: Place the camera `range` m from `target` (rendered ECEF) at azimuth/elevation (degrees, in
#: the target's ENU frame), looking at target + `lookOffset` (m, ENU) so the target is off the
#: image centre; return the target's window position (page CSS pixels) and the distance of the
#: pick ray through that position from the target (a check of the projection, metres).
AIM_JS = """([target, azDeg, elDeg, range, lookOffset]) => {
  const C = Cesium, v = gsgeo.viewer;
  const K = new C.Cartesian3(target[0], target[1], target[2]);
  const enu = C.Transforms.eastNorthUpToFixedFrame(K);
  const az = C.Math.toRadians(azDeg), el = C.Math.toRadians(elDeg);
  const local = new C.Cartesian3(range * Math.cos(el) * Math.sin(az),
                                 range * Math.cos(el) * Math.cos(az), range * Math.sin(el));
  const pos = C.Matrix4.multiplyByPoint(enu, local, new C.Cartesian3());
  const look = C.Matrix4.multiplyByPoint(enu, new C.Cartesian3(...lookOffset), new C.Cartesian3());
  const V = () => new C.Cartesian3();
  const dir = C.Cartesian3.normalize(C.Cartesian3.subtract(look, pos, V()), V());
  const upGuess = C.Matrix4.multiplyByPointAsVector(enu, C.Cartesian3.UNIT_Z, new C.Cartesian3());
  const right = C.Cartesian3.normalize(C.Cartesian3.cross(dir, upGuess, V()), V());
  const up = C.Cartesian3.cross(right, dir, new C.Cartesian3());
  v.camera.cancelFlight();  // a flight still under way (V) would move the camera after this
  v.camera.setView({destination: pos, orientation: {direction: dir, up: up}});
  const win = C.SceneTransforms.worldToWindowCoordinates(v.scene, K);
  const ray = v.camera.getPickRay(win);
  const w = C.Cartesian3.subtract(K, ray.origin, new C.Cartesian3());
  const along = C.Cartesian3.dot(w, ray.direction);
  const perp = C.Cartesian3.subtract(w, C.Cartesian3.multiplyByScalar(ray.direction, along, V()), V());
  const rect = v.scene.canvas.getBoundingClientRect();
  return {x: rect.left + win.x, y: rect.top + win.y, win: [win.x, win.y],
          canvas: [v.scene.canvas.clientWidth, v.scene.canvas.clientHeight],
          dist: C.Cartesian3.magnitude(perp)};
}"""

#: Four to five viewpoints (azimuth, elevation in degrees, range in m, look offset ENU m).
VIEWPOINTS = [
    (30.0, 35.0, 9.0, (0.6, -0.4, 0.0)),
    (120.0, 45.0, 8.0, (-0.5, 0.3, -0.3)),
    (215.0, 30.0, 10.0, (0.4, 0.5, 0.2)),
    (300.0, 55.0, 7.0, (-0.3, -0.6, 0.0)),
]
