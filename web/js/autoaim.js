// Auto-aim (key A while a point is measured): the feature clicked for ray 1 is looked for in K
// suggested views by image matching on the server, and each match enters the measurement as a
// ray marked auto with its score.
//
// The flow: at the first click the rendered canvas around the clicked pixel is kept as the
// reference (with the camera it was seen from). On A: the depth of ray 1 (POST
// /api/scenes/{scene}/depth: where along it the splats are), K suggested views (POST
// /api/scenes/{scene}/views); for each view the camera is set, the splats are drawn sorted for
// it, the canvas around ray 1's epipolar segment (near..far projected into the view) is cut out
// and POST /api/scenes/{scene}/match finds the reference there (the scene's splats about the
// click weight the patch and warp it by their shape). The requests run while the next view
// renders.
// A matched pixel becomes a ray by the same math as a click (rays.js's captureRay at that
// view's camera); a declined view is reported with its reason. The camera then returns to the
// view of the first click.
//
// Frames: rays and points are in rendered ECEF (metres). Window coordinates are Cesium's: CSS
// pixels from the canvas' top-left corner, x right, y down; a crop's "origin" is the window
// position of its top-left corner.

import { api } from "./api.js";
import { autoAimDeclined, autoAimSummary, snapText } from "./autoaimtext.js";
import { fixed, h } from "./format.js";
import { currentCamera, project, requestDepth } from "./guide.js";
import { add, norm, scale } from "./linalg.js";
import { captureRay } from "./rays.js";
import { holdSplats, splatsHoldable } from "./render.js";
import { hideScenery } from "./still.js";

const Cesium = window.Cesium;

/** Views searched per A. */
export const K = 4;
/** Half size (px) of the reference crop around the click: the matcher takes a 25 px patch,
 *  warped by the view change, so an oblique view reaches far around the click. */
const REF_HALF = 256;
/** Margin (px) of the target crop around the projected epipolar segment (the matcher asks ~20). */
const MARGIN = 28;
/** Half size (px) of a match's thumbnail. */
const THUMB_HALF = 24;
/** How long one view may take to be drawn before it is given up (ms). */
const VIEW_TIMEOUT_MS = 120000;

const references = new WeakMap(); // ray 1 object -> Promise of {camera, image, origin, pixel}
const cameras = new WeakMap(); // ray 1 object -> the Camera it was clicked from
const thumbs = new WeakMap(); // auto ray object -> data URL of its match thumbnail
const snaps = new WeakMap(); // ray 1 snapped onto its feature -> how far it moved (px)

/** The thumbnail (PNG data URL) of auto ray `ray`'s match: the target crop around the matched
 *  pixel, marked; null for a clicked ray. */
export function thumbOf(ray) {
  return thumbs.get(ray) || null;
}

function unit(v) {
  const n = norm(v);
  return n > 0 ? scale(v, 1 / n) : v;
}

function c3(a) {
  return new Cesium.Cartesian3(a[0], a[1], a[2]);
}

/** Whether the splats of tileset `t` were drawn, in the frame just rendered, in an order
 *  sorted for the viewer's camera. CesiumJS 1.145 (pinned) has no public signal: this reads
 *  the Gaussian splat primitive's state, as render.js does (revisit on a Cesium upgrade). A
 *  sort is taken as made for the camera within Cesium's own re-sort thresholds (1 m, 0.5°). */
function sortedFor(t, camera) {
  if (!t || !t.tilesLoaded) return false;
  const p = t.gaussianSplatPrimitive;
  if (!p) return true;
  const n = t.statistics.numberOfPointsSelected;
  if (!(n > 0) || p._numSplats !== n || !p._drawCommand) return false;
  if (p._pendingSnapshot || p._needsSnapshotRebuild || p._dirty || p._pendingSortPromise || p._sorterPromise) return false;
  if (p._sorterState !== 0) return false; // 0: IDLE
  if (!p._hasLastSteadySortCameraPosition) return false;
  const moved = Cesium.Cartesian3.distance(camera.positionWC, p._lastSteadySortCameraPosition);
  const turned = Cesium.Cartesian3.angleBetween(camera.directionWC, p._lastSteadySortCameraDirection);
  return moved < 1.0 && turned < 0.0087;
}

