// Navigation made for a measured splat scene. Cesium's globe controls cannot pick splats, so
// its wheel zoom aims at the globe (under the scene) and walks the camera below the ground.
// Here the wheel, + and - zoom about the splat under the cursor (or the view's centre), found
// by the server from the splats' depth (POST /api/scenes/{scene}/depth): the camera moves
// along the ray through that pixel, so the point stays under the cursor, and stops short of
// the surface (never through it). A left drag pans: the camera moves in its image plane so
// the splat grabbed stays under the cursor. A right or middle drag (or a left drag with Shift
// or Ctrl) orbits about the splat under the cursor where the drag began, never below the
// pivot's horizon. Arrow keys pan by a tenth of the view, with Shift they orbit by 5 degrees
// about the splat at the view's centre. Home returns to the scene's overview. A north arrow, a
// scale bar (at the depth of the view's centre) and the cursor's coordinates in the project's
// grid (POST /api/projects/{pid}/locate, from the splat under the cursor) follow the view.
//
// Frames: rendered ECEF (metres), as the viewer draws; window coordinates in CSS pixels from
// the canvas' top-left corner.

import { api } from "./api.js";
import { DRAG_START_PX, MAX_RANGE_RADII, MIN_GAP_M, ORBIT_DEG_PER_PX, headingOf, metresPerPixel, notches,
  orbitedPose, pannedPosition, scaleBar, zoomedPosition } from "./navmath.js";
import { captureRay } from "./rays.js";

const Cesium = window.Cesium;
/** The cursor rests this long (ms) before its coordinates are asked. */
const CURSOR_REST_MS = 120;
/** Degrees an arrow key with Shift orbits. */
const ORBIT_KEY_DEG = 5;

/** Install the navigation on the viewer of `ctx` ({viewer, state, modelMatrix, still}).
 *  `overview()` puts the camera at the scene's overview. Returns {home, zoom, cursor} for
 *  tests and the keys. */
