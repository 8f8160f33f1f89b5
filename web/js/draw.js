// Scene graphics: rays, point markers, error ellipsoids, lines and polygons, all in the
// rendered ECEF frame (georeferenced ECEF carried through the tileset's current modelMatrix).

import { eigSym3, transformCovariance, applyPoint, norm, sub } from "./linalg.js";
import { Overlay } from "./overlay.js";
import { QUALITY_COLORS, SCALE_95_3D, exaggeration, quality } from "./quality.js";

const Cesium = window.Cesium;

export const COLORS = {
  ray: Cesium.Color.fromCssColorString("#f5b700"),
  outlier: Cesium.Color.fromCssColorString("#ff3b30"),
  excluded: Cesium.Color.fromCssColorString("#8a939b"),
  point: Cesium.Color.fromCssColorString("#f5b700"),
  selected: Cesium.Color.fromCssColorString("#3ea6ff"),
  solution: Cesium.Color.fromCssColorString("#00e5ff"),
  // known points not measured yet: control (georeference) and check (accuracy)
  control: Cesium.Color.fromCssColorString("#ff8c1a"),
  check: Cesium.Color.fromCssColorString("#e36bff"),
  line: Cesium.Color.fromCssColorString("#3fb950"),
  polygon: Cesium.Color.fromCssColorString("#d2a8ff"),
  draft: Cesium.Color.fromCssColorString("#ffffff"),
  // building surfaces by kind (CityJSON semantic surface types), drawn translucent
  RoofSurface: Cesium.Color.fromCssColorString("#ff3d2e"),
  WallSurface: Cesium.Color.fromCssColorString("#ffd24a"),
  GroundSurface: Cesium.Color.fromCssColorString("#8a939b"),
};

export { SCALE_95_3D };

export function cart(p) {
  return new Cesium.Cartesian3(p[0], p[1], p[2]);
}

/** Semi-axes (m, descending) and the rotation (columns = principal axes) of the ellipsoid
 *  k * sqrt(eigenvalues) of covariance `cov` (3x3 rows, m^2, ECEF axes). */
export function ellipsoidAxes(cov, k) {
  const { values, vectors } = eigSym3(cov);
  const radii = values.map((v) => k * Math.sqrt(Math.max(v, 0)));
  return { radii, vectors };
}

export class Drawer {
  /** Everything is drawn on the 2-D overlay (overlay.js): a change repaints it without a frame
   *  of the scene where the camera still shows what was drawn. `requestFrame()` asks for a
   *  frame otherwise; `fixedView()` is the view a still shows (still.js), else null. */
  constructor(viewer, { requestFrame = null, fixedView = () => null } = {}) {
    this.viewer = viewer;
    this.overlay = new Overlay(viewer, document.getElementById("viewer-wrap"), document.getElementById("status"), fixedView);
    if (requestFrame) this.overlay.requestFrame = requestFrame;
    this.trueSize = false; // ellipsoids at true size, else exaggerated to be seen (ellipsoid())
    this.ellipsoids = new Map(); // group -> what ellipsoid() drew last, for the on-screen badge
  }

  clear(group) {
    this.overlay.clear(group);
    if (this.ellipsoids.delete(group)) this.badge();
  }

  /** A ray from `origin` along unit `direction` for `len` metres (rendered ECEF), its origin
   *  marked and labelled `label` (or not labelled when null). */
  ray(group, origin, direction, len, color, label) {
    const end = [origin[0] + direction[0] * len, origin[1] + direction[1] * len,
      origin[2] + direction[2] * len];
    const css = color.toCssColorString();
    this.overlay.add(group, [origin, end], { color: css, width: 2 });
    this.overlay.marker(group, origin, { size: 6, color: css, outline: 1, label: label || null,
      font: "12px sans-serif", labelColor: css });
  }

  /** A point marker labelled with its id `id` (overlay.markers(group) lists them). */
  marker(group, id, position, color, size = 9) {
    this.overlay.marker(group, position, { id, size, color: color.toCssColorString(), outline: 1.5, label: id });
  }

