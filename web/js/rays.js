// One aim = one ray (README, "Session JSON"): the camera centre and the direction through the
// clicked pixel in rendered ECEF, the angular size of that pixel, and the tileset's modelMatrix.

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