/** Cesium skips a re-sort asked within 3 frames of the last one and then waits for the next
 *  camera change: forget the last view matrix so that the next frame sorts again. */
function askSort(t) {
  const p = t && t.gaussianSplatPrimitive;
  if (p && p._prevViewMatrix && p._sorterState === 0 && !p._sorterPromise) {
    Cesium.Matrix4.clone(Cesium.Matrix4.ZERO, p._prevViewMatrix);
  }
}

/** A crop of the canvas just rendered: `box` [x0, y0, w, h] (CSS px, integers) as a canvas of
 *  CSS-px size (the drawing buffer is scaled when its pixels are not CSS px). */
function cropOf(canvas, box) {
  const [x0, y0, w, h] = box;
  const s = canvas.width / canvas.clientWidth;
  const c = document.createElement("canvas");
  c.width = w;
  c.height = h;
  c.getContext("2d").drawImage(canvas, x0 * s, y0 * s, w * s, h * s, 0, 0, w, h);
  return c;
}

/** Box [x0, y0, w, h] (integers) around window points `pts` with `margin` px all round, cut
 *  to the canvas; null when nothing of it is on the canvas. */
function boxAround(pts, margin, width, height) {
  const xs = pts.map((p) => p[0]);
  const ys = pts.map((p) => p[1]);
  const x0 = Math.max(0, Math.floor(Math.min(...xs) - margin));
  const y0 = Math.max(0, Math.floor(Math.min(...ys) - margin));
  const x1 = Math.min(width, Math.ceil(Math.max(...xs) + margin));
  const y1 = Math.min(height, Math.ceil(Math.max(...ys) + margin));
  return x1 - x0 >= 8 && y1 - y0 >= 8 ? [x0, y0, x1 - x0, y1 - y0] : null;
}

/** Set the viewer's camera to `camera` (the shared interface's Camera object). */
function setCamera(viewer, camera) {
  viewer.camera.cancelFlight();
  viewer.camera.setView({ destination: c3(camera.position),
    orientation: { direction: c3(camera.direction), up: c3(camera.up) } });
}

/** The viewer camera's pose now, to tell later whether something else moved it. */
function poseOf(viewer) {
  const c = viewer.camera;
  return { position: Cesium.Cartesian3.clone(c.positionWC), direction: Cesium.Cartesian3.clone(c.directionWC) };
}

/** Whether the camera left `pose` (more than 1 mm, or turned more than 1 microradian): the
 *  operator moved it while a capture waited for its frame. */
function movedFrom(viewer, pose) {
  const c = viewer.camera;
  return Cesium.Cartesian3.distance(c.positionWC, pose.position) > 1e-3
    || Cesium.Cartesian3.distance(c.directionWC, pose.direction) > 1e-6;
}

/** A capture's error when the operator moved the camera before its frame was drawn: the
 *  capture gives up rather than put the camera back (a reference is taken again on A). */
const MOVED = "the camera was moved before the view was drawn";

/** Render at `camera` until a frame shows the splats sorted and drawn for it, without the
 *  globe and the sky (the measuring graphics are on the overlay, not in the frame), and return
 *  the crops `boxes()` gives of that frame (canvases) and the number of frames it took. The
 *  drawing buffer is read in the frame's postRender, before the browser may clear it.
 *
 *  Speed: every frame draws all the splats, seconds each in a software renderer. Until the
 *  splats are sorted for the new camera (in a worker, over several frames) the frames would
 *  draw the old order, which is of no use here: the splat draw command of the old order is
 *  muted (instanceCount 0) meanwhile, so that only the one frame that is captured draws them.
 *  Where the splats can be drawn by parts (a scene whose snapshot holds all its tiles, as
 *  the demo's one tile) captureHeld does it in one frame of the crops' splats instead, also
 *  from the first frame in which that becomes possible (the scene's first snapshot built). */
