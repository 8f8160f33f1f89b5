// Guidance for manual clicks while a point is measured: in the current view, each ray's
// epipolar line with the segment where the feature can lie (near..far of the scene's splats
// along the ray, from POST /api/scenes/{scene}/depth), the first ray's depth hint as a
// provisional point, and from two rays the predicted pixel of the solution with its 95 %
// error ellipse. Painted with the measuring overlay's 2-D canvas (after every frame, so after
// every camera change, and when only the drawing changed) and exposed as window.gsgeo.guide.
//
// Frames: rays and depth points are in rendered ECEF (metres); the solution's point_ecef and
// cov_ecef are carried into it by the tileset's current modelMatrix. Window coordinates are
// Cesium's: CSS pixels, origin at the canvas' top-left corner, x right, y down.

import { api } from "./api.js";
import { add, cross, dot, norm, scale, sub, applyPoint, transformCovariance } from "./linalg.js";
import { viewOf } from "./overlay.js";

/** Scale of the 2-D 95 % ellipse: sqrt of chi-square(2) at 0.95. */
export const SCALE_95_2D = Math.sqrt(5.991);

const STYLE = {
  segment: "#ff4fd8",
  predicted: "#39ff14",
  depth: "#ffffff",
};

// the /depth answer of each ray object (kept off the ray, which is sent to the server as it is)
const depths = new WeakMap();
const pending = new WeakMap();

/** The current camera as the shared interface's Camera object: position, unit direction and
 *  up (rendered ECEF), vertical field of view (rad), canvas size (CSS px); null when the
 *  frustum is not perspective. */
export function currentCamera(viewer) {
  const v = viewOf(viewer);
  if (!v) return null;
  const { position, direction, up, fovy, width, height } = v;
  return { position, direction, up, fovy, width, height };
}

/** The pinhole of `camera`: f (px), right, and the depth of a point along the view direction. */
function pinhole(camera) {
  const f = camera.height / (2 * Math.tan(camera.fovy / 2));
  return { f, right: cross(camera.direction, camera.up) };
}

/** Window position [x, y] of rendered-ECEF point `p` seen by `camera`, or null behind it. */
export function project(camera, p) {
  const { f, right } = pinhole(camera);
  const d = sub(p, camera.position);
  const c = dot(d, camera.direction);
  if (!(c > 0)) return null;
  return [camera.width / 2 + (f * dot(d, right)) / c, camera.height / 2 - (f * dot(d, camera.up)) / c];
}

/** The 2x2 covariance (px²) of the window position of a point at `p` with 3x3 covariance
 *  `cov` (m², rendered ECEF), through the projection's Jacobian at `p`. */
export function projectCovariance(camera, p, cov) {
  const { f, right } = pinhole(camera);
  const d = sub(p, camera.position);
  const a = dot(d, right);
  const b = dot(d, camera.up);
  const c = dot(d, camera.direction);
  // x = W/2 + f a / c, y = H/2 - f b / c
  const jx = sub(scale(right, f / c), scale(camera.direction, (f * a) / (c * c)));
  const jy = sub(scale(camera.direction, (f * b) / (c * c)), scale(camera.up, f / c));
  const cj = (j) => [0, 1, 2].map((r) => dot(cov[r], j));
  const sxx = dot(jx, cj(jx));
  const syy = dot(jy, cj(jy));
  const sxy = dot(jx, cj(jy));
  return [[sxx, sxy], [sxy, syy]];
}

/** The ellipse k * sqrt(eigenvalues) of a 2x2 covariance (px²): semi-axes [major, minor] (px)
 *  and the major axis' angle (degrees from +x towards +y, i.e. clockwise on screen). */
export function ellipse2(cov2, k) {
  const [[sxx, sxy], [, syy]] = cov2;
  const mean = (sxx + syy) / 2;
  const r = Math.hypot((sxx - syy) / 2, sxy);
  const l1 = Math.max(mean + r, 0);
  const l2 = Math.max(mean - r, 0);
  const angle = 0.5 * Math.atan2(2 * sxy, sxx - syy);
  return { axes: [k * Math.sqrt(l1), k * Math.sqrt(l2)], angle_deg: (angle * 180) / Math.PI };
}

