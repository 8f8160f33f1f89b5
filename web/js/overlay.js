// A 2-D canvas over the Cesium canvas for rays, point markers, error ellipsoids, lines and
// polygons. CesiumJS 1.145 hides entity polylines wherever Gaussian splats are drawn, so these
// measuring graphics are projected by the camera here and drawn on top: after every frame, and
// without a frame when only the drawing changed (repaint), since a WebGL frame draws every
// splat (seconds in a software renderer) and a click changes nothing of the scene itself.
//
// Frames: points in rendered ECEF (metres); window coordinates are Cesium's, CSS pixels from
// the canvas' top-left corner, x right, y down.

const Cesium = window.Cesium;

/** The view a frame is drawn from: Cesium's view matrix (column-major array, rendered ECEF ->
 *  camera), the camera's position, unit direction and up (rendered ECEF), vertical field of
 *  view (rad) and the canvas size (CSS px); null when the frustum is not perspective. */
export function viewOf(viewer) {
  const cam = viewer.camera;
  if (!(cam.frustum instanceof Cesium.PerspectiveFrustum)) return null;
  const arr = (c) => [c.x, c.y, c.z];
  const canvas = viewer.scene.canvas;
  return { matrix: Cesium.Matrix4.toArray(cam.viewMatrix), position: arr(cam.positionWC),
    direction: arr(cam.directionWC), up: arr(cam.upWC), fovy: cam.frustum.fovy,
    near: cam.frustum.near, width: canvas.clientWidth, height: canvas.clientHeight };
}

/** Whether views `a` and `b` (viewOf) draw the same picture: the same canvas size and field
 *  of view, and poses within 0.1 mm and 1e-7 rad (a camera set back where it was). */
export function sameView(a, b) {
  if (!a || !b || a.width !== b.width || a.height !== b.height || Math.abs(a.fovy - b.fovy) > 1e-12) return false;
  for (let i = 0; i < 16; i++) {
    const tol = i >= 12 ? 1e-4 : 1e-7;
    if (!(Math.abs(a.matrix[i] - b.matrix[i]) <= tol)) return false;
  }
  return true;
}

export class Overlay {
  /** `fixedView()` returns the view the scene canvas shows while it is not the camera's (a still
   *  of the operator's view while auto-aim draws elsewhere: still.js), else null. */
  constructor(viewer, container, before = null, fixedView = () => null) {
    this.viewer = viewer;
    this.canvas = document.createElement("canvas");
    this.canvas.className = "gsgeo-overlay";
    container.insertBefore(this.canvas, before);
    this.ctx = this.canvas.getContext("2d");
    this.groups = new Map();
    this.painters = [];
    this.fixedView = fixedView;
    this.requestFrame = () => viewer.scene.requestRender();
    this.shown = null; // the view of the scene canvas' last frame (viewOf)
    this.queued = false;
    this.hiddenKeys = new Set(); // labelled markers the splats hide (occlusion.js): drawn faint
    this.markerListeners = [];
    viewer.scene.postRender.addEventListener(() => {
      const fixed = this.fixedView();
      if (!fixed) this.shown = viewOf(viewer);
      this.draw(fixed || this.shown);
    });
  }

  clear(group) {
    const had = (this.groups.get(group) || []).some((s) => s.marker && s.id);
    this.groups.set(group, []);
    if (had) this.markersChanged();
    this.repaint();
  }

  /** `fn()` is called when a labelled marker (one with an id) is added or cleared. */
  onMarkersChanged(fn) {
    this.markerListeners.push(fn);
  }

  markersChanged() {
    for (const fn of this.markerListeners) fn();
  }

  /** The markers with an id: [{id, position, key}] (key: id and position, kept across
   *  redraws of the same marker). */
  labelled() {
    return [...this.groups.values()].flat().filter((s) => s.marker && s.id)
      .map((s) => ({ id: s.id, position: s.position, key: markerKey(s) }));
  }