function captureAt(ctx, camera, boxes) {
  const hold = holdSplats(ctx.state.tileset);
  if (hold) return captureHeld(ctx, hold, camera, boxes);
  const { viewer } = ctx;
  const scene = viewer.scene;
  setCamera(viewer, camera);
  const pose = poseOf(viewer);
  const restore = hideScenery(scene);
  const t = ctx.state.tileset;
  const p = t && t.gaussianSplatPrimitive;
  let muted = null;
  if (p && p._drawCommand && !sortedFor(t, viewer.camera)) {
    muted = { command: p._drawCommand, instanceCount: p._drawCommand.instanceCount };
    muted.command.instanceCount = 0;
  }
  return new Promise((resolve, reject) => {
    let frames = 0;
    let ready = false;
    const done = (fn) => {
      scene.preRender.removeEventListener(onPre);
      scene.postRender.removeEventListener(onPost);
      clearTimeout(timer);
      if (muted) muted.command.instanceCount = muted.instanceCount;
      restore();
      // no frame asked here: the next view's camera, or the return to the first view, asks
      // for one (a frame now would draw every splat again while the match is awaited)
      fn();
    };
    // the frame draws the sorted splats when, before it, the primitive's draw command is one
    // built from a sort for this camera (Cesium builds it in the frame that notices the sort
    // and draws it from the next)
    const onPre = () => {
      const tt = ctx.state.tileset;
      if (movedFrom(viewer, pose)) { done(() => reject(new Error(MOVED))); return; }
      if (splatsHoldable(tt)) {
        // the splats became drawable by parts (their first snapshot is in): this frame
        // draws only those of the crops instead
        done(() => resolve(captureHeld(ctx, holdSplats(tt), camera, boxes)));
        return;
      }
      const q = tt && tt.gaussianSplatPrimitive;
      ready = sortedFor(tt, viewer.camera) && !(muted && q && q._drawCommand === muted.command);
    };
    const onPost = () => {
      frames++;
      const tt = ctx.state.tileset;
      if (movedFrom(viewer, pose)) { done(() => reject(new Error(MOVED))); return; }
      if (ready && sortedFor(tt, viewer.camera)) {
        let crops;
        try { crops = boxes().map((b) => cropOf(scene.canvas, b)); } catch (exc) { done(() => reject(exc)); return; }
        done(() => resolve({ crops, frames }));
        return;
      }
      if (!ready && frames % 4 === 3) askSort(tt);
      scene.requestRender();
    };
    const timer = setTimeout(() => done(() => reject(new Error("the view was not drawn in time"))), VIEW_TIMEOUT_MS);
    scene.preRender.addEventListener(onPre);
    scene.postRender.addEventListener(onPost);
    scene.requestRender();
  });
}

/** captureAt when the splats can be drawn by parts (render.js's holdSplats, `hold`): one
 *  frame at `camera` that draws only the splats reaching the crops, sorted for it here (no
 *  wait for Cesium's sort of all the splats); the crops are those of a full frame. */