/** Segment a..b (rendered ECEF) in window coordinates, cut where it passes behind the camera's
 *  near plane; null when it is wholly behind. */
function projectSegment(camera, a, b, near) {
  const depth = (p) => dot(sub(p, camera.position), camera.direction);
  let pa = a;
  let pb = b;
  const da = depth(a);
  const db = depth(b);
  if (da < near && db < near) return null;
  if (da < near || db < near) {
    const t = (near - da) / (db - da);
    const cut = add(a, scale(sub(b, a), t));
    if (da < near) pa = cut; else pb = cut;
  }
  return [project(camera, pa), project(camera, pb)];
}

function unit(v) {
  const n = norm(v);
  return n > 0 ? scale(v, 1 / n) : v;
}

/** The /depth answer of `ray` when known (null while asked or when the server has none). */
export function depthOf(ray) {
  return depths.get(ray) || null;
}

/** Whether `ray` is known to hit no splat (a click on the sky). */
export function hitsNothing(ray) {
  const d = depths.get(ray);
  return Boolean(d && d.hit === false);
}

/** Ask the server where the splats are along `ray` (once per ray); resolves to the answer, or
 *  null where the server cannot tell (a static scene host, an older server, no scene). */
export function requestDepth(ctx, ray) {
  if (depths.has(ray)) return Promise.resolve(depths.get(ray));
  if (pending.has(ray)) return pending.get(ray);
  const scene = ctx.state.sceneName;
  if (!scene) return Promise.resolve(null);
  const p = api("POST", `/scenes/${encodeURIComponent(scene)}/depth`, { ray })
    .then((res) => { depths.set(ray, res); return res; })
    .catch(() => { depths.set(ray, null); return null; }) // not asked again
    .finally(() => { pending.delete(ray); refresh(ctx); });
  pending.set(ray, p);
  return p;
}

/** The provisional point of the measurement: the first ray's depth hint (rendered ECEF), or
 *  null while it is unknown or the ray hits nothing. */
export function depthHint(m) {
  const first = m && m.rays.find((r, i) => !m.excluded.has(i) && depths.get(r) && depths.get(r).hit);
  if (!first) return null;
  const d = depths.get(first);
  const point = d.point_ecef || add(first.origin, scale(unit(first.direction), d.depth_m));
  return { point_ecef: point, depth_m: d.depth_m, ray: m.rays.indexOf(first) };
}

/** Everything the guide shows for measurement `m` in view `camera` (see window.gsgeo.guide):
 *  {camera, epipolar: [{ray, segment, line, hit}], predicted, depth}. `reach(origin)` is how
 *  far (m) a ray without a depth answer is drawn; `modelMatrix` carries the solution into the
 *  rendered frame. */
export function compute(m, camera, modelMatrix, reach) {
  const out = { camera, epipolar: [], predicted: null, depth: null };
  if (!m || !camera) return out;
  const near = 0.1;
  m.rays.forEach((ray, i) => {
    if (m.excluded.has(i)) return;
    const d = unit(ray.direction);
    const at = (t) => add(ray.origin, scale(d, t));
    const answer = depths.get(ray);
    const hit = answer ? answer.hit : null;
    const entry = { ray: i, hit, segment: null, line: projectSegment(camera, ray.origin, at(reach(ray.origin)), near) };
    if (answer && answer.hit && Number.isFinite(answer.near_m) && Number.isFinite(answer.far_m)) {
      entry.segment = projectSegment(camera, at(answer.near_m), at(answer.far_m), near);
    }
    out.epipolar.push(entry);
  });
  const hint = depthHint(m);
  if (hint) out.depth = { point_ecef: hint.point_ecef, depth_m: hint.depth_m, pixel: project(camera, hint.point_ecef) };
  const res = m.solution;
  if (res && res.point_ecef && res.cov_ecef) {
    const p = applyPoint(modelMatrix, res.point_ecef);
    const pixel = project(camera, p);
    if (pixel) {
      const cov2 = projectCovariance(camera, p, transformCovariance(modelMatrix, res.cov_ecef));
      out.predicted = { pixel, ellipse: { center: pixel, ...ellipse2(cov2, SCALE_95_2D) } };
    }
  }
  return out;
}