  /** The labelled markers (their keys) the splats hide: drawn faint. */
  setHidden(keys) {
    const same = keys.size === this.hiddenKeys.size && [...keys].every((k) => this.hiddenKeys.has(k));
    this.hiddenKeys = keys;
    if (!same) this.repaint();
  }

  /** Add a 3-D polyline: points [[x, y, z], ...] in rendered ECEF (m); style {color, width, dash,
   *  closed, fill}: with `fill` (a CSS colour) a closed planar ring is filled, farthest first. */
  add(group, points, style) {
    this.item(group, { points, ...style });
  }

  /** Add a point marker at `position` (rendered ECEF, m), drawn over everything: a disc of
   *  `size` px (`color`, a CSS colour; "transparent" for a ring) with a black outline of
   *  `outline` px (`ring`: a CSS colour for the outline instead), and `label` beside it
   *  (`font`, `labelColor`); `id` names it (markers(group) lists them). */
  marker(group, position, { size = 9, color, outline = 1.5, ring = null, label = null, font = "bold 13px sans-serif",
    labelColor = "#ffffff", id = null } = {}) {
    this.item(group, { marker: true, position, size, color, outline, ring, label, font, labelColor, id });
  }

  item(group, it) {
    if (!this.groups.has(group)) this.groups.set(group, []);
    this.groups.get(group).push(it);
    if (it.marker && it.id) this.markersChanged();
    this.repaint();
  }

  /** The markers of `group`: [{id, position}]. */
  markers(group) {
    return (this.groups.get(group) || []).filter((s) => s.marker).map((s) => ({ id: s.id, position: s.position }));
  }

  /** `fn(ctx2d, view)` paints more after the overlay's own drawing (CSS px, view: viewOf). */
  onPaint(fn) {
    this.painters.push(fn);
  }

  /** The drawing changed: paint it again now for the view the scene canvas shows, when that is
   *  still the camera's; otherwise ask for a frame, which paints it after drawing the scene. */
  repaint() {
    if (this.queued) return; // once for all the changes made by the code running now
    this.queued = true;
    queueMicrotask(() => {
      this.queued = false;
      const shown = this.fixedView() || this.shown;
      if (shown && sameView(shown, viewOf(this.viewer))) this.draw(shown);
      else this.requestFrame();
    });
  }

