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
