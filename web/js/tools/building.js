// The building tool (B): an LoD2 building from measured roof corners. Click the measured points
// (their markers in the scene or rows of the points list) of one roof face in order, Enter
// closes the face; the next face the same way; Enter on an empty face stores the building
// (POST /buildings {id, roofs, ground}): the server adjusts the faces to planes, extrudes the
// walls to the ground and answers the model. Faces share corners by point id. Its state is
// state.building: {faces: [[point ids], ...], current: [point ids]}.

import { api } from "../api.js";
import { COLORS } from "../draw.js";
import { $ } from "../format.js";
import { applyPoint } from "../linalg.js";

/** The next free automatic building id B<n> (above every stored B<number>). */
export function nextBuildingId(buildings) {
  const used = new Set(buildings.map((b) => b.id));
  let n = 1;
  for (const b of buildings) {
    const m = /^B(\d+)$/.exec(b.id);
    if (m) n = Math.max(n, Number(m[1]) + 1);
  }
  while (used.has(`B${n}`)) n++;
  return `B${n}`;
}

/** The ground as the API takes it from the panel's field: a number is a height (the project's
 *  height system, CRS vertical units), other text a measured point's id; null when empty. */
export function parseGround(text) {
  const t = String(text ?? "").trim();
  if (!t) return null;
  const x = Number(t.replace(",", "."));
  return /^[-+]?(\d+([.,]\d*)?|[.,]\d+)([eE][-+]?\d+)?$/.test(t) && Number.isFinite(x) ? x : t;
}

function faceText(ids) {
  return ids.join(" → ");
}

/** The faces so far in the panel, and as white rings (the open face as a path) in the scene. */
function drawDraft(ctx) {
  const b = ctx.state.building;
  const lines = b.faces.map((f, i) => `face ${i + 1}: ${faceText(f)}`);
  lines.push(b.current.length ? `face ${b.faces.length + 1}: ${faceText(b.current)} …`
    : `face ${b.faces.length + 1}: click its corners in order…`);
  $("#building-faces").textContent = lines.join("\n");
  ctx.draw.clear("draft");
  const mmNow = ctx.modelMatrix();
  const pos = (ids) => ids.map((id) => ctx.pointById(id)).filter((p) => p && p.result)
    .map((p) => applyPoint(mmNow, p.result.point_ecef));
  for (const f of b.faces) ctx.draw.path("draft", pos(f), COLORS.RoofSurface, true, 2);
  ctx.draw.path("draft", pos(b.current), COLORS.draft, false, 2);
}

function pickPoint(ctx, id) {
  const b = ctx.state.building;
  const p = ctx.pointById(id);
  if (!p || !p.result) { ctx.message(`${id} has no solved position.`, true); return; }
  if (b.current.includes(id)) {
    // a click on the face's first corner closes it, as Enter does
    if (id === b.current[0] && b.current.length >= 3) closeFace(ctx);
    else ctx.message(`${id} is already a corner of this face.`);
    return;
  }
  b.current.push(id);
  drawDraft(ctx);
  ctx.updateStatus();
}

function closeFace(ctx) {
  const b = ctx.state.building;
  b.faces.push(b.current);
  b.current = [];
  drawDraft(ctx);
  ctx.updateStatus();
}

function end(ctx) {
  ctx.state.building = null;
  $("#building-panel").hidden = true;
  ctx.draw.clear("draft");
  ctx.done();
}

const building = {
  id: "building",
  shortcut: "B",
  label: "Building",
  title: "LoD2 building from measured roof corners (B)",
  needsProject: true,

  setup() {
    // the next free id is proposed unless the user types one
    $("#bld-id").addEventListener("input", () => { $("#bld-id").dataset.auto = "0"; });
  },

  start(ctx) {
    ctx.state.building = { faces: [], current: [] };
    $("#bld-id").value = nextBuildingId(ctx.state.buildings || []);
    $("#bld-id").dataset.auto = "1";
    $("#building-panel").hidden = false;
    drawDraft(ctx);
  },

  /** A click picks the point whose marker is within 14 px. */
  click(ctx, event) {
    const id = ctx.nearestPoint(event.position, 14);
    if (id) pickPoint(ctx, id);
    else ctx.message("Click on a point marker (or a row of the points list).");
  },

  /** A row of the points list was clicked. */
  pick(ctx, id) {
    pickPoint(ctx, id);
  },

  /** Backspace: drop the last corner; on an empty face, reopen the previous face. */
  undo(ctx) {
    const b = ctx.state.building;
    if (b.current.length) b.current.pop();
    else if (b.faces.length) b.current = b.faces.pop();
    drawDraft(ctx);
    ctx.updateStatus();
  },

  /** Enter: close the face being clicked; on an empty face, store the building. */
  async finish(ctx) {
    const b = ctx.state.building;
    if (b.current.length >= 3) { closeFace(ctx); return; }
    if (b.current.length) {
      ctx.message(`A roof face needs at least 3 corners (${b.current.length} so far).`, true);
      return;
    }
    await building.store(ctx);
  },

  /** Store the closed faces as a building (the panel's Store button, Enter on an empty face). */
  async store(ctx) {
    const { state } = ctx;
    const b = state.building;
    if (!b) return;
    if (!b.faces.length) { ctx.message("Click the corners of a roof face first (Enter closes it).", true); return; }
    if (b.current.length) { ctx.message("Close the face being clicked first (Enter), or remove its corners (Backspace).", true); return; }
    const ground = parseGround($("#bld-ground").value);
    if (ground === null) {
      ctx.message("Give the ground: a height (the project's height system) or the id of a measured ground point.", true);
      return;
    }
    const typed = $("#bld-id").dataset.auto !== "1" && $("#bld-id").value.trim();
    const id = typed || nextBuildingId(state.buildings || []);
    try {
      const made = await api("POST", `/projects/${encodeURIComponent(state.project.id)}/buildings`,
        { id, roofs: b.faces, ground });
      if (state.building !== b) return;
      end(ctx);
      ctx.buildingStored(made);
      const ms = made.measures || {};
      ctx.message(`Stored building ${made.id}${ms.roof_type ? ` (${ms.roof_type} roof)` : ""}`
        + `${Number.isFinite(ms.volume) ? `, volume ${ms.volume.toFixed(1)} m³` : ""}.`);
    } catch (exc) { ctx.fail(exc); }
  },

  cancel(ctx, event) {
    end(ctx);
    if (event) ctx.message("Building cancelled.");
  },

  status(ctx) {
    const b = ctx.state.building;
    const n = b.faces.length;
    let text = `Building: face ${n + 1}: `;
    if (!b.current.length) {
      text += "click the measured corners of a roof face in order (markers or the points list)"
        + (n ? `; Enter stores the building with ${n} face${n > 1 ? "s" : ""}. ` : ". ");
    } else {
      text += `${faceText(b.current)}. `
        + (b.current.length >= 3 ? "Enter closes the face. " : `Needs ${3 - b.current.length} more corner${b.current.length === 2 ? "" : "s"}. `);
    }
    return { text: text + "Backspace removes the last corner, Esc cancels.", className: "picking" };
  },

  redraw: drawDraft,
};

export default building;