  /** Paint everything for view `view` (viewOf; nothing when null). */
  draw(view) {
    const w = view ? view.width : this.viewer.scene.canvas.clientWidth;
    const h = view ? view.height : this.viewer.scene.canvas.clientHeight;
    const dpr = window.devicePixelRatio || 1;
    if (this.canvas.width !== Math.round(w * dpr) || this.canvas.height !== Math.round(h * dpr)) {
      this.canvas.width = Math.round(w * dpr);
      this.canvas.height = Math.round(h * dpr);
      this.canvas.style.width = `${w}px`;
      this.canvas.style.height = `${h}px`;
    }
    const ctx = this.ctx;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, w, h);
    if (!view) return;
    const f = h / (2 * Math.tan(view.fovy / 2));
    const near = Math.max(view.near, 1e-3);
    const m = view.matrix;
    const toView = (p) => [
      m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12],
      m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13],
      m[2] * p[0] + m[6] * p[1] + m[10] * p[2] + m[14]];
    const toScreen = (v) => [w / 2 + (f * v[0]) / -v[2], h / 2 - (f * v[1]) / -v[2]];
    const all = [...this.groups.values()].flat();
    // filled faces under the lines, the farthest first, so translucent faces blend in depth order
    const faces = all.filter((s) => s.fill).map((s) => ({ s, pts: s.points.map(toView) }))
      .map((f) => ({ ...f, depth: f.pts.reduce((a, p) => a + p[2], 0) / f.pts.length }))
      .sort((a, b) => a.depth - b.depth);
    for (const { s, pts } of faces) {
      const poly = clipNear(pts, near);
      if (poly.length < 3) continue;
      ctx.beginPath();
      poly.map(toScreen).forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
      ctx.closePath();
      ctx.fillStyle = s.fill;
      ctx.fill();
    }
    for (const s of all) {
      if (s.marker || (s.fill && !s.color)) continue;
      const pts = s.points.map(toView);
      if (s.closed && pts.length > 2) pts.push(pts[0]);
      ctx.beginPath();
      for (let i = 0; i + 1 < pts.length; i++) {
        let a = pts[i];
        let b = pts[i + 1];
        // clip the segment to the part in front of the near plane (view z < -near)
        if (a[2] > -near && b[2] > -near) continue;
        if (a[2] > -near || b[2] > -near) {
          const t = (-near - a[2]) / (b[2] - a[2]);
          const c = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), -near];
          if (a[2] > -near) a = c; else b = c;
        }
        const sa = toScreen(a);
        const sb = toScreen(b);
        ctx.moveTo(sa[0], sa[1]);
        ctx.lineTo(sb[0], sb[1]);
      }
      ctx.setLineDash(s.dash || []);
      ctx.lineCap = "round";
      ctx.strokeStyle = "rgba(0,0,0,0.6)";
      ctx.lineWidth = (s.width || 2) + 2;
      ctx.stroke();
      ctx.strokeStyle = s.color;
      ctx.lineWidth = s.width || 2;
      ctx.stroke();
    }
    ctx.setLineDash([]);
    // markers over the lines (as Cesium's point entities with depth test off were)
    for (const s of all) {
      if (!s.marker) continue;
      const v = toView(s.position);
      if (v[2] > -near) continue;
      const [x, y] = toScreen(v);
      const faint = s.id && this.hiddenKeys.has(markerKey(s));
      if (faint) ctx.globalAlpha = HIDDEN_ALPHA;
      paintMarker(ctx, x, y, s);
      if (faint) ctx.globalAlpha = 1;
    }
    for (const fn of this.painters) {
      ctx.save();
      fn(ctx, view);
      ctx.restore();
    }
  }
}

/** Opacity of a marker and its label that the splats hide (occlusion.js). */
export const HIDDEN_ALPHA = 0.3;

/** A labelled marker's key: its id and position (mm), the same for the same marker drawn again. */
export function markerKey(s) {
  return `${s.id}@${s.position.map((x) => x.toFixed(3)).join(",")}`;
}

/** A marker at window position x, y (see Overlay.marker). */
function paintMarker(ctx, x, y, s) {
  const r = s.size / 2;
  ctx.beginPath();
  ctx.arc(x, y, r, 0, 2 * Math.PI);
  if (s.color && s.color !== "transparent") {
    ctx.fillStyle = s.color;
    ctx.fill();
  }
  if (s.ring) {
    ctx.lineWidth = s.outline;
    ctx.strokeStyle = s.ring;
    ctx.stroke();
  } else if (s.outline > 0) {
    ctx.lineWidth = s.outline;
    ctx.strokeStyle = "#000000";
    ctx.stroke();
  }
  if (s.label) {
    ctx.font = s.font;
    ctx.textAlign = "left";
    ctx.textBaseline = "bottom";
    const lx = x + r + 4;
    const ly = y - 4;
    ctx.lineJoin = "round";
    ctx.lineWidth = 3;
    ctx.strokeStyle = "#000000";
    ctx.strokeText(s.label, lx, ly);
    ctx.fillStyle = s.labelColor;
    ctx.fillText(s.label, lx, ly);
  }
}

/** The part of a polygon (view coordinates) in front of the near plane (view z < -near):
 *  Sutherland-Hodgman against that one plane. */
function clipNear(pts, near) {
  const out = [];
  const inside = (p) => p[2] <= -near;
  for (let i = 0; i < pts.length; i++) {
    const a = pts[i];
    const b = pts[(i + 1) % pts.length];
    if (inside(a)) out.push(a);
    if (inside(a) !== inside(b)) {
      const t = (-near - a[2]) / (b[2] - a[2]);
      out.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), -near]);
    }
  }
  return out;
}
