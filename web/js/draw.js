// Scene graphics: rays, point markers, error ellipsoids, lines and polygons, all in the
// rendered ECEF frame (georeferenced ECEF carried through the tileset's current modelMatrix).

import { eigSym3, transformCovariance, applyPoint } from "./linalg.js";
import { Overlay } from "./overlay.js";

const Cesium = window.Cesium;

export const COLORS = {
  ray: Cesium.Color.fromCssColorString("#f5b700"),
  outlier: Cesium.Color.fromCssColorString("#ff3b30"),
  excluded: Cesium.Color.fromCssColorString("#8a939b"),
  point: Cesium.Color.fromCssColorString("#f5b700"),
  selected: Cesium.Color.fromCssColorString("#3ea6ff"),
  solution: Cesium.Color.fromCssColorString("#00e5ff"),
  line: Cesium.Color.fromCssColorString("#3fb950"),
  polygon: Cesium.Color.fromCssColorString("#d2a8ff"),
  draft: Cesium.Color.fromCssColorString("#ffffff"),
  // building surfaces by kind (CityJSON semantic surface types), drawn translucent
  RoofSurface: Cesium.Color.fromCssColorString("#ff3d2e"),
  WallSurface: Cesium.Color.fromCssColorString("#ffd24a"),
  GroundSurface: Cesium.Color.fromCssColorString("#8a939b"),
};

/** The 3-D confidence scale of a drawn ellipsoid: 95 % (sqrt of chi-square(3) 0.95) or 1 sigma. */
export const SCALE_95_3D = 2.7955;

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
  constructor(viewer) {
    this.viewer = viewer;
    this.ds = new Cesium.CustomDataSource("gsgeo");
    viewer.dataSources.add(this.ds);
    this.groups = new Map();
    this.overlay = new Overlay(viewer, document.getElementById("viewer-wrap"), document.getElementById("status"));
  }

  clear(group) {
    const list = this.groups.get(group) || [];
    for (const e of list) this.ds.entities.remove(e);
    this.groups.set(group, []);
    this.overlay.clear(group);
  }

  add(group, options) {
    const e = this.ds.entities.add(options);
    if (!this.groups.has(group)) this.groups.set(group, []);
    this.groups.get(group).push(e);
    return e;
  }

  batch(fn) {
    this.ds.entities.suspendEvents();
    try { fn(); } finally { this.ds.entities.resumeEvents(); }
  }

  /** A ray from `origin` along unit `direction` for `len` metres (rendered ECEF). */
  ray(group, origin, direction, len, color, label) {
    const end = [origin[0] + direction[0] * len, origin[1] + direction[1] * len,
      origin[2] + direction[2] * len];
    this.overlay.add(group, [origin, end], { color: color.toCssColorString(), width: 2 });
    this.add(group, {
      position: cart(origin),
      point: { pixelSize: 6, color, outlineColor: Cesium.Color.BLACK, outlineWidth: 1,
        disableDepthTestDistance: Number.POSITIVE_INFINITY },
      label: label ? {
        text: label, font: "12px sans-serif", fillColor: color, outlineColor: Cesium.Color.BLACK,
        outlineWidth: 3, style: Cesium.LabelStyle.FILL_AND_OUTLINE, pixelOffset: new Cesium.Cartesian2(6, -6),
        horizontalOrigin: Cesium.HorizontalOrigin.LEFT, verticalOrigin: Cesium.VerticalOrigin.BOTTOM,
        disableDepthTestDistance: Number.POSITIVE_INFINITY,
      } : undefined,
    });
  }

  /** A point marker with its id; `id` becomes the entity id "pt:<id>" for picking. */
  marker(group, id, position, color, size = 9) {
    return this.add(group, {
      id: group === "points" ? `pt:${id}` : undefined,
      position: cart(position),
      point: { pixelSize: size, color, outlineColor: Cesium.Color.BLACK, outlineWidth: 1.5,
        disableDepthTestDistance: Number.POSITIVE_INFINITY },
      label: {
        text: id, font: "bold 13px sans-serif", fillColor: Cesium.Color.WHITE,
        outlineColor: Cesium.Color.BLACK, outlineWidth: 3, style: Cesium.LabelStyle.FILL_AND_OUTLINE,
        pixelOffset: new Cesium.Cartesian2(8, -6), horizontalOrigin: Cesium.HorizontalOrigin.LEFT,
        verticalOrigin: Cesium.VerticalOrigin.BOTTOM, disableDepthTestDistance: Number.POSITIVE_INFINITY,
      },
    });
  }

  /** The error ellipsoid of a point: georeferenced ECEF point and covariance (m^2), drawn through
   *  the model matrix `mm` (column-major) at confidence scale k. Returns the semi-axes (m). */
  ellipsoid(group, pointGeo, covGeo, mm, k, color) {
    const p = applyPoint(mm, pointGeo);
    const cov = transformCovariance(mm, covGeo);
    const { radii, vectors } = ellipsoidAxes(cov, k);
    if (!radii.every((r) => Number.isFinite(r) && r > 0)) return radii;
    // the three principal sections, drawn at true size
    const css = color.toCssColorString();
    for (const [a, b] of [[0, 1], [1, 2], [2, 0]]) {
      const ring = [];
      for (let i = 0; i < 48; i++) {
        const t = (2 * Math.PI * i) / 48;
        const ca = radii[a] * Math.cos(t);
        const sb = radii[b] * Math.sin(t);
        ring.push([0, 1, 2].map((k) => p[k] + ca * vectors[a][k] + sb * vectors[b][k]));
      }
      this.overlay.add(group, ring, { color: css, width: 1.5, closed: true });
    }
    return radii;
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
