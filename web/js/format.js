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

/** The measures of a line or polygon as the server gives them (lengths in m, areas in m²),
 *  each with its sigma: "length 3d 5.000 m ± 1.2 mm, ...". */
export function measuresText(ms) {
  if (!ms) return "—";
  if (ms.error) return ms.error;
  const parts = [];
  for (const [k, v] of Object.entries(ms)) {
    if (typeof v !== "number" || k.startsWith("sigma") || k === "n_points") continue;
    const sig = ms[`sigma_${k}`];
    const val = k.includes("area") ? area(v) : (/length|perimeter/.test(k) ? length(v) : fixed(v));
    parts.push(`${k.replace(/_/g, " ")} ${val}${typeof sig === "number" ? ` ± ${k.includes("area") ? area(sig) : length(sig)}` : ""}`);
  }
  return parts.join(", ") || "—";
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
