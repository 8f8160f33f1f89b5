// Ids for a new point: the next free P<n>, or the id of the unmeasured check or control point
// nearest to the solution. No Cesium here (tested in Node.js).

/** How far (m) a check or control point may lie from the solved point and still be offered as
 *  its id: far beyond any measuring error, well inside the spacing of surveyed marks. */
export const SUGGEST_RADIUS_M = 1.0;

/** The next free automatic point id P<n> (above every stored P<number>). */
export function nextPointId(points) {
  const used = new Set(points.map((p) => p.id));
  let n = 1;
  for (const p of points) {
    const m = /^P(\d+)$/.exec(p.id);
    if (m) n = Math.max(n, Number(m[1]) + 1);
  }
  while (used.has(`P${n}`)) n++;
  return `P${n}`;
}

const GEOGRAPHIC = new Set(["EPSG:4979", "EPSG:4326", "OGC:CRS84", "EPSG:4937", "EPSG:4258"]);
const M_PER_DEG = 111320; // metres per degree of latitude (and of longitude at the equator)

/** Distance (m) from solution `res` (the /intersect answer: easting, northing, height in its
 *  `crs`; lon, lat, h_wgs84) to check point `c` ({x, y, z, crs}); null when they are not in
 *  one frame this can compare (a check point in another projected CRS). */
export function distanceTo(res, c) {
  const crs = String(c.crs || "").toUpperCase();
  const sq = (a) => a * a;
  const dz = (h) => (c.z === null || c.z === undefined || !Number.isFinite(h) ? 0 : c.z - h);
  if (res.crs && crs === String(res.crs).toUpperCase() && Number.isFinite(res.easting)) {
    return Math.sqrt(sq(c.x - res.easting) + sq(c.y - res.northing) + sq(dz(res.height)));
  }
  if (GEOGRAPHIC.has(crs) && Number.isFinite(res.lon)) {
    const de = (c.x - res.lon) * M_PER_DEG * Math.cos((res.lat * Math.PI) / 180);
    const dn = (c.y - res.lat) * M_PER_DEG;
    return Math.sqrt(sq(de) + sq(dn) + sq(crs === "EPSG:4979" ? dz(res.h_wgs84) : 0));
  }
  return null;
}

/** The id to offer for a new point solved as `res`: the nearest check or control point of
 *  `checkPoints` that no point of `points` measures yet, within `radius` m; else the next P<n>. */
export function suggestPointId(res, checkPoints, points, radius = SUGGEST_RADIUS_M) {
  const measured = new Set(points.map((p) => p.id));
  let best = null;
  let bestD = radius;
  if (res) {
    for (const c of checkPoints || []) {
      if (measured.has(c.id)) continue;
      const d = distanceTo(res, c);
      if (d !== null && d <= bestD) { bestD = d; best = c.id; }
    }
  }
  return best || nextPointId(points);
}