function stroke(g, width, color) {
  g.lineWidth = width + 2;
  g.strokeStyle = "rgba(0,0,0,0.6)";
  g.stroke();
  g.lineWidth = width;
  g.strokeStyle = color;
  g.stroke();
}

/** Radius (CSS px) kept clear of every drawing around the predicted pixel (or, before there
 *  is one, the depth hint): the feature to aim at stays seen, the hints are beside it. */
export const CLEAR_PX = 5;

/** Draw guide `gd` on the 2-D context `g` (CSS px), then clear the disc of CLEAR_PX around
 *  the pixel the operator aims at of everything the overlay drew there (rays, segments, the
 *  ellipse and the ellipsoid's outline pass through it). */
function paint(g, gd) {
  draw(g, gd);
  const at = gd.predicted ? gd.predicted.pixel : (gd.depth && gd.depth.pixel);
  if (!at) return;
  g.save();
  g.globalCompositeOperation = "destination-out";
  g.beginPath();
  g.arc(at[0], at[1], CLEAR_PX, 0, 2 * Math.PI);
  g.fill();
  g.restore();
}

function draw(g, gd) {
  g.setLineDash([]);
  g.lineCap = "round";
  for (const e of gd.epipolar) {
    if (!e.segment) continue;
    const [[x0, y0], [x1, y1]] = e.segment;
    const len = Math.hypot(x1 - x0, y1 - y0);
    g.beginPath();
    g.moveTo(x0, y0);
    g.lineTo(x1, y1);
    // ticks across the near and far ends
    if (len > 0) {
      const nx = (-(y1 - y0) / len) * 7;
      const ny = ((x1 - x0) / len) * 7;
      for (const [x, y] of e.segment) { g.moveTo(x - nx, y - ny); g.lineTo(x + nx, y + ny); }
    }
    stroke(g, 4, STYLE.segment);
  }
  if (gd.depth && gd.depth.pixel && !gd.predicted) {
    const [x, y] = gd.depth.pixel;
    g.beginPath();
    g.moveTo(x, y - 7); g.lineTo(x + 7, y); g.lineTo(x, y + 7); g.lineTo(x - 7, y); g.closePath();
    stroke(g, 2, STYLE.depth);
    g.font = "12px sans-serif";
    g.fillStyle = STYLE.depth;
    g.fillText("depth hint", x + 10, y - 8);
  }
  if (gd.predicted) {
    const [x, y] = gd.predicted.pixel;
    const { axes, angle_deg: angle } = gd.predicted.ellipse;
    g.beginPath();
    // a crosshair with a gap, so the feature under it stays visible
    for (const [dx, dy] of [[1, 0], [-1, 0], [0, 1], [0, -1]]) {
      g.moveTo(x + dx * 8, y + dy * 8);
      g.lineTo(x + dx * 20, y + dy * 20);
    }
    stroke(g, 2, STYLE.predicted);
    if (axes.every(Number.isFinite)) {
      g.beginPath();
      g.ellipse(x, y, Math.max(axes[0], 0.5), Math.max(axes[1], 0.5), (angle * Math.PI) / 180, 0, 2 * Math.PI);
      stroke(g, 1.5, STYLE.predicted);
    }
  }
}

/** The guide changed (a depth answer came): paint the overlay again (overlay.js: without a
 *  frame of the scene while the camera stands still). */
export function refresh(ctx) {
  if (ctx && ctx.draw) ctx.draw.overlay.repaint();
}

/** Install the guide: painted on `overlay`'s canvas whenever it is painted (after its own
 *  drawing, for the view the scene canvas shows), exposed as window.gsgeo.guide (computed for
 *  the camera of that moment). */
export function installGuide(ctx, overlay) {
  const reach = (origin) => {
    const ts = ctx.state.tileset;
    if (!ts) return 50;
    const bs = ts.boundingSphere;
    return norm(sub([bs.center.x, bs.center.y, bs.center.z], origin)) + bs.radius;
  };
  const now = () => compute(ctx.state.measure, currentCamera(ctx.viewer), ctx.modelMatrix(), reach);
  Object.defineProperty(window.gsgeo, "guide", { get: now, configurable: true });
  overlay.onPaint((g, view) => {
    const m = ctx.state.measure;
    if (!m || !m.rays.length) return;
    paint(g, compute(m, view, ctx.modelMatrix(), reach));
  });
}
