// Suggested views (key V): while a point is measured, the server proposes the viewpoints that
// most reduce its predicted uncertainty (POST /api/scenes/{scene}/views); each V flies the
// camera to the next of them, cycling. The list is asked anew when the rays or the
// provisional point change.

import { api } from "./api.js";
import { fixed, mm } from "./format.js";
import { depthHint, currentCamera } from "./guide.js";
import { applyPoint } from "./linalg.js";

const Cesium = window.Cesium;

/** How many views to ask for, and how long a flight to one takes (s). */
const K = 4;
const FLIGHT_S = 0.8;

let cache = { key: null, views: [], index: -1 };
let asking = false;

/** The provisional point of measurement `m` (rendered ECEF): the live solution, else the
 *  first ray's depth hint; null when neither is known. */
function provisionalPoint(m, modelMatrix) {
  if (m.solution && m.solution.point_ecef) return applyPoint(modelMatrix, m.solution.point_ecef);
  const hint = depthHint(m);
  return hint ? hint.point_ecef : null;
}

function keyOf(m, point) {
  const active = m.rays.filter((r, i) => !m.excluded.has(i));
  return JSON.stringify([active.map((r) => r.origin.concat(r.direction)), point.map((x) => x.toFixed(3))]);
}

function describe(v, i, n) {
  return `Suggested view ${i + 1} of ${n}: azimuth ${fixed(v.azimuth_deg, 0)}°, elevation ${fixed(v.elevation_deg, 0)}°, `
    + `${fixed(v.range_m, 1)} m; ${fixed(v.min_angle_deg, 0)}° from the rays, predicted σ ${mm(v.predicted_sigma_m)} mm`
    + `${v.occluded ? " (the point may be hidden from here)" : ""}. V again for the next.`;
}

/** Key V: fly to the next suggested view of the point being measured. */
export async function nextView(ctx) {
  const m = ctx.state.measure;
  if (!m || !m.rays.length) {
    ctx.message("V suggests where to look from once a point has a ray: press M and click the feature first.", true);
    return;
  }
  if (asking) return;
  const point = provisionalPoint(m, ctx.modelMatrix());
  if (!point) {
    ctx.message("No provisional point yet: the first ray's depth is not known (or it hits no splat).", true);
    return;
  }
  const camera = currentCamera(ctx.viewer);
  if (!camera) { ctx.message("Suggested views need a perspective camera.", true); return; }
  const key = keyOf(m, point);
  if (cache.key !== key) {
    asking = true;
    try {
      const rays = m.rays.filter((r, i) => !m.excluded.has(i));
      const res = await api("POST", `/scenes/${encodeURIComponent(ctx.state.sceneName)}/views`, {
        rays, point_ecef: point, k: K, fovy: camera.fovy, width: camera.width, height: camera.height,
      });
      cache = { key, views: res.views || [], index: -1 };
    } catch (exc) {
      ctx.fail(exc);
      return;
    } finally {
      asking = false;
    }
  }
  if (!cache.views.length) { ctx.message("The server suggests no view for this point.", true); return; }
  if (ctx.state.measure !== m) return;
  cache.index = (cache.index + 1) % cache.views.length;
  const v = cache.views[cache.index];
  const c3 = (a) => new Cesium.Cartesian3(a[0], a[1], a[2]);
  ctx.viewer.camera.flyTo({ destination: c3(v.camera.position),
    orientation: { direction: c3(v.camera.direction), up: c3(v.camera.up) }, duration: FLIGHT_S });
  ctx.message(describe(v, cache.index, cache.views.length));
}
