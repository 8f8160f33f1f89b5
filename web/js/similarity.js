// A georeference change is a similarity S (4x4 column-major, ECEF -> ECEF: y = s Q x + t)
// put in front of the tileset's root transform. Pure helpers: its parameters in words, the
// camera carried along so the view stays on the same feature, the scene's georeference state.

/** The parameters of similarity `m16` (column-major 4x4): scale s, scale - 1 in ppm, the
 *  rotation Q as an angle (degrees) about a unit axis (ECEF), the translation t (m). */
export function decompose(m16) {
  const a = [[m16[0], m16[4], m16[8]], [m16[1], m16[5], m16[9]], [m16[2], m16[6], m16[10]]];
  const det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
    - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
    + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
  const s = Math.cbrt(det);
  const q = a.map((row) => row.map((x) => x / s));
  const cos = Math.min(1, Math.max(-1, (q[0][0] + q[1][1] + q[2][2] - 1) / 2));
  const axis = [q[2][1] - q[1][2], q[0][2] - q[2][0], q[1][0] - q[0][1]];
  const n = Math.hypot(...axis);
  return {
    scale: s,
    ppm: (s - 1) * 1e6,
    rotation: q,
    angleDeg: (Math.acos(cos) * 180) / Math.PI,
    axis: n > 0 ? axis.map((x) => x / n) : [0, 0, 1],
    translation: [m16[12], m16[13], m16[14]],
  };
}

/** y = S x for a point x (ECEF, metres). */
export function applySimilarity(m16, x) {
  return [0, 1, 2].map((i) => m16[i] * x[0] + m16[4 + i] * x[1] + m16[8 + i] * x[2] + m16[12 + i]);
}

/** A camera {position, direction, up} (ECEF) carried by S: the position S p, the direction
 *  and up turned by S's rotation. The frustum keeps its angles, so the view shows the same
 *  features at the same pixels, from s times the distance. */
export function moveCamera(m16, camera) {
  const { scale, rotation } = decompose(m16);
  const turn = (v) => rotation.map((row) => row[0] * v[0] + row[1] * v[1] + row[2] * v[2]);
  return {
    position: applySimilarity(m16, camera.position),
    direction: turn(camera.direction),
    up: turn(camera.up),
    scale,
  };
}

/** The georeference version of a loaded tileset's extras (extras.gsgeo.georef.version; 0 when
 *  absent): sent with every stored point, the frame its rays were taken in. */
export function georefVersion(extras) {
  const v = extras && extras.gsgeo && extras.gsgeo.georef ? extras.gsgeo.georef.version : 0;
  return Number.isInteger(v) && v >= 0 ? v : 0;
}

/** Whether a scene of /api/scenes is not georeferenced: never fitted (georeferenced false), or
 *  placed at latitude 0, longitude 0 (gsgeo tiles without a georeference). */
export function notGeoreferenced(info) {
  if (!info) return false;
  if (info.georeferenced === false) return true;
  const o = info.origin;
  return Boolean(o) && Math.abs(o.lat) < 1e-6 && Math.abs(o.lon) < 1e-6;
}

/** Whether similarity `m16` leaves the scene where it is: scale within 0.001 ppm of 1, rotation
 *  under 1e-6 degrees, and `centre` (ECEF; the origin when null) moved less than 0.1 mm (a
 *  fit of a scene that already has its result). */
export function changesNothing(m16, centre) {
  const d = decompose(m16);
  const c = centre || [0, 0, 0];
  const moved = applySimilarity(m16, c);
  return Math.abs(d.ppm) < 1e-3 && d.angleDeg < 1e-6 && Math.hypot(...moved.map((x, i) => x - c[i])) < 1e-4;
}

/** The lines of the confirmation of an Apply: what will change. `fit` is the preview's
 *  GeorefResult, `centre` the scene's centre (ECEF) or null, `projects` [{name, points}] of
 *  every project on the scene. */
export function applySummary(fit, centre, projects) {
  const d = decompose(fit.matrix);
  const lines = [];
  const ppm = Math.round(d.ppm).toLocaleString("en-GB");
  const sig = Number.isFinite(fit.scale_sigma) ? ` ± ${(fit.scale_sigma * 1e6).toFixed(1)} ppm` : "";
  lines.push(`Scale: × ${d.scale.toFixed(6)} (${d.ppm >= 0 ? "+" : ""}${ppm} ppm${sig})`);
  lines.push(`Rotation: ${d.angleDeg.toFixed(4)}° about the axis (${d.axis.map((x) => x.toFixed(3)).join(", ")}) (ECEF)`);
  if (centre) {
    const moved = applySimilarity(fit.matrix, centre);
    const shift = Math.hypot(...moved.map((x, i) => x - centre[i]));
    lines.push(`Shift: the scene's centre moves ${shift < 1000 ? `${shift.toFixed(3)} m` : `${(shift / 1000).toFixed(3)} km`}`);
  } else {
    lines.push(`Shift: translation (${fit.translation.map((x) => x.toFixed(3)).join(", ")}) m (ECEF)`);
  }
  if (fit.outliers && fit.outliers.length) {
    lines.push(`Outliers kept in the fit (you accept them): ${fit.outliers.join(", ")}`);
  }
  const total = projects.reduce((n, p) => n + p.points, 0);
  lines.push(`Re-solved: ${total} point${total === 1 ? "" : "s"} in ${projects.length} project${projects.length === 1 ? "" : "s"} on this scene`
    + (projects.length ? ` (${projects.map((p) => `${p.name}: ${p.points}`).join(", ")})` : ""));
  lines.push("The tiles are not rewritten: only the scene's root transform changes; Undo restores it.");
  return lines;
}