  /** A known point not measured yet (a control or check point) at `position` (rendered ECEF):
   *  a ring of `size` px in its role's colour, labelled with its id. */
  known(group, id, position, role, size = 14) {
    const css = (role === "control" ? COLORS.control : COLORS.check).toCssColorString();
    this.overlay.marker(group, position, { id, size, color: "transparent", outline: 2.5, ring: css, label: id,
      labelColor: css, font: "bold 12px sans-serif" });
  }

  /** A ring of `size` px around `position` (rendered ECEF): the solution of the point measured. */
  ring(group, position, color, size = 14) {
    this.overlay.marker(group, position, { size, color: "transparent", outline: 2, ring: color.toCssColorString() });
  }

  /** The error ellipsoid of a point: georeferenced ECEF point and covariance (m^2), drawn through
   *  the model matrix `mm` (column-major) at confidence scale k, coloured by its 95 % 3-D radius
   *  against the tolerance (quality.js) and, unless `trueSize` is set, exaggerated by a 1-2-5
   *  factor until it is some 24 px across at the camera's present range. Returns {radii (m, true
   *  size, at scale k), scale (the exaggeration), r95 (m), quality}. */
  ellipsoid(group, pointGeo, covGeo, mm, k) {
    const p = applyPoint(mm, pointGeo);
    const cov = transformCovariance(mm, covGeo);
    const { radii, vectors } = ellipsoidAxes(cov, k);
    const info = { radii, scale: 1, r95: NaN, quality: null };
    if (!radii.every((r) => Number.isFinite(r) && r > 0)) return info;
    info.r95 = (radii[0] * SCALE_95_3D) / k;
    info.quality = quality(info.r95);
    const camera = this.viewer.camera;
    const cam = camera.positionWC;
    const fovy = camera.frustum instanceof Cesium.PerspectiveFrustum ? camera.frustum.fovy : NaN;
    info.scale = this.trueSize ? 1
      : exaggeration(radii[0], norm(sub(p, [cam.x, cam.y, cam.z])), fovy, this.viewer.scene.canvas.clientHeight);
    // the three principal sections
    const css = QUALITY_COLORS[info.quality];
    for (const [a, b] of [[0, 1], [1, 2], [2, 0]]) {
      const ring = [];
      for (let i = 0; i < 48; i++) {
        const t = (2 * Math.PI * i) / 48;
        const ca = info.scale * radii[a] * Math.cos(t);
        const sb = info.scale * radii[b] * Math.sin(t);
        ring.push([0, 1, 2].map((j) => p[j] + ca * vectors[a][j] + sb * vectors[b][j]));
      }
      this.overlay.add(group, ring, { color: css, width: 2, closed: true });
    }
    this.ellipsoids.set(group, { ...info, k });
    this.badge();
    return info;
  }

  /** The badge on the viewer says how the ellipsoid in view is drawn: the point being measured
   *  first, else the selected point. */
  badge() {
    const el = document.getElementById("ellipsoid-badge");
    if (!el) return;
    const e = this.ellipsoids.get("current") || this.ellipsoids.get("selected");
    el.hidden = !e;
    if (!e) return;
    el.className = e.quality || "";
    el.textContent = `${e.scale === 1 ? "ellipsoid at true size" : `ellipsoid ×${e.scale}`}`
      + ` · ${e.k === SCALE_95_3D ? "95 %" : "1σ"} · 95 % radius ${(e.r95 * 1000).toFixed(1)} mm: ${e.quality}`;
    el.title = "colour by the 95 % 3-D radius: green up to 20 mm, amber up to 50 mm, red beyond; "
      + "tick 'true size' to draw it without exaggeration";
  }

  /** A planar face through rendered positions (a ring, not closed), filled with `color` at
   *  `alpha` and outlined by `edge` (drawn on the overlay, farther faces first). */
  face(group, positions, color, alpha, edge, width = 1.5) {
    if (positions.length < 3) return;
    this.overlay.add(group, positions, { fill: color.withAlpha(alpha).toCssColorString(),
      color: edge.toCssColorString(), width, closed: true });
  }

  /** A polyline through rendered positions (drawn on the overlay); closed when `closed`. */
  path(group, positions, color, closed = false, width = 3) {
    if (positions.length < 2) return;
    this.overlay.add(group, positions, { color: color.toCssColorString(), width, closed: closed && positions.length > 2 });
  }
}
