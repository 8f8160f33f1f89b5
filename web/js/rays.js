// One aim = one ray (README, "Session JSON"): the camera centre and the direction through the
// clicked pixel in rendered ECEF, the angular size of that pixel, and the tileset's modelMatrix.

import { IDENTITY16, applyDirection, applyPoint, norm } from "./linalg.js";

const Cesium = globalThis.Cesium;

/** The angular size (radians) of one CSS pixel at window position (x, y) of a pinhole camera
 *  with vertical field of view `fovy` on a canvas `height` CSS pixels high: the square root of
 *  the pixel's solid angle f / (f² + r²)^(3/2), i.e. the geometric mean of its radial
 *  (f / (f² + r²)) and tangential (1 / sqrt(f² + r²)) extents; f is the focal length in pixels
 *  and r the distance from the image centre. At the centre it is 2 tan(fovy / 2) / height. */
export function pixelAngle(fovy, width, height, x, y) {
  const f = height / (2 * Math.tan(fovy / 2));
  const r2 = (x - width / 2) ** 2 + (y - height / 2) ** 2;
  const q = f * f + r2;
  return Math.sqrt((f / q) * (1 / Math.sqrt(q)));
}

/** The session-JSON ray of a click at `windowPosition` (Cartesian2, CSS pixels relative to the
 *  canvas), or null when the camera is not perspective. `modelMatrix` is 16 numbers,
 *  column-major. */
export function captureRay(viewer, windowPosition, modelMatrix) {
  const camera = viewer.camera;
  const frustum = camera.frustum;
  if (!(frustum instanceof Cesium.PerspectiveFrustum)) return null;
  const canvas = viewer.scene.canvas;
  const width = canvas.clientWidth;
  const height = canvas.clientHeight;
  const ray = camera.getPickRay(windowPosition);
  if (!ray) return null;
  const o = ray.origin;
  const d = ray.direction;
  return {
    origin: [o.x, o.y, o.z],
    direction: [d.x, d.y, d.z],
    ifov: pixelAngle(frustum.fovy, width, height, windowPosition.x, windowPosition.y),
    pixel: [windowPosition.x, windowPosition.y],
    viewport: [width, height],
    model_matrix: modelMatrix,
  };
}

/** The rays of stored point `pt` in the frame the scene is rendered in now (`modelMatrix`, 16
 *  numbers column-major), to add rays to it. A point keeps its rays as taken, in the scene's
 *  frame of that time; the server's solution (pt.result.rays: origin_ecef, direction_ecef)
 *  carries them into the current one. Where a stored ray and its carried one differ by more
 *  than `tol` metres (the scene's georeference changed since), every ray is rebuilt from the
 *  carried one so that the old rays and the new clicks are in one frame; otherwise, and for a
 *  point without a solution, the stored rays are returned as they are. */
export function raysInCurrentFrame(pt, modelMatrix, tol = 1e-4) {
  const stored = pt.rays.map((r) => ({ ...r }));
  const carried = pt.result && Array.isArray(pt.result.rays) ? pt.result.rays : null;
  if (!carried || carried.length !== stored.length) return stored;
  const byIndex = new Map(carried.map((c, i) => [c.index ?? i, c]));
  const moved = stored.some((r, i) => {
    const c = byIndex.get(i);
    if (!c) return false;
    const rendered = applyPoint(r.model_matrix || IDENTITY16, c.origin_ecef);
    return norm([0, 1, 2].map((k) => rendered[k] - r.origin[k])) > tol;
  });
  if (!moved) return stored;
  return stored.map((r, i) => {
    const c = byIndex.get(i);
    if (!c) return r;
    const d = applyDirection(modelMatrix, c.direction_ecef);
    const n = norm(d);
    return { ...r, origin: applyPoint(modelMatrix, c.origin_ecef), direction: d.map((x) => x / n),
      model_matrix: modelMatrix.slice() };
  });
}