export function installNavigation(ctx, { overview }) {
  const { viewer } = ctx;
  const scene = viewer.scene;
  const canvas = scene.canvas;
  const sscc = scene.screenSpaceCameraController;
  sscc.zoomEventTypes = [Cesium.CameraEventType.PINCH]; // the wheel is ours
  // so are the drags: Cesium's aim at the globe under the scene (a turn of 143 degrees and a
  // move of 180 m for a drag of 250 px)
  sscc.enableRotate = false;
  sscc.enableTranslate = false;
  sscc.enableTilt = false;
  sscc.enableLook = false;
  const nav = { wheels: 0, zooms: 0, drags: 0, keys: 0, busy: false, cursor: null, centreDepth: null, drag: null, grabbing: 0 };
  let queued = 0;
  let at = null;
  let anchor = null; // {pos, pose, point}: the point zoomed about from `pos` at pose `pose`

  const poseKey = () => {
    const p = viewer.camera.positionWC;
    const d = viewer.camera.directionWC;
    return [p.x, p.y, p.z, d.x, d.y, d.z].map((x) => x.toFixed(4)).join(",");
  };

  /** The splat point (rendered ECEF) under window position `pos`, or null (sky, no scene). */
  async function pointUnder(pos) {
    const name = ctx.state.sceneName;
    if (!name) return null;
    // a scene whose tiles are on a static host has no splats here to ask (409)
    const info = (ctx.state.scenes || []).find((s) => s.name === name);
    if (!info || info.tiles_url || info.error) return null;
    const ray = captureRay(viewer, new Cesium.Cartesian2(pos[0], pos[1]), ctx.modelMatrix());
    if (!ray) return null;
    try {
      const d = await api("POST", `/scenes/${encodeURIComponent(name)}/depth`, { ray });
      if (!d || !d.hit) return null;
      return d.point_ecef || ray.origin.map((o, k) => o + ray.direction[k] * d.depth_m);
    } catch (exc) {
      return null; // e.g. a scene on a static host: no depth, no cursor point
    }
  }

  /** A point to zoom out from when no splat is under the cursor or the view's centre: along
   *  the cursor's ray, as far as the scene's centre is from the camera. */
  function fallbackPoint(pos) {
    const t = ctx.state.tileset;
    const ray = viewer.camera.getPickRay(new Cesium.Cartesian2(pos[0], pos[1]));
    if (!t || !ray) return null;
    const dist = Cesium.Cartesian3.distance(viewer.camera.positionWC, t.boundingSphere.center);
    const p = Cesium.Ray.getPoint(ray, dist);
    return [p.x, p.y, p.z];
  }

  function zoomAbout(point, n) {
    const c = viewer.camera.positionWC;
    const next = zoomedPosition([c.x, c.y, c.z], point, n);
    if (!next) return false;
    if (n < 0) { // out: never lower than both the camera and the point (below the ground)
      const h = (x) => Cesium.Cartographic.fromCartesian(x).height;
      const floor = Math.min(h(c), h(new Cesium.Cartesian3(...point)));
      if (h(new Cesium.Cartesian3(...next)) < floor) return false;
    }
    const t = ctx.state.tileset;
    if (n < 0 && t) { // not further out than a few scene radii
      const centre = t.boundingSphere.center;
      const far = MAX_RANGE_RADII * Math.max(t.boundingSphere.radius, 10);
      const away = Cesium.Cartesian3.distance(new Cesium.Cartesian3(...next), centre);
      if (away > far && away > Cesium.Cartesian3.distance(c, centre)) return false;
    }
    const cam = viewer.camera;
    cam.cancelFlight();
    cam.setView({ destination: new Cesium.Cartesian3(...next),
      orientation: { direction: Cesium.Cartesian3.clone(cam.directionWC), up: Cesium.Cartesian3.clone(cam.upWC) } });
    nav.zooms++;
    return true;
  }

  /** Zoom `n` notches about the splat under window position `pos`. */
  async function zoom(pos, n) {
    queued += n;
    at = pos;
    if (nav.busy) return;
    nav.busy = true;
    try {
      while (queued !== 0) {
        const k = queued;
        const where = at;
        queued = 0;
        let point = anchor && anchor.pos[0] === where[0] && anchor.pos[1] === where[1]
          && anchor.pose === poseKey() ? anchor.point : null;
        if (!point) {
          point = await pointUnder(where);
          // nothing under the cursor: the splat at the view's centre, else (out only) the
          // cursor's ray as far as the scene's centre
          if (!point) point = await pointUnder([canvas.clientWidth / 2, canvas.clientHeight / 2]);
          if (!point && k < 0) point = fallbackPoint(where);
        }
        if (!point) break;
        const moved = zoomAbout(point, k);
        anchor = { pos: where, pose: poseKey(), point };
        if (!moved) break;
      }
    } finally {
      nav.busy = false;
      queued = 0;
    }
  }

  canvas.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    nav.wheels++;
    const r = canvas.getBoundingClientRect();
    zoom([ev.clientX - r.left, ev.clientY - r.top], notches(ev));
  }, { passive: false });

  const cameraPose = () => {
    const c = viewer.camera;
    const arr = (v) => [v.x, v.y, v.z];
    return { position: arr(c.positionWC), direction: arr(c.directionWC), up: arr(c.upWC), right: arr(c.rightWC) };
  };
  const heightOf = (p) => Cesium.Cartographic.fromCartesian(new Cesium.Cartesian3(...p)).height;
  const verticalAt = (p) => {
    const n = Cesium.Ellipsoid.WGS84.geodeticSurfaceNormal(new Cesium.Cartesian3(...p), new Cesium.Cartesian3());
    return [n.x, n.y, n.z];
  };

  function setPose(pose) {
    const cam = viewer.camera;
    cam.cancelFlight();
    cam.setView({ destination: new Cesium.Cartesian3(...pose.position),
      orientation: { direction: new Cesium.Cartesian3(...pose.direction), up: new Cesium.Cartesian3(...pose.up) } });
  }

  /** Pan from pose `p0` by (dx, dy) CSS px at view depth `depth` (m); not below `floor` (m,
   *  ellipsoidal height). Whether it moved. */
  function panFrom(p0, dx, dy, depth, floor) {
    const mpp = metresPerPixel(depth, viewer.camera.frustum.fovy, canvas.clientHeight);
    const next = pannedPosition(p0.position, p0.right, p0.up, dx, dy, mpp);
    if (heightOf(next) < floor) return false;
    setPose({ ...p0, position: next });
    return true;
  }

  /** View depth (m, along the camera's direction) of `point` seen from pose `p`. */
  const depthOf = (p, point) => p.direction.reduce((a, d, k) => a + d * (point[k] - p.position[k]), 0);

  // drags: pan (left) and orbit (right, middle, or left with Shift or Ctrl)
  canvas.addEventListener("contextmenu", (ev) => ev.preventDefault());
  canvas.addEventListener("pointerdown", (ev) => {
    if (ev.button > 2) return; // a new press starts a new drag (a release outside the window was missed)
    const r = canvas.getBoundingClientRect();
    const pos = [ev.clientX - r.left, ev.clientY - r.top];
    const orbit = ev.button !== 0 || ev.shiftKey || ev.ctrlKey;
    const p0 = cameraPose();
    const drag = { id: ev.pointerId, pos, orbit, p0, last: [0, 0], moving: false, point: null };
    nav.drag = drag;
  });
  /** The splat grabbed (pan) or the pivot (orbit), asked once the press is a drag (a click
   *  asks nothing); a pan uses the view centre's depth until the answer comes. */
  async function grab(drag) {
    nav.grabbing++;
    try {
      let point = await pointUnder(drag.pos);
      if (!point && drag.orbit) point = await pointUnder([canvas.clientWidth / 2, canvas.clientHeight / 2]);
      if (!point && drag.orbit) point = fallbackPoint(drag.pos);
      drag.point = point;
      moveDrag(drag); // also when the button is up already: the drag's whole move
    } finally {
      nav.grabbing--;
    }
  }
  window.addEventListener("pointermove", (ev) => {
    const drag = nav.drag;
    if (!drag || ev.pointerId !== drag.id) return;
    const r = canvas.getBoundingClientRect();
    const d = [ev.clientX - r.left - drag.pos[0], ev.clientY - r.top - drag.pos[1]];
    if (!drag.moving && Math.hypot(...d) < DRAG_START_PX) return;
    if (!drag.moving) {
      drag.moving = true;
      canvas.setPointerCapture?.(ev.pointerId);
      grab(drag);
    }
    drag.last = d;
    moveDrag(drag);
  });
  const endDrag = (ev) => {
    const drag = nav.drag;
    if (!drag || ev.pointerId !== drag.id) return;
    if (drag.moving) nav.drags++;
    nav.drag = null;
  };
  window.addEventListener("pointerup", endDrag);
  window.addEventListener("pointercancel", endDrag);

  /** Put the camera where the drag so far takes it from where the drag began. */
  function moveDrag(drag) {
    const [dx, dy] = drag.last;
    const p0 = drag.p0;
    if (drag.orbit) {
      if (!drag.point) return; // the pivot is not known yet: the move waits for it
      const rad = (ORBIT_DEG_PER_PX * Math.PI) / 180;
      setPose(orbitedPose(p0, drag.point, verticalAt(drag.point), -dx * rad, dy * rad));
      return;
    }
    const depth = drag.point ? depthOf(p0, drag.point) : nav.centreDepth;
    if (!(depth > 0)) return;
    panFrom(p0, dx, dy, depth, Math.min(heightOf(p0.position), drag.point ? heightOf(drag.point) + MIN_GAP_M : Infinity));
  }

  /** A key's move: `dir` one of "left", "right", "up", "down"; `orbit` turns about the splat
   *  at the view's centre by ORBIT_KEY_DEG instead of panning a tenth of the view. */
  async function keyMove(dir, orbit) {
    if (nav.busy) return;
    nav.busy = true;
    try {
      const centre = [canvas.clientWidth / 2, canvas.clientHeight / 2];
      const point = await pointUnder(centre);
      const p0 = cameraPose();
      const [dx, dy] = { left: [-1, 0], right: [1, 0], up: [0, -1], down: [0, 1] }[dir];
      if (orbit) {
        const pivot = point || fallbackPoint(centre);
        if (!pivot) return;
        const rad = (ORBIT_KEY_DEG * Math.PI) / 180;
        setPose(orbitedPose(p0, pivot, verticalAt(pivot), -dx * rad, dy * rad));
      } else {
        const depth = point ? depthOf(p0, point) : nav.centreDepth;
        if (!(depth > 0)) return;
        // the view moves a tenth of its height: the arrow says which way the camera goes
        const step = canvas.clientHeight / 10;
        panFrom(p0, -dx * step, -dy * step, depth, Math.min(heightOf(p0.position), point ? heightOf(point) + MIN_GAP_M : Infinity));
      }
      nav.keys++;
    } finally {
      nav.busy = false;
    }
  }

  // the cursor's coordinates, once it rests
  const coords = document.getElementById("cursor-coords");
  let rest = null;
  let asked = 0;
  canvas.addEventListener("mousemove", (ev) => {
    const r = canvas.getBoundingClientRect();
    const pos = [ev.clientX - r.left, ev.clientY - r.top];
    clearTimeout(rest);
    rest = setTimeout(() => showCursor(pos), CURSOR_REST_MS);
  });
  canvas.addEventListener("mouseleave", () => { clearTimeout(rest); });

  async function showCursor(pos) {
    const ask = ++asked;
    const point = await pointUnder(pos);
    if (ask !== asked) return;
    if (!point) {
      nav.cursor = { pos, point: null };
      if (coords) coords.textContent = "cursor: no splat here";
      return;
    }
    const out = { pos, point };
    const p = ctx.state.project;
    if (p) {
      try {
        const mm = ctx.modelMatrix();
        const res = await api("POST", `/projects/${encodeURIComponent(p.id)}/locate`, { points: [point], model_matrix: mm });
        if (ask !== asked) return;
        out.located = res.points[0];
        out.crs = res.crs;
      } catch (exc) {
        out.error = exc.message || String(exc);
      }
    }
    nav.cursor = out;
    if (coords) coords.textContent = cursorText(out);
  }

  // the north arrow and the scale bar, after each frame of a new pose
  const arrow = document.getElementById("north-arrow");
  const bar = document.getElementById("scale-bar");
  let drawnPose = "";
  let centreAsk = 0;
  scene.postRender.addEventListener(() => {
    const key = poseKey();
    if (key === drawnPose) return;
    drawnPose = key;
    if (arrow) {
      const cam = viewer.camera;
      const xyz = (c) => [c.x, c.y, c.z];
      const heading = headingOf(xyz(cam.positionWC), xyz(cam.directionWC), xyz(cam.upWC));
      arrow.style.transform = `rotate(${-Cesium.Math.toDegrees(heading)}deg)`;
    }
    const ask = ++centreAsk;
    setTimeout(async () => { // the view's centre depth, once the camera rests
      if (ask !== centreAsk || nav.busy) return;
      const centre = [canvas.clientWidth / 2, canvas.clientHeight / 2];
      const point = await pointUnder(centre);
      if (ask !== centreAsk) return;
      const c = viewer.camera.positionWC;
      nav.centreDepth = point ? Math.hypot(point[0] - c.x, point[1] - c.y, point[2] - c.z) : null;
      drawScale();
    }, 250);
  });

  function drawScale() {
    if (!bar) return;
    const f = viewer.camera.frustum;
    const d = nav.centreDepth;
    const s = d && f.fovy ? scaleBar((2 * Math.tan(f.fovy / 2) * d) / canvas.clientHeight) : null;
    bar.hidden = !s;
    if (!s) return;
    bar.querySelector(".bar").style.width = `${s.px.toFixed(1)}px`;
    bar.querySelector(".label").textContent = s.label;
    bar.dataset.metres = String(s.metres);
  }

  nav.home = () => { overview(); };
  nav.zoom = zoom;
  nav.keyMove = keyMove;
  nav.showCursor = showCursor;
  window.gsgeo.navigation = nav;
  return nav;
}

/** The status text of the cursor's point: grid E, N, H (m) with the CRS, or WGS 84. */
export function cursorText(c) {
  if (!c || !c.point) return "";
  const g = c.located;
  if (g && g.easting !== undefined) {
    return `E ${g.easting.toFixed(3)}  N ${g.northing.toFixed(3)}  H ${g.height.toFixed(3)}  (${c.crs})`;
  }
  if (g) return `lon ${g.lon.toFixed(7)}  lat ${g.lat.toFixed(7)}  h ${g.h_wgs84.toFixed(3)} (WGS 84)`;
  const carto = Cesium.Cartographic.fromCartesian(new Cesium.Cartesian3(...c.point));
  return `lon ${Cesium.Math.toDegrees(carto.longitude).toFixed(7)}  lat ${Cesium.Math.toDegrees(carto.latitude).toFixed(7)}  h ${carto.height.toFixed(3)} (WGS 84, rendered)`;
}
