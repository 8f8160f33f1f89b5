// Number and text formatting for the panels (metres in, readable strings out).

export function fixed(x, digits = 3) {
  return x === null || x === undefined || !Number.isFinite(x) ? "—" : x.toFixed(digits);
}

/** metres -> millimetres with one decimal ("—" when missing). */
export function mm(x, digits = 1) {
  return x === null || x === undefined || !Number.isFinite(x) ? "—" : (x * 1000).toFixed(digits);
}

/** A length in metres with a sensible unit. */
export function length(x) {
  if (x === null || x === undefined || !Number.isFinite(x)) return "—";
  const a = Math.abs(x);
  if (a < 0.1) return `${(x * 1000).toFixed(1)} mm`;
  if (a < 1000) return `${x.toFixed(3)} m`;
  return `${(x / 1000).toFixed(4)} km`;
}

export function area(x) {
  if (x === null || x === undefined || !Number.isFinite(x)) return "—";
  return Math.abs(x) < 1e5 ? `${x.toFixed(3)} m²` : `${(x / 1e4).toFixed(4)} ha`;
}

/** The measures of a line or polygon as the server gives them (lengths in m, areas in m²,
 *  1σ beside each): grid values (in the CRS's plane), their ground values (divided by the
 *  combined scale factor, areas by its square) and that factor. "2-D grid 12.345 m ± 1.2 mm,
 *  ground 12.347 m · 3-D 12.400 m ± 1.5 mm · CSF 0.99985127". */
export function measuresText(ms) {
  if (!ms) return "—";
  if (ms.error) return ms.error;
  const num = (v) => typeof v === "number" && Number.isFinite(v);
  const withSig = (v, sig, fmt) => `${fmt(v)}${num(sig) ? ` ± ${fmt(sig)}` : ""}`;
  const parts = [];
  const groundOf = (k, fmt) => (num(ms[`${k}_ground`]) ? `, ground ${fmt(ms[`${k}_ground`])}` : "");
  if (num(ms.length_2d)) parts.push(`2-D grid ${withSig(ms.length_2d, ms.sigma_length_2d, length)}${groundOf("length_2d", length)}`);
  if (num(ms.length_3d)) parts.push(`3-D ${withSig(ms.length_3d, ms.sigma_length_3d, length)}`);
  if (num(ms.area_2d)) parts.push(`area grid ${withSig(ms.area_2d, ms.sigma_area_2d, area)}${groundOf("area_2d", area)}`);
  if (num(ms.perimeter_2d)) parts.push(`perimeter grid ${withSig(ms.perimeter_2d, ms.sigma_perimeter_2d, length)}${groundOf("perimeter_2d", length)}`);
  if (num(ms.combined_scale_factor)) parts.push(`CSF ${ms.combined_scale_factor.toFixed(8)}`);
  return parts.join(" · ") || "—";
}

export function escapeHtml(s) {
  return String(s ?? "").replace(/[&<>"']/g, (c) => ({
    "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;",
  }[c]));
}

/** The first element matching a CSS selector. */
export const $ = (sel) => document.querySelector(sel);

/** Element helper: h("td", {class: "num"}, "1.0") */
export function h(tag, attrs = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else if (k === "class") el.className = v;
    else el.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined || c === false) continue;
    el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return el;
}

/** A point's height system in one phrase: the server's vertical_datum (e.g. "ellipsoidal
 *  height on WGS 84 (EPSG:4979)"), with the height type only where the datum does not say it. */
export function heightsText(heightType, verticalDatum) {
  if (!verticalDatum) return heightType ? `${heightType} height` : "";
  if (!heightType || verticalDatum.toLowerCase().includes(heightType.toLowerCase())) return verticalDatum;
  return `${verticalDatum} (${heightType} height)`;
}

/** The warnings every solved point of `points` shares (two points at least): the project's,
 *  e.g. a datum transformation accurate to 2 m only, shown once instead of on every point. */
export function sharedWarnings(points) {
  const lists = points.filter((p) => p.status === "solved" && p.result)
    .map((p) => p.result.warnings || []);
  if (lists.length < 2) return [];
  return lists[0].filter((w, i, all) => all.indexOf(w) === i && lists.every((l) => l.includes(w)));
}