function captureHeld(ctx, hold, camera, boxes) {
  const { viewer } = ctx;
  const scene = viewer.scene;
  setCamera(viewer, camera);
  const pose = poseOf(viewer);
  const restore = hideScenery(scene);
  const canvas = scene.canvas;
  let splats = 0;
  try {
    const bs = boxes();
    const x0 = Math.min(...bs.map((b) => b[0]));
    const y0 = Math.min(...bs.map((b) => b[1]));
    const x1 = Math.max(...bs.map((b) => b[0] + b[2]));
    const y1 = Math.max(...bs.map((b) => b[1] + b[3]));
    splats = hold.arm(viewer.camera, [x0, y0, x1 - x0, y1 - y0], canvas.clientWidth, canvas.clientHeight);
  } catch (exc) {
    restore();
    hold.release(viewer.camera);
    return Promise.reject(exc);
  }
  return new Promise((resolve, reject) => {
    let frames = 0;
    const done = (fn) => {
      scene.postRender.removeEventListener(onPost);
      clearTimeout(timer);
      hold.disarm();
      restore();
      hold.release(viewer.camera);
      fn();
    };
    const onPost = () => {
      frames++;
      if (movedFrom(viewer, pose)) { done(() => reject(new Error(MOVED))); return; }
      if (hold.drawnFrame >= 0) {
        let crops;
        try { crops = boxes().map((b) => cropOf(canvas, b)); } catch (exc) { done(() => reject(exc)); return; }
        done(() => resolve({ crops, frames, splats }));
        return;
      }
      scene.requestRender();
    };
    const timer = setTimeout(() => done(() => reject(new Error("the view was not drawn in time"))), VIEW_TIMEOUT_MS);
    scene.postRender.addEventListener(onPost);
    scene.requestRender();
  });
}

/** The reference of ray 1 `ray` taken at `camera`: the crop around its pixel. */
function captureReference(ctx, ray, camera) {
  const [px, py] = ray.pixel;
  const box = () => [boxAround([[px, py]], REF_HALF, camera.width, camera.height)];
  return captureAt(ctx, camera, box).then(({ crops }) => {
    const b = box()[0];
    return { camera, pixel: [px, py], origin: [b[0], b[1]], image: crops[0].toDataURL("image/png") };
  });
}

/** After the first click of a point: keep the canvas around the clicked pixel as the
 *  reference of auto-aim (taken now, while the camera is where the operator clicked). */
export function rememberReference(ctx, ray) {
  const camera = cameras.get(ray) || currentCamera(ctx.viewer);
  if (!camera || !ray.pixel || references.has(ray)) return;
  cameras.set(ray, camera);
  const back = awayFromView(ctx);
  const p = captureReference(ctx, ray, camera);
  p.catch(() => references.delete(ray)).finally(back); // asked again on A
  references.set(ray, p);
}

/** The scene canvas is about to show other frames than the operator's view (auto-aim's crops):
 *  put up the still of the view (still.js) and keep it; returns the function to call when
 *  done, which asks for a frame of the view when there was no still to keep it. */
function awayFromView(ctx) {
  const still = ctx.still;
  const kept = still && still.take() ? still.keep() : null;
  return () => {
    if (kept) kept();
    else ctx.viewer.scene.requestRender();
  };
}

/** The ray (session JSON) through window position `pixel` of view `camera` (a view's camera
 *  JSON), in the frame of `modelMatrix` (16 numbers), or null. */
function rayThrough(ctx, camera, pixel, modelMatrix) {
  const cam = new Cesium.Camera(ctx.viewer.scene);
  cam.frustum = ctx.viewer.camera.frustum.clone();
  cam.setView({ destination: c3(camera.position), orientation: { direction: c3(camera.direction), up: c3(camera.up) } });
  return captureRay({ camera: cam, scene: ctx.viewer.scene }, new Cesium.Cartesian2(pixel[0], pixel[1]), modelMatrix);
}

/** The ray (session JSON, marked auto) through window position `pixel` of view `camera`. */
function rayAt(ctx, camera, pixel, score) {
  const ray = rayThrough(ctx, camera, pixel, ctx.modelMatrix());
  return ray ? { ...ray, auto: true, score } : null;
}

/** Smallest move (px) of a snap that replaces ray 1. */
const SNAP_MIN_PX = 0.05;

/** Ray 1 `ray1` of measurement `m` snapped onto the point feature its click was near in its
 *  reference view `ref` (POST /api/snap): the new ray 1 (through the feature, from the same
 *  camera) replaces it in `m` and takes over its reference, camera and thumbnail; returns
 *  {ray, ref, moved_px}, or null when the click stays (no point feature near it, the server
 *  said no, or it was on the feature already). */
