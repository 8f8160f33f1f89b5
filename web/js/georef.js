// The Georeference panel (key G): the project's control points (check points of role
// "control") and which of them are measured (a point with the control point's id); from 3
// measured on, the live fit of the 7-parameter similarity (POST /georeference, apply false)
// with each control point's residual, outliers in red, an exclude toggle per point; Apply
// (after a confirmation that says what will change) and Undo write the scene's root transform
// on the server, which re-solves every point of every project on the scene; the viewer then
// reloads the tileset and carries the camera by the returned similarity (similarity.js).
// Its state is state.georef: {open, status, fit, error, exclude: Set, seq, pending}.

import { api, download } from "./api.js";
import { $, fixed, h, mm } from "./format.js";
import { applySummary, changesNothing, decompose, notGeoreferenced } from "./similarity.js";

export const MIN_MEASURED = 3;

/** The panel, wired to the workplace `ctx`: {state, message, fail, sceneCentre(),
 *  georeferenceChanged(similarity16, version)}. Returns {toggle, refresh, banner}. */
export function georefPanel(ctx) {
  const { state } = ctx;
  const g = { open: false, status: null, fit: null, error: null, exclude: new Set(), seq: 0, pending: null };
  state.georef = g;
  const pidPath = () => `/projects/${encodeURIComponent(state.project.id)}`;

  function measured() {
    return g.status ? g.status.control.filter((c) => c.measured) : [];
  }

  /** The status (GET) and, from 3 measured control points on, the fit (POST, apply false). */
  async function refresh() {
    banner();
    if (!g.open) return;
    const seq = ++g.seq;
    if (!state.project) {
      g.status = null; g.fit = null; g.error = null;
      render();
      return;
    }
    try {
      const status = await api("GET", `${pidPath()}/georeference`);
      if (seq !== g.seq) return;
      g.status = status;
      const ids = new Set(status.control.map((c) => c.id));
      for (const id of [...g.exclude]) if (!ids.has(id)) g.exclude.delete(id);
      g.fit = null;
      g.error = null;
      const usable = measured().filter((c) => !g.exclude.has(c.id)).length;
      if (usable >= MIN_MEASURED) {
        render(true);
        try {
          const fit = await api("POST", `${pidPath()}/georeference`, { exclude: [...g.exclude], apply: false });
          if (seq !== g.seq) return;
          g.fit = fit;
        } catch (exc) {
          if (seq !== g.seq) return;
          g.error = exc.message;
        }
      }
    } catch (exc) {
      if (seq !== g.seq) return;
      g.status = null;
      g.error = exc.message;
    }
    render();
  }

  function toggleExclude(id) {
    if (g.exclude.has(id)) g.exclude.delete(id); else g.exclude.add(id);
    refresh();
  }

  /** Whether the fit is the scene's georeference already (fitted again after an Apply). */
  function current() {
    return Boolean(g.fit && g.fit.matrix && changesNothing(g.fit.matrix, ctx.sceneCentre()));
  }

  function residualRow(c, r) {
    const excluded = g.exclude.has(c.id);
    const outlier = r && r.outlier;
    const cls = excluded ? "excluded" : (outlier ? "outlier" : (c.measured ? "" : "unmeasured"));
    const d3 = r ? Math.hypot(r.dE, r.dN, r.dH) : null;
    const known = (state.checkPointList || []).find((k) => k.id === c.id);
    return h("tr", { "data-id": c.id, class: cls, title: outlier ? `${c.id} fails the blunder test (w ${fixed(r.w, 2)}, p ${fixed(r.p, 4)})` : "" },
      h("td", {}, h("button", { class: "known", "data-id": c.id, disabled: !(known && known.ecef),
        title: known ? `${ctx.knownText(known)}: look at it` : "", onclick: () => ctx.viewKnown(c.id) },
      `${c.id}${outlier ? " ⚑" : ""}`)),
      h("td", { class: "num coords" }, known ? ctx.knownText(known) : "—"),
      h("td", {}, c.measured ? "✓" : "not measured"),
      h("td", { class: "num" }, r ? mm(r.dE) : "—"),
      h("td", { class: "num" }, r ? mm(r.dN) : "—"),
      h("td", { class: "num" }, r ? mm(r.dH) : "—"),
      h("td", { class: "num" }, r ? mm(d3) : "—"),
      h("td", { class: "num" }, r && Number.isFinite(r.w) ? fixed(r.w, 2) : "—"),
      h("td", {}, c.measured ? h("label", { title: "leave this point out of the fit" },
        h("input", { type: "checkbox", class: "georef-exclude", "data-id": c.id, checked: excluded,
          onchange: () => toggleExclude(c.id) }), " excl.") : ""));
  }

  function summaryText(fit) {
    const d = decompose(fit.matrix);
    const lines = [];
    const sig = Number.isFinite(fit.scale_sigma) ? ` ± ${(fit.scale_sigma * 1e6).toFixed(1)}` : "";
    lines.push(`scale × ${d.scale.toFixed(6)} (${d.ppm >= 0 ? "+" : ""}${d.ppm.toFixed(1)}${sig} ppm)`);
    const rs = fit.rotation_sigma_deg;
    lines.push(`rotation ${d.angleDeg.toFixed(4)}°${Array.isArray(rs) ? ` (σ about X/Y/Z ${rs.map((x) => fixed(x, 4)).join(" / ")}°)` : ""}`);
    const ts = fit.translation_sigma;
    if (Array.isArray(ts)) lines.push(`translation σ X/Y/Z ${ts.map((x) => mm(x)).join(" / ")} mm (ECEF)`);
    lines.push(`σ0 ${fixed(fit.sigma0, 2)}   dof ${fit.dof ?? "—"}${Number.isFinite(fit.global_test_p) ? `   global test p ${fixed(fit.global_test_p, 3)}` : ""}`);
    const rc = fit.rmse_control;
    if (rc) lines.push(`RMSE control H ${mm(rc.horizontal)}  V ${mm(rc.h)}  3D ${mm(rc["3d"])} mm (${rc.count})`);
    const rk = fit.rmse_check;
    if (rk) lines.push(`RMSE check   H ${mm(rk.horizontal)}  V ${mm(rk.h)}  3D ${mm(rk["3d"])} mm (${rk.count})`);
    return lines.join("\n");
  }

  function render(busy = false) {
    const panel = $("#georef-panel");
    panel.hidden = !g.open;
    if (!g.open) return;
    const st = g.status;
    const info = $("#georef-state");
    if (!state.project) {
      info.textContent = "Open a project on this scene to georeference it.";
    } else if (!st) {
      info.textContent = g.error || "loading…";
    } else {
      info.textContent = `Scene ${st.scene ?? "—"}: ${st.georeferenced ? "georeferenced" : "NOT georeferenced"}, version ${st.version}.`;
    }
    info.classList.toggle("error", Boolean(state.project && !st && g.error));
    const control = st ? st.control : [];
    const byId = new Map(((g.fit && g.fit.control) || []).map((r) => [r.id, r]));
    const rows = control.map((c) => residualRow(c, byId.get(c.id)));
    $("#georef-table tbody").replaceChildren(...(rows.length ? rows : [h("tr", {}, h("td", { colspan: 9, class: "muted" },
      "No control points: import them below (Check points, role control), then measure each target with the control point's id."))]));
    const n = measured().length;
    const box = $("#georef-fit");
    box.replaceChildren();
    box.classList.remove("error");
    if (g.fit) {
      box.append(h("div", { class: "solution", id: "georef-summary" }, summaryText(g.fit)));
      if (g.fit.outliers && g.fit.outliers.length) {
        const wo = g.fit.without_outliers;
        box.append(h("div", { class: "error", id: "georef-outliers" },
          `Outlier${g.fit.outliers.length > 1 ? "s" : ""}: ${g.fit.outliers.map((id) => {
            const r = byId.get(id);
            return r ? `${id} (${mm(Math.hypot(r.dE, r.dN, r.dH))} mm)` : id;
          }).join(", ")}. Exclude ${g.fit.outliers.length > 1 ? "them" : "it"} or accept on Apply.`
          + (wo && wo.rmse_control ? ` Without: RMSE 3D ${mm(wo.rmse_control["3d"])} mm, scale × ${fixed(wo.scale, 6)}.` : "")));
      }
      for (const w of g.fit.warnings || []) box.append(h("div", { class: "warn" }, `⚠ ${w}`));
      if (current()) {
        box.append(h("p", { class: "note", id: "georef-current" }, "The scene already has this georeference: nothing to apply."));
      }
    } else if (g.error && st) {
      box.textContent = g.error;
      box.classList.add("error");
    } else if (busy) {
      box.textContent = "fitting…";
    } else if (st) {
      box.textContent = `${n} of ${control.length} control points measured; the fit needs ${MIN_MEASURED} (not excluded).`;
    }
    const cur = st ? (st.history || []).find((e) => e.version === st.version) : null;
    $("#btn-georef-apply").disabled = !g.fit || current();
    $("#btn-georef-undo").disabled = !(cur && cur.parent !== null && cur.parent !== undefined);
    $("#btn-georef-report").disabled = !state.project;
  }

  /** The banner over an un-georeferenced scene. */
  function banner() {
    const info = state.scenes.find((s) => s.name === state.sceneName);
    const local = Boolean(state.sceneName && notGeoreferenced(info));
    $("#georef-banner").hidden = !local;
    if (ctx.localScene) ctx.localScene(local);
  }

  async function projectsOnScene() {
    const on = state.projects.filter((p) => p.scene && p.scene === state.sceneName);
    const counts = await Promise.all(on.map((p) => api("GET", `/projects/${encodeURIComponent(p.id)}`)));
    return counts.map((p) => ({ name: p.name, points: (p.counts && p.counts.n_points) || 0 }));
  }

  function confirm(title, lines, label, action) {
    g.pending = action;
    $("#georef-confirm-title").textContent = title;
    $("#btn-georef-confirm").textContent = label;
    $("#georef-confirm-text").replaceChildren(...lines.map((l) => h("li", {}, l)));
    $("#georef-confirm").hidden = false;
    $("#btn-georef-confirm").focus();
  }

  function closeConfirm() {
    g.pending = null;
    $("#georef-confirm").hidden = true;
  }

  /** Whether a change must wait: a point is being measured (its rays are in the current
   *  frame), or the viewer shows another scene than the project's (it could not follow). */
  function mustWait() {
    if (state.measure && state.measure.rays.length) {
      ctx.message("Finish or cancel the point being measured first: its rays are in the current frame.", true);
      return true;
    }
    if (state.project && state.project.scene !== state.sceneName) {
      ctx.message(`Project ${state.project.name} is on scene '${state.project.scene ?? "none"}': load that scene first.`, true);
      return true;
    }
    return false;
  }

  async function askApply() {
    if (!g.fit || mustWait()) return;
    const fit = g.fit;
    try {
      const lines = applySummary(fit, ctx.sceneCentre(), await projectsOnScene());
      const body = { exclude: [...g.exclude], apply: true, accept_outliers: Boolean(fit.outliers && fit.outliers.length) };
      confirm("Apply this georeference to the scene?", lines, "Apply", async () => {
        const r = await api("POST", `${pidPath()}/georeference`, body);
        await ctx.georeferenceChanged(r.scene.similarity);
        ctx.message(`Applied: the scene is at georeference version ${r.scene.version}; ${r.remeasured_points ?? "its"} points re-solved.`);
      });
    } catch (exc) { ctx.fail(exc); }
  }

  async function askUndo() {
    if (mustWait() || !g.status) return;
    try {
      const projects = await projectsOnScene();
      const total = projects.reduce((n, p) => n + p.points, 0);
      confirm("Undo the scene's georeference?", [
        `The scene goes back to the georeference before version ${g.status.version}.`,
        `Re-solved: ${total} points in ${projects.length} project${projects.length === 1 ? "" : "s"} on this scene.`,
      ], "Undo", async () => {
        const r = await api("POST", `${pidPath()}/georeference/undo`);
        await ctx.georeferenceChanged(r.similarity);
        ctx.message(`Undone: the scene is at georeference version ${r.version}; ${r.remeasured_points ?? "its"} points re-solved.`);
      });
    } catch (exc) { ctx.fail(exc); }
  }

  async function confirmed() {
    const action = g.pending;
    closeConfirm();
    if (!action) return;
    try {
      await action();
    } catch (exc) { ctx.fail(exc); }
    await refresh();
  }

  async function report() {
    if (!state.project) { ctx.message("Open a project first: the report is a project's.", true); return; }
    try {
      const name = await download(`${pidPath()}/report?format=pdf`, `${state.project.id}-report.pdf`);
      ctx.message(`Downloaded ${name}.`);
    } catch (exc) { ctx.fail(exc); }
  }

  function toggle(show) {
    g.open = show === undefined ? !g.open : Boolean(show);
    render();
    if (g.open) {
      refresh();
      $("#georef-panel").scrollIntoView({ block: "nearest" });
    }
  }

  $("#btn-georef").addEventListener("click", (ev) => { toggle(); ev.currentTarget.blur(); });
  $("#btn-georef-close").addEventListener("click", () => toggle(false));
  $("#btn-georef-banner").addEventListener("click", () => toggle(true));
  $("#btn-georef-apply").addEventListener("click", askApply);
  $("#btn-georef-undo").addEventListener("click", askUndo);
  $("#btn-georef-report").addEventListener("click", report);
  $("#btn-report").addEventListener("click", (ev) => { report(); ev.currentTarget.blur(); });
  $("#btn-georef-confirm").addEventListener("click", confirmed);
  $("#btn-georef-cancel").addEventListener("click", closeConfirm);

  return { toggle, refresh, banner, closeConfirm, get confirming() { return !$("#georef-confirm").hidden; } };
}
