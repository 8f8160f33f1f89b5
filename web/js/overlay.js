// A 2-D canvas over the Cesium canvas for rays, error ellipsoids, lines and polygons.
// CesiumJS 1.145 hides entity polylines wherever Gaussian splats are drawn, so these
// measuring graphics are projected by the camera here and drawn on top, every frame. The
// page renders on demand: `changed()` (set by the owner) is called when the drawing changes.

const Cesium = window.Cesium;

export class Overlay {
  constructor(viewer, container, before = null) {
    this.viewer = viewer;
    this.canvas = document.createElement("canvas");
    this.canvas.className = "gsgeo-overlay";
    container.insertBefore(this.canvas, before);
    this.ctx = this.canvas.getContext("2d");
    this.groups = new Map();
    this.changed = () => {};
    this.view = new Cesium.Matrix4();
    viewer.scene.postRender.addEventListener(() => this.draw());
  }

  clear(group) {
    this.groups.set(group, []);
    this.changed();
  }

  /** Add a 3-D polyline: points [[x, y, z], ...] in rendered ECEF (m); style {color, width, dash,
   *  closed, fill}: with `fill` (a CSS colour) a closed planar ring is filled, farthest first. */
  add(group, points, style) {
    if (!this.groups.has(group)) this.groups.set(group, []);
    this.groups.get(group).push({ points, ...style });
    this.changed();
  }

  draw() {
    const sceneCanvas = this.viewer.scene.canvas;
    const w = sceneCanvas.clientWidth;
    const h = sceneCanvas.clientHeight;
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
    const camera = this.viewer.camera;
    const frustum = camera.frustum;
    if (!(frustum instanceof Cesium.PerspectiveFrustum)) return;
    const f = h / (2 * Math.tan(frustum.fovy / 2));
    const near = Math.max(frustum.near, 1e-3);
    const m = Cesium.Matrix4.toArray(camera.viewMatrix);
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
      if (s.fill && !s.color) continue;
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