async function snapRay1(ctx, m, ray1, ref) {
  let ans = null;
  try {
    ans = await api("POST", "/snap", { reference: { image: ref.image, origin: ref.origin, camera: ref.camera, pixel: ref.pixel } });
  } catch (exc) {
    return null;
  }
  if (!ans || !ans.ok || !(ans.moved_px >= SNAP_MIN_PX) || m.rays[0] !== ray1) return null;
  const made = rayThrough(ctx, ref.camera, ans.pixel, ray1.model_matrix || ctx.modelMatrix());
  if (!made) return null;
  const ray = { ...ray1, ...made };
  const snappedRef = { ...ref, pixel: ans.pixel };
  m.rays[0] = ray;
  references.set(ray, Promise.resolve(snappedRef));
  cameras.set(ray, cameras.get(ray1) || ref.camera);
  if (thumbs.has(ray1)) thumbs.set(ray, thumbs.get(ray1));
  snaps.set(ray, ans.moved_px);
  return { ray, ref: snappedRef, moved_px: ans.moved_px };
}

/** How far (px) ray 1 `ray` was moved onto its feature by auto-aim, or 0. */
function snappedBy(ray) {
  return snaps.get(ray) || 0;
}

/** The thumbnail of a match: the target crop around `pixel` (window coords) with a cross on it. */
function thumbnail(crop, origin, pixel) {
  const size = 2 * THUMB_HALF;
  const c = document.createElement("canvas");
  c.width = size;
  c.height = size;
  const g = c.getContext("2d");
  const x = pixel[0] - origin[0];
  const y = pixel[1] - origin[1];
  g.fillStyle = "#000";
  g.fillRect(0, 0, size, size);
  g.drawImage(crop, x - THUMB_HALF, y - THUMB_HALF, size, size, 0, 0, size, size);
  g.strokeStyle = "#ff3b30";
  g.lineWidth = 1;
  g.beginPath();
  g.moveTo(THUMB_HALF - 7, THUMB_HALF); g.lineTo(THUMB_HALF - 2, THUMB_HALF);
  g.moveTo(THUMB_HALF + 2, THUMB_HALF); g.lineTo(THUMB_HALF + 7, THUMB_HALF);
  g.moveTo(THUMB_HALF, THUMB_HALF - 7); g.lineTo(THUMB_HALF, THUMB_HALF - 2);
  g.moveTo(THUMB_HALF, THUMB_HALF + 2); g.lineTo(THUMB_HALF, THUMB_HALF + 7);
  g.stroke();
  return c.toDataURL("image/png");
}

function viewName(v, i) {
  return `view ${i + 1} (azimuth ${fixed(v.azimuth_deg, 0)}°, elevation ${fixed(v.elevation_deg, 0)}°)`;
}

let running = null;

/** Whether auto-aim is under way. */
export function autoAimRunning() {
  return running !== null;
}

/** What the last auto-aim of measurement `m` did: {added, declined: [{view, reason}], text},
 *  or null. */
export function autoAimResult(m) {
  return (m && m.autoaim) || null;
}

/**
 * Key A: find ray 1's feature in K suggested views and add each match as an auto ray.
 * `changed(raysAdded)` is called when the panel should show news (with true once rays were
 * added: the point is to be solved again). The timings (ms from A) go to window.gsgeo.autoaim.last: depth, views, each view's drawn and
 * matched instants, rays (when the rays were added), frames per view.
 */
