// The project's LoD2 buildings (GET /buildings): listed with their measures, the selected one's
// adjustment and warnings in a detail box, and every model drawn at its true place from the
// server's vertices_ecef (georeferenced ECEF, carried by the tileset's modelMatrix as the
// points are): translucent faces coloured by kind (roof, wall, ground) with their edges.
// The list is state.buildings (the API's answers: BuildingModel.to_dict() + vertices_ecef; a
// building that cannot be built from its points now has only its spec and `error`).

import { api } from "./api.js";
import { COLORS } from "./draw.js";
import { $, area, fixed, h, mm } from "./format.js";
import { applyPoint } from "./linalg.js";
import { upsert, without } from "./merge.js";

/** Alpha of the drawn faces by kind: the roof most visible, the ground faint. */
const ALPHA = { RoofSurface: 0.55, WallSurface: 0.35, GroundSurface: 0.25 };
const EDGE = window.Cesium.Color.fromCssColorString("#ffffff");

/** Every point id a building uses (its roof and wall corners and a ground point). */
export function buildingPointIds(b) {
  const spec = b.spec || {};
  const ids = [...(spec.roofs || []), ...(spec.walls || [])].flat();
  if (typeof spec.ground === "string") ids.push(spec.ground);
  if (spec.ground && typeof spec.ground === "object" && typeof spec.ground.point_id === "string") {
    ids.push(spec.ground.point_id);
  }
  return ids;
}

/** "7.500 ± 0.004" (value and 1-sigma in the same unit, `digits` decimals). */
function withSigma(v, s, digits = 3) {
  return `${fixed(v, digits)}${Number.isFinite(s) ? ` ± ${fixed(s, digits)}` : ""}`;
}

/** The largest vertex correction of the planarity adjustment (m) and the point it moved. */
function largestCorrection(adjustment) {
  let best = null;
  for (const [id, d] of Object.entries((adjustment && adjustment.corrections) || {})) {
    const n = Math.hypot(...d);
    if (!best || n > best.size) best = { id, size: n };
  }
  return best;
}

/** The buildings list and drawing, wired to the workplace `ctx`: {state, draw, modelMatrix,
 *  message, fail}. Returns {load, stored, uses, render, redraw}. */
