// How an error ellipsoid is shown: its quality against the project's tolerance (a colour)
// and the exaggeration that makes it visible at the current range. No Cesium here (tested
// in Node.js).

/** The 3-D confidence scale of 95 % (sqrt of chi-square(3) at 0.95) on each principal axis. */
export const SCALE_95_3D = 2.7955;

/** Default tolerance on the 95 % 3-D radius (the largest semi-axis of the 95 % ellipsoid),
 *  metres: up to GOOD_M a point is good (green), up to FAIR_M fair (amber), beyond poor (red).
 *  2 cm / 5 cm: a careful survey of well-defined features on a 3DGS scene reaches the first,
 *  a point beyond the second should be measured again. */
export const TOLERANCE = { GOOD_M: 0.02, FAIR_M: 0.05 };

export const QUALITY_COLORS = { good: "#3fb950", fair: "#f5b700", poor: "#ff3b30" };

/** "good" | "fair" | "poor" for a 95 % 3-D radius `r95` (m); null when not finite. */
export function quality(r95, tol = TOLERANCE) {
  if (!Number.isFinite(r95)) return null;
  return r95 <= tol.GOOD_M ? "good" : (r95 <= tol.FAIR_M ? "fair" : "poor");
}

/** The smallest factor of the 1-2-5 series (1, 2, 5, 10, 20, ... up to 10000) that draws a
 *  semi-axis of `radius` m at least `minPx` pixels long, seen from `distance` m through a
 *  perspective camera of vertical field of view `fovy` (rad) on a `heightPx` px tall view.
 *  1 when it is large enough already or the geometry is unknown. */
export function exaggeration(radius, distance, fovy, heightPx, minPx = 24) {
  if (!(radius > 0) || !(distance > 0) || !(fovy > 0) || !(heightPx > 0)) return 1;
  const px = (radius * heightPx) / (2 * distance * Math.tan(fovy / 2));
  const need = minPx / px;
  if (need <= 1) return 1;
  for (let decade = 1; decade <= 1000; decade *= 10) {
    for (const step of [1, 2, 5]) {
      if (step * decade >= need) return step * decade;
    }
  }
  return 10000;
}
