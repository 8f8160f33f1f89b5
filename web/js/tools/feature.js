// What the line and polygon tools share: pick measured points (their markers in the scene or
// rows of the points list) in order, Enter stores the feature. Their state is state.feature:
// {kind, points: [point ids]}. Not a tool itself: line.js and polygon.js make one each.

import { api } from "../api.js";
import { COLORS } from "../draw.js";
import { $, measuresText } from "../format.js";
import { applyPoint } from "../linalg.js";

function pickPoint(ctx, id) {
  const f = ctx.state.feature;
  const p = ctx.pointById(id);
  if (!p || !p.result) { ctx.message(`${id} has no solved position.`, true); return; }
  if (f.points[f.points.length - 1] === id) return;
  if (f.kind === "polygon" && f.points.includes(id)) { ctx.message(`${id} is already a vertex.`); return; }
  f.points.push(id);
  drawDraft(ctx);
  ctx.updateStatus();
}

/** The picked points in the panel and as a white path (closed for a polygon) in the scene. */
function drawDraft(ctx) {
  const f = ctx.state.feature;
  $("#feature-points").textContent = f.points.length ? f.points.join(" → ") : "click measured points…";
  ctx.draw.clear("draft");
  const mmNow = ctx.modelMatrix();
  const pos = f.points.map((id) => applyPoint(mmNow, ctx.pointById(id).result.point_ecef));
  ctx.draw.path("draft", pos, COLORS.draft, f.kind === "polygon", 2);
}

/** The tool that builds a `kind` ("line" or "polygon", the API's name) of at least `need`
 *  points, started by key `shortcut`; `plural` names its API collection. */
export function featureTool({ kind, plural, need, shortcut, label, title }) {
  const tool = {
    id: kind,
    shortcut,
    label,
    title,
    needsProject: true,

    start(ctx) {
      ctx.state.feature = { kind, points: [] };
      $("#feature-panel").hidden = false;
      $("#feature-title").textContent = `New ${kind}`;
      $("#feat-code").value = "";
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

    /** Backspace: drop the last picked point. */
    undo(ctx) {
      ctx.state.feature.points.pop();
      drawDraft(ctx);
      ctx.updateStatus();
    },

    /** Enter: store the feature. */
    async finish(ctx) {
      const { state } = ctx;
      const f = state.feature;
      if (f.points.length < need) { ctx.message(`A ${kind} needs at least ${need} points.`, true); return; }
      try {
        const made = await api("POST", `/projects/${encodeURIComponent(state.project.id)}/${plural}`,
          { points: f.points, code: $("#feat-code").value.trim() });
        tool.cancel(ctx);
        await ctx.featureStored(made);
        ctx.message(`Stored ${kind} ${made.id}: ${measuresText(made.measures)}`);
      } catch (exc) { ctx.fail(exc); }
    },

    cancel(ctx) {
      ctx.state.feature = null;
      $("#feature-panel").hidden = true;
      ctx.draw.clear("draft");
      ctx.done();
    },

    status(ctx) {
      const f = ctx.state.feature;
      const text = `New ${kind}: click a measured point in the scene or the list (${f.points.length} picked`
        + `${f.points.length ? ": " + f.points.join(" → ") : ""}). `
        + (f.points.length >= need ? "Enter stores it. " : `Needs ${need} points. `)
        + "Backspace removes the last, Esc cancels.";
      return { text, className: "picking" };
    },

    redraw: drawDraft,
  };
  return tool;
}