export function buildingsPanel(ctx) {
  const { state } = ctx;
  state.buildings = [];
  let selected = null;
  const path = () => `/projects/${encodeURIComponent(state.project.id)}/buildings`;

  /** Fetch the project's buildings (none without a project). */
  async function load() {
    if (!state.project) { state.buildings = []; render(); return; }
    try {
      const data = await api("GET", path());
      state.buildings = Array.isArray(data) ? data : (data.buildings || []);
    } catch (exc) {
      state.buildings = [];
      ctx.fail(exc);
    }
    render();
  }

  /** Building `b` as the server stored it: into the list, selected. */
  function stored(b) {
    state.buildings = upsert(state.buildings, b);
    selected = b.id;
    render();
  }

  /** Whether a building uses one of the point ids `ids` (its model is the server's to redo). */
  function uses(ids) {
    return state.buildings.some((b) => buildingPointIds(b).some((q) => ids.includes(q)));
  }

  async function remove(id) {
    try {
      await api("DELETE", `${path()}/${encodeURIComponent(id)}`);
      state.buildings = without(state.buildings, id);
      if (selected === id) selected = null;
      render();
      ctx.message(`Deleted building ${id}.`);
    } catch (exc) { ctx.fail(exc); }
  }

  function render() {
    if (selected && !state.buildings.some((b) => b.id === selected)) selected = null;
    const rows = state.buildings.map((b) => {
      const ms = b.measures || {};
      return h("tr", { "data-id": b.id, class: b.id === selected ? "selected" : "",
        onclick: () => { selected = selected === b.id ? null : b.id; render(); } },
      h("td", {}, b.id),
      h("td", {}, ms.roof_type || "—"),
      h("td", { class: "num" }, Number.isFinite(ms.volume) ? `${ms.volume.toFixed(1)} m³` : "—"),
      h("td", { class: "num" }, fixed(ms.measured_height, 2)),
      b.error ? h("td", { class: "error", title: b.error }, "✖")
        : h("td", { class: (b.warnings || []).length ? "warn" : "", title: (b.warnings || []).join("\n") },
          (b.warnings || []).length ? "⚠" : ""),
      h("td", {}, h("button", { title: `delete ${b.id}`,
        onclick: (ev) => { ev.stopPropagation(); remove(b.id); } }, "✕")));
    });
    $("#buildings-table tbody").replaceChildren(...(rows.length ? rows
      : [h("tr", {}, h("td", { colspan: 6, class: "muted" }, "None yet: B, then click the corners of each roof face."))]));
    renderDetail();
    redraw();
  }

  /** The selected building: adjustment, volume, footprint, heights with sigmas, roof, warnings. */
  function renderDetail() {
    const box = $("#building-detail");
    const b = state.buildings.find((x) => x.id === selected);
    if (!b) { box.hidden = true; box.replaceChildren(); return; }
    box.hidden = false;
    if (b.error) {
      box.replaceChildren(h("div", { class: "kv" }, h("div", {}, "Building"), h("div", { class: "mono" }, b.id)),
        h("p", { class: "error" }, `Cannot be built from its points now: ${b.error}`));
      return;
    }
    const ms = b.measures || {};
    const adj = b.adjustment || {};
    const kv = [];
    const row = (k, v) => kv.push(h("div", {}, k), h("div", { class: "mono" }, v));
    row("Building", `${b.id} · ${ms.roof_type || "?"} roof · ${(b.surfaces || []).length} surfaces`);
    row("Volume", `${withSigma(ms.volume, ms.sigma_volume, 2)} m³`);
    row("Footprint", `${area(ms.footprint_area)}${Number.isFinite(ms.sigma_footprint_area) ? ` ± ${area(ms.sigma_footprint_area)}` : ""}`);
    row("Eaves H", `${withSigma(ms.eaves_height, ms.sigma_eaves_height)} m`);
    row("Ridge H", `${withSigma(ms.ridge_height, ms.sigma_ridge_height)} m`);
    row("Ground H", `${withSigma(ms.ground_height, ms.sigma_ground_height)} m`);
    row("Height", `${withSigma(ms.measured_height, ms.sigma_measured_height)} m, ridge above the ground`);
    for (const s of ms.roof_slopes || []) {
      row(`Roof ${s.face + 1} slope`, `${withSigma(s.slope_deg, s.sigma_slope_deg, 2)}°, aspect ${fixed(s.aspect_deg, 1)}°`);
    }
    (adj.faces || []).forEach((f, i) => {
      const name = f.kind === "wall" ? "Wall" : (f.kind === "roof" ? "Roof" : "Face");
      row(`${name} ${(f.index ?? i) + 1} RMS`, `${mm(f.rms)} mm (${(f.points || []).join(", ")})`
        + `${Number.isFinite(f.p) ? `, p ${fixed(f.p, 3)}` : ""}`);
    });
    const big = largestCorrection(adj);
    if (big) row("Largest corr.", `${mm(big.size)} mm at ${big.id}`);
    if (Number.isFinite(adj.sigma0)) row("σ0", fixed(adj.sigma0, 2));
    const warns = b.warnings || [];
    box.replaceChildren(h("div", { class: "kv" }, ...kv),
      warns.length ? h("div", { class: "warn" }, ...warns.map((w) => h("div", {}, `⚠ ${w}`))) : "");
  }

  /** Every building's surfaces, translucent by kind, with white edges (the selected thicker). */
  function redraw() {
    ctx.draw.clear("buildings");
    const mmNow = ctx.modelMatrix();
    for (const b of state.buildings) {
      const v = (b.vertices_ecef || []).map((p) => applyPoint(mmNow, p));
      for (const s of b.surfaces || []) {
        const ring = (s.ring || []).map((i) => v[i]).filter(Boolean);
        const color = COLORS[s.kind] || COLORS.GroundSurface;
        ctx.draw.face("buildings", ring, color, ALPHA[s.kind] ?? 0.3, EDGE, b.id === selected ? 2.5 : 1.5);
      }
    }
  }

  return { load, stored, uses, render, redraw };
}