export async function autoAim(ctx, changed = () => {}) {
  const { state, viewer } = ctx;
  const m = state.measure;
  if (!m || !m.rays.length) {
    ctx.message("A (auto-aim) finds the feature in other views once it has a ray: press M and click it first.", true);
    return;
  }
  if (running) { ctx.message("Auto-aim is already under way."); return; }
  let ray1 = m.rays[0];
  const t0 = performance.now();
  const at = () => Math.round(performance.now() - t0);
  const timings = { views: [] };
  const declined = [];
  const images = []; // the crops sent (reference first), kept for review and tests
  const result = { running: true, added: 0, declined, text: "", timings };
  m.autoaim = result;
  running = result;
  // progress goes to the status line and the panel only: a redraw of the measuring graphics
  // would ask for frames, each drawing every splat again between the views
  const say = (text) => {
    result.text = text;
    ctx.updateStatus();
    const el = autoAimPanel(m);
    const old = document.getElementById("autoaim-report");
    if (old) old.replaceWith(el);
    else if (document.getElementById("live-solution")) document.getElementById("live-solution").append(el);
  };
  const home = currentCamera(viewer);
  let moved = false;
  let restore = null;
  let held = null;
  const back = awayFromView(ctx);
  try {
    // held from now on: a frame still asked for the operator's view (the click's ray drawn)
    // draws none of the splats instead of all of them
    held = holdSplats(state.tileset);
    say("Auto-aim: finding the feature of ray 1 in other views…");
    const scene = encodeURIComponent(state.sceneName);
    // taken again at ray 1's camera when the capture at the click failed
    if (!references.has(ray1) && cameras.has(ray1)) rememberReference(ctx, ray1);
    const refP = references.get(ray1);
    if (!refP) throw new Error("ray 1's view is not known (a reopened point): click the feature for a new ray 1");
    let ref = await refP;
    timings.reference = at();
    // ray 1 onto the point feature the click was near (a target's centre, a corner): every
    // auto ray finds what ray 1 hits, so a click a pixel off would be a pixel off in all
    const snapped = await snapRay1(ctx, m, ray1, ref);
    timings.snapped = at();
    if (snapped) ({ ray: ray1, ref } = snapped);
    result.snap = snapped ? snapped.moved_px : 0;
    const depth = await requestDepth(ctx, ray1);
    timings.depth = at();
    if (!depth) throw new Error("the server gives no depth along ray 1 (is the scene on this server?)");
    if (!depth.hit) throw new Error(`ray 1 ${depth.reason || "hits no splat (sky?)"}`);
    images.push(ref.image);
    const cam = ref.camera;
    const res = await api("POST", `/scenes/${scene}/views`, {
      rays: m.rays.filter((r, i) => !m.excluded.has(i)), point_ecef: depth.point_ecef, k: K,
      fovy: cam.fovy, width: cam.width, height: cam.height, ...(ctx.solveSettings ? { sigma_px: ctx.solveSettings().sigma_px } : {}),
      // views near ray 1 for a corner or a pole top: only with the scene's match below, which
      // knows the splats' shape (the plain match on such views matched the background)
      shape_views: true,
    });
    timings.suggested = at();
    const views = res.views || [];
    if (!views.length) throw new Error("the server suggests no view for this point");
    const d = unit(ray1.direction);
    const near = add(ray1.origin, scale(d, depth.near_m));
    const far = add(ray1.origin, scale(d, depth.far_m));
    const matches = [];
    restore = hideScenery(viewer.scene);
    // the splats stay held across the views: no sort of all of them, no full frame between
    if (!held) held = holdSplats(state.tileset);
    for (let i = 0; i < views.length; i++) {
      if (state.measure !== m) return;
      const v = views[i];
      const vc = v.camera;
      const ends = [project(vc, near), project(vc, far)].filter(Boolean);
      const box = ends.length === 2 ? boxAround(ends, MARGIN, vc.width, vc.height) : null;
      if (!box) { declined.push({ view: i + 1, reason: `${viewName(v, i)}: outside the view (ray 1's segment is not in it)` }); continue; }
      say(`Auto-aim: rendering ${viewName(v, i)} of ${views.length}…`);
      moved = true;
      const shot = await captureAt(ctx, vc, () => [box]);
      const tv = { view: i + 1, drawn: at(), frames: shot.frames, ...(shot.splats ? { splats: shot.splats } : {}) };
      timings.views.push(tv);
      const crop = shot.crops[0];
      const target = { image: crop.toDataURL("image/png"), origin: [box[0], box[1]], camera: vc };
      images.push(target.image);
      // matched while the next view renders
      // the scene's match: the splats about the click weight the patch and warp it by their shape
      matches.push(api("POST", `/scenes/${scene}/match`, {
        reference: { image: ref.image, origin: ref.origin, camera: ref.camera, pixel: ref.pixel },
        target,
        depth: { near_m: depth.near_m, far_m: depth.far_m, depth_m: depth.depth_m },
        model_matrix: ray1.model_matrix || ctx.modelMatrix(),
      }).then((ans) => { tv.matched = at(); return { i, v, ans, crop, origin: target.origin }; },
        (exc) => { tv.matched = at(); return { i, v, ans: { ok: false, reason: exc.message }, crop, origin: target.origin }; }));
    }
    const answers = await Promise.all(matches);
    if (state.measure !== m) return;
    const added = [];
    for (const { i, v, ans, crop, origin } of answers) {
      const ray = ans.ok && ans.pixel ? rayAt(ctx, v.camera, ans.pixel, ans.score) : null;
      if (!ray) { declined.push({ view: i + 1, reason: `${viewName(v, i)}: ${ans.reason || "no match"}` }); continue; }
      thumbs.set(ray, thumbnail(crop, origin, ans.pixel));
      added.push(ray);
    }
    declined.sort((a, b) => a.view - b.view);
    m.rays.push(...added);
    timings.rays = at();
    result.added = added.length;
    result.text = autoAimSummary(added.length, views.length, declined.length);
    ctx.message(result.text, added.length === 0);
  } catch (exc) {
    result.text = autoAimDeclined(exc.message || exc);
    ctx.message(result.text, true);
  } finally {
    result.running = false;
    running = null;
    if (restore) restore();
    if (moved && home) setCamera(viewer, home);
    if (held) held.release(viewer.camera);
    back();
    window.gsgeo.autoaim = { last: { ...timings, added: result.added, declined: declined.map((x) => x.reason), text: result.text, snap_px: result.snap || 0 }, images };
    if (state.measure === m) changed(result.added > 0);
    ctx.updateStatus();
  }
}

