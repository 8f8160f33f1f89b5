// The arithmetic of navigate.js, free of the browser (tested in Node.js): wheel notches, the
// camera's position after a zoom about a point (ECEF, metres), a scale bar's length.

/** Distance factor of one wheel notch towards the point (its inverse away from it). */
export const ZOOM_STEP = 0.8;
/** How close (m) a zoom may bring the camera to the surface it zooms to. */
export const MIN_GAP_M = 0.3;
/** A zoom out stops at this many scene radii from the scene's centre. */
export const MAX_RANGE_RADII = 8;

/** Wheel notches of a WheelEvent: positive towards the scene (the wheel turned away from the
 *  operator, deltaY < 0). One notch is 100 px (deltaMode 0), 3 lines (1) or a page (2). */
export function notches(ev) {
  const per = ev.deltaMode === 1 ? 3 : ev.deltaMode === 2 ? 1 : 100;
  return -ev.deltaY / per;
}

/** The camera position after zooming `n` notches (positive: towards) about point `p` from
 *  position `c` (both ECEF, metres): on the line through them, the distance times
 *  ZOOM_STEP^n, never closer than `minGap`; null when the camera is already as close. */
export function zoomedPosition(c, p, n, minGap = MIN_GAP_M) {
  const v = [0, 1, 2].map((k) => c[k] - p[k]);
  const dist = Math.hypot(...v);
  if (!(dist > 0)) return null;
  const want = Math.max(dist * ZOOM_STEP ** n, minGap);
  if (n > 0 && want >= dist) return null;
  return [0, 1, 2].map((k) => p[k] + (v[k] / dist) * want);
}

/** A length for a scale bar of at most `maxPx` pixels at `metresPerPx`: the largest of 1, 2, 5
 *  times a power of ten that fits, and its width in pixels. */
export function scaleBar(metresPerPx, maxPx = 120) {
  if (!(metresPerPx > 0) || !Number.isFinite(metresPerPx)) return null;
  const most = metresPerPx * maxPx;
  const p = 10 ** Math.floor(Math.log10(most));
  const m = [5, 2, 1].map((k) => k * p).find((x) => x <= most);
  return { metres: m, px: m / metresPerPx, label: m >= 1000 ? `${m / 1000} km` : m >= 1 ? `${m} m` : `${Math.round(m * 100)} cm` };
}

/** A drag shorter than this (CSS px) is a click, not a move (Cesium's click tolerance). */
export const DRAG_START_PX = 5;
/** Orbit: degrees of turn per CSS pixel of drag. */
export const ORBIT_DEG_PER_PX = 0.25;
/** Orbit: the camera stays between these elevations (deg) seen from the pivot: above the
 *  ground, and short of straight overhead (where heading is undefined). */
export const ORBIT_MIN_ELEVATION_DEG = 2;
export const ORBIT_MAX_ELEVATION_DEG = 88;

const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const unit = (a) => scale(a, 1 / Math.hypot(...a));

/** Vector `v` turned by `angle` (rad) about unit axis `k` (Rodrigues). */
export function rotate(v, k, angle) {
  const c = Math.cos(angle);
  const s = Math.sin(angle);
  return add(add(scale(v, c), scale(cross(k, v), s)), scale(k, dot(k, v) * (1 - c)));
}

/** The camera position (ECEF, m) after a pan by a drag of (dx, dy) CSS px (x right, y down)
 *  from position `p0` with unit `right` and `up` vectors, `metresPerPx` at the grabbed point's
 *  depth: the camera moves in its image plane so that the grabbed point follows the cursor. */
export function pannedPosition(p0, right, up, dx, dy, metresPerPx) {
  return add(p0, add(scale(right, -dx * metresPerPx), scale(up, dy * metresPerPx)));
}

/** Metres per CSS pixel at view depth `depth` (m) for vertical field of view `fovy` (rad) on a
 *  canvas `heightPx` CSS px high. */
export function metresPerPixel(depth, fovy, heightPx) {
  return (2 * Math.tan(fovy / 2) * depth) / heightPx;
}

/** The camera pose after orbiting about `pivot` (ECEF, m) with local vertical `vertical`
 *  (unit, the ellipsoid normal there): `pitch` (rad, positive raises the camera) about the
 *  level axis through the pivot square to the camera's bearing, limited so the camera stays
 *  between ORBIT_MIN/MAX_ELEVATION_DEG as seen from the pivot, then `yaw` (rad) about the
 *  vertical. `pose` is {position, direction, up} (ECEF; direction and up unit). The camera
 *  turns as a rigid body about the pivot, so the pivot stays at its pixel. */
export function orbitedPose(pose, pivot, vertical, yaw, pitch) {
  const rel0 = sub(pose.position, pivot);
  const e0 = Math.asin(Math.max(-1, Math.min(1, dot(unit(rel0), vertical))));
  const lo = (ORBIT_MIN_ELEVATION_DEG * Math.PI) / 180;
  const hi = (ORBIT_MAX_ELEVATION_DEG * Math.PI) / 180;
  // within the limits; a camera already beyond one may only come back
  const a = pitch > 0 ? Math.min(pitch, Math.max(0, hi - e0)) : Math.max(pitch, Math.min(0, lo - e0));
  const level = cross(rel0, vertical); // rotating rel0 about this raises it
  const k = Math.hypot(...level) > 1e-12 ? unit(level) : unit(cross(pose.direction, pose.up));
  let rel = rotate(rel0, k, a);
  let dir = rotate(pose.direction, k, a);
  let up = rotate(pose.up, k, a);
  rel = rotate(rel, vertical, yaw);
  dir = rotate(dir, vertical, yaw);
  up = rotate(up, vertical, yaw);
  return { position: add(pivot, rel), direction: dir, up, pitch: a };
}

/** WGS 84's semi-axes (m). */
const WGS84_A = 6378137.0;
const WGS84_B = 6356752.314245179;

/** Heading (rad, clockwise from north, 0..2 pi) of a camera at ECEF `position` (m) looking
 *  along unit `direction` with unit `up`: the azimuth of the direction in the local
 *  east-north-up frame, or of `up` when it looks straight down or up (as Cesium's
 *  camera.heading; that getter also turns the camera's axes by rounding, so it is not read
 *  for what is drawn after every frame). */
export function headingOf(position, direction, up) {
  const [x, y, z] = position;
  const u = unit([x / WGS84_A ** 2, y / WGS84_A ** 2, z / WGS84_B ** 2]);
  const e = Math.hypot(x, y) > 0 ? unit([-y, x, 0]) : [0, 1, 0];
  const n = cross(u, e);
  const v = Math.abs(dot(direction, u)) < 1 - 1e-3 ? direction : up;
  const h = Math.atan2(dot(v, e), dot(v, n));
  return h < 0 ? h + 2 * Math.PI : h;
}