/** The panel's lines about the last auto-aim of measurement `m` (what it is doing, or how many
 *  views matched and why each declined one was declined), or null. */
export function autoAimPanel(m) {
  const r = autoAimResult(m);
  if (!r || !r.text) return null;
  const lines = r.running || !r.declined.length ? [r.text]
    : [`Auto-aim: ${r.added} ray${r.added === 1 ? "" : "s"} added.`, ...r.declined.map((x) => `declined ${x.reason}`)];
  if (!r.running && r.snap) lines.push(snapText(r.snap));
  return h("div", { class: r.running ? "note" : (r.added ? "note" : "warn"), id: "autoaim-report" },
    ...lines.map((t) => h("div", {}, t)));
}

/** What the ray table's first cell adds for ray `ray`: for an auto ray its match thumbnail
 *  and "auto 0.93" (its score); for a click auto-aim snapped, "snapped 1.4 px"; nothing for
 *  another click. */
export function rayBadge(ray) {
  if (!ray.auto) {
    const px = snappedBy(ray);
    return px ? [h("span", { class: "autoaim-score", title: "auto-aim moved this click onto the point feature beside it" },
      ` snapped ${fixed(px, 1)} px`)] : [];
  }
  const src = thumbOf(ray);
  return [
    src ? h("img", { src, class: "autoaim-thumb", width: 2 * THUMB_HALF, height: 2 * THUMB_HALF,
      alt: "match", title: "found by auto-aim: the target view around the match, its pixel marked" }) : "",
    h("span", { class: "autoaim-score" }, ` auto ${typeof ray.score === "number" ? fixed(ray.score, 2) : ""}`),
  ];
}
