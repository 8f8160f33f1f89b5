// The measure tool (M): each click adds a ray from the camera through the clicked pixel; from
// two rays on the server intersects them (/api/intersect) and the panel shows the solution,
// its error ellipsoid and each ray's residual; Enter asks for a new point's id (idprompt.js) and
// Enter again stores it (a stored point reopened with "Add rays" is stored at once). Its state is
// state.measure:
// {rays, excluded: Set, editing, pointId, solution, error, seq, georefVersion}; a new point is
// stored with the georeference version of the tileset its first ray was taken in.

import { api } from "../api.js";
import { COLORS } from "../draw.js";
import { $, fixed, h, mm } from "../format.js";
import { IDENTITY16, applyPoint, norm, sub } from "../linalg.js";
import { captureRay, raysInCurrentFrame } from "../rays.js";
import { nextPointId } from "../pointid.js";
import { closeIdPrompt, idError, idPromptOpen, openIdPrompt, promptedId } from "../idprompt.js";
import { hitsNothing, refresh as refreshGuide, requestDepth } from "../guide.js";
import { autoAim, autoAimPanel, autoAimResult, rayBadge, rememberReference } from "../autoaim.js";
import { tooFewRays } from "../autoaimtext.js";

/** What to say about ray i (0-based) of `m` that hits no splat: how to get rid of it. */
function noHitText(m, i) {
  return `Ray ${i + 1} hits no splat (sky?) — ${i === m.rays.length - 1 ? "Backspace removes it" : "exclude it"}`;
}

/** The indices of the rays known to hit no splat (and not excluded). */
function noHitRays(m) {
  return m.rays.map((r, i) => i).filter((i) => !m.excluded.has(i) && hitsNothing(m.rays[i]));
}

function activeExcluded(m) {
  return [...m.excluded].filter((i) => i < m.rays.length);
}

async function solveLive(ctx) {
  const m = ctx.state.measure;
  const seq = ++m.seq;
  m.solution = null;
  m.error = null;
  if (m.rays.length - activeExcluded(m).length < 2) { render(ctx); return; }
  render(ctx, true);
  try {
    const res = await api("POST", "/intersect", {
      rays: m.rays, exclude: activeExcluded(m), id: m.pointId, ...ctx.solveSettings(),
    });
    if (ctx.state.measure !== m || seq !== m.seq) return;
    m.solution = res;
  } catch (exc) {
    if (ctx.state.measure !== m || seq !== m.seq) return;
    m.error = exc.message;
  }
  render(ctx);
}

function toggleExclude(ctx, i) {
  const m = ctx.state.measure;
  if (m.excluded.has(i)) m.excluded.delete(i); else m.excluded.add(i);
  solveLive(ctx);
}

/** What the drawn ellipsoid is: `ell` as Drawer.ellipsoid returns it (true semi-axes, the
 *  exaggeration it is drawn with, its quality). */
function ellipsoidNote(conf, ell) {
  const what = conf === "95"
    ? "95 % confidence ellipsoid (3-D: 2.7955 σ on each principal axis)"
    : "1σ ellipsoid (holds only 19.9 % of the probability in 3-D; 95 % is 2.7955× larger)";
  if (!ell || !ell.radii.every(Number.isFinite)) return `Drawn: ${what}.`;
  const how = ell.scale === 1 ? "Drawn at true size" : `Drawn ×${ell.scale} (enlarged to be seen; 'true size' draws it in metres)`;
  return `${how}: ${what}; semi-axes ${ell.radii.map((r) => mm(r)).join(" × ")} mm`
    + `; 95 % radius ${mm(ell.r95)} mm: ${ell.quality} (tolerance 20 / 50 mm).`;
}

function solutionText(res) {
  const lines = [];
  if (res.crs) {
    lines.push(`E ${fixed(res.easting)}  N ${fixed(res.northing)}  H ${fixed(res.height)} m`);
    lines.push(`   ${res.crs}${res.vertical_datum ? " + " + res.vertical_datum : ""} (${res.height_type || "h"})`);
    lines.push(`σ E/N/H ${mm(res.sigma_e)} / ${mm(res.sigma_n)} / ${mm(res.sigma_h)} mm (1σ)`);
  }
  lines.push(`lon ${fixed(res.lon, 8)}  lat ${fixed(res.lat, 8)}  h ${fixed(res.h_wgs84)} m (WGS 84)`);
  lines.push(`σ0 ${fixed(res.sigma0, 2)}   rays ${res.n_rays}   max angle ${fixed(res.max_angle_deg, 1)}°   rms ${mm(res.rms_m)} mm`);
  return lines.join("\n");
}

/** Where ray `ray` was taken from, seen from the solved point `pointEcef` (georeferenced ECEF,
 *  carried into the ray's rendered frame by its model matrix): azimuth from north and
 *  elevation (degrees, in the point's local east-north-up) and range (m) of its camera. */
export function station(ray, pointEcef) {
  const Cesium = window.Cesium;
  const p = applyPoint(ray.model_matrix || IDENTITY16, pointEcef);
  const enu = Cesium.Transforms.eastNorthUpToFixedFrame(new Cesium.Cartesian3(...p));
  const local = Cesium.Matrix4.multiplyByPoint(Cesium.Matrix4.inverseTransformation(enu, new Cesium.Matrix4()),
    new Cesium.Cartesian3(...ray.origin), new Cesium.Cartesian3());
  const range = Cesium.Cartesian3.magnitude(local);
  const az = (Cesium.Math.toDegrees(Math.atan2(local.x, local.y)) + 360) % 360;
  const el = Cesium.Math.toDegrees(Math.atan2(local.z, Math.hypot(local.x, local.y)));
  return { az, el, range };
}

function stationText(s) {
  return `az ${s.az.toFixed(1)}° el ${s.el.toFixed(1)}° ${s.range.toFixed(2)} m`;
}

/** The panel: one row per ray (residuals, outlier flag, where it was taken from, click or
 *  auto, exclude button) and the live solution. */
function render(ctx, busy = false) {
  const m = ctx.state.measure;
  if (!m) return;
  const res = m.solution;
  $("#ray-table tbody").replaceChildren(...m.rays.map((ray, i) => {
    const rr = res && res.rays ? res.rays[i] : null;
    const excluded = m.excluded.has(i);
    const outlier = rr && rr.outlier;
    const noHit = !excluded && hitsNothing(ray);
    return h("tr", { class: excluded ? "excluded" : (outlier || noHit ? "outlier" : "") },
      h("td", noHit ? { title: noHitText(m, i) } : {}, `${i + 1}${outlier ? " ⚑ outlier" : ""}${noHit ? " ⚠ hits no splat (sky?)" : ""}`, ...rayBadge(ray)),
      h("td", { class: "num" }, rr ? fixed(rr.residual_px, 2) : "—"),
      h("td", { class: "num" }, rr ? mm(rr.residual_m) : "—"),
      h("td", { class: "station" }, res && res.point_ecef ? stationText(station(ray, res.point_ecef)) : "—"),
      h("td", { class: "source" }, ray.auto ? "auto" : "click"),
      h("td", {}, h("button", { onclick: () => toggleExclude(ctx, i), title: excluded ? "use this ray again" : "leave this ray out of the solution" }, excluded ? "restore" : "exclude")));
  }));
  const live = $("#live-solution");
  live.classList.remove("error");
  if (m.error) {
    live.textContent = m.error;
    live.classList.add("error");
  } else if (res) {
    live.textContent = solutionText(res);
    if (res.warnings && res.warnings.length) {
      // the project's own warnings (shared by every stored point) are shown once, by the points list
      const own = res.warnings.filter((w) => !(ctx.state.projectWarnings || []).includes(w));
      if (own.length) live.append(h("div", { class: "warn" }, ...own.map((w) => h("div", {}, `⚠ ${w}`))));
    }
  } else {
    live.textContent = busy ? "solving…" : (m.rays.length < 2 ? `Needs at least 2 rays (${m.rays.length} so far).` : "");
  }
  const auto = autoAimPanel(m);
  if (auto) live.append(auto);
  const sky = noHitRays(m);
  if (sky.length) live.append(h("div", { class: "warn" }, ...sky.map((i) => h("div", {}, `⚠ ${noHitText(m, i)}.`))));
  draw(ctx);
}

/** The rays (rendered ECEF), and from two rays on the solution's marker and ellipsoid. */
function draw(ctx) {
  const { state, draw: drawer } = ctx;
  drawer.clear("current");
  const m = state.measure;
  if (!m) return;
  const res = m.solution;
  const mmNow = ctx.modelMatrix();
  const pRendered = res ? applyPoint(mmNow, res.point_ecef) : null;
  // without a solution a ray reaches past the tileset's bounding sphere (50 m without a tileset)
  const reach = (origin) => {
    if (!state.tileset) return 50;
    const bs = state.tileset.boundingSphere;
    return norm(sub([bs.center.x, bs.center.y, bs.center.z], origin)) + bs.radius;
  };
  m.rays.forEach((ray, i) => {
    const rr = res && res.rays ? res.rays[i] : null;
    const color = m.excluded.has(i) ? COLORS.excluded : (rr && rr.outlier ? COLORS.outlier : COLORS.ray);
    const len = pRendered ? norm(sub(pRendered, ray.origin)) * 1.25 : reach(ray.origin);
    drawer.ray("current", ray.origin, ray.direction, len, color, `${i + 1}`);
  });
  if (res) {
    const ell = drawer.ellipsoid("current", res.point_ecef, res.cov_ecef, mmNow, ctx.confScale());
    drawer.ring("current", pRendered, COLORS.solution);
    $("#ellipsoid-note").textContent = ellipsoidNote(state.conf, ell);
  } else {
    $("#ellipsoid-note").textContent = "";
  }
  // the epipolar guide (guide.js) needs each ray's depth; it paints itself with the overlay
  for (const ray of m.rays) requestDepth(ctx, ray);
  refreshGuide(ctx);
}

function end(ctx) {
  closeIdPrompt();
  ctx.state.measure = null;
  $("#measure-panel").hidden = true;
  ctx.draw.clear("current");
  ctx.done();
}

const measure = {
  id: "measure",
  shortcut: "M",
  label: "Measure point",
  title: "Measure a point (M)",
  primary: true,
  hidesSelection: true, // the selected point's rays and ellipsoid would mix with the new ones

  /** Start a new point, or reopen the stored point `editPoint` to add rays to it. */
  start(ctx, editPoint = null) {
    const { state } = ctx;
    state.measure = {
      // a reopened point's rays in the scene's current frame (its georeference may have changed)
      rays: editPoint ? raysInCurrentFrame(editPoint, ctx.modelMatrix()) : [],
      excluded: new Set(editPoint ? editPoint.excluded : []),
      editing: editPoint ? editPoint.id : null,
      pointId: editPoint ? editPoint.id : nextPointId(state.points),
      solution: null, error: null, seq: 0,
    };
    $("#pt-code").value = editPoint ? editPoint.code : "";
    $("#pt-desc").value = editPoint ? editPoint.description : "";
    $("#measure-panel").hidden = false;
    $("#measure-title").textContent = editPoint ? `Adding rays to ${editPoint.id}` : `New point ${state.measure.pointId}`;
    if (editPoint) solveLive(ctx); else render(ctx);
  },

  /** A point in progress is finished or cancelled first: M again does nothing. */
  leave(ctx, next) {
    if (next !== measure) ctx.message("Finish or cancel the point first (Enter / Esc).", true);
    return false;
  },

  /** A click adds a ray through the clicked pixel. */
  click(ctx, event) {
    const ray = captureRay(ctx.viewer, event.position, ctx.modelMatrix());
    if (!ray) { ctx.message("This click gives no ray (is the camera perspective?).", true); return; }
    const m = ctx.state.measure;
    // the scene's georeference version the rays are taken in, stored with the point
    if (!m.rays.length) m.georefVersion = ctx.georefVersion();
    m.rays.push(ray);
    // the canvas around ray 1's pixel: auto-aim's reference (A)
    if (m.rays.length === 1 && !m.editing) rememberReference(ctx, ray);
    // a click on the sky: said at once, and the ray stays flagged in its row and the solution
    requestDepth(ctx, ray).then((d) => {
      if (!d || d.hit !== false || ctx.state.measure !== m || !m.rays.includes(ray)) return;
      ctx.message(noHitText(m, m.rays.indexOf(ray)), true);
      render(ctx);
      ctx.updateStatus();
    });
    solveLive(ctx);
    ctx.updateStatus();
  },

  /** A: auto-aim (autoaim.js) adds the rays it finds in suggested views. */
  key(ctx, event) {
    if (event.key !== "a" && event.key !== "A") return false;
    autoAim(ctx, (raysAdded) => { if (raysAdded) solveLive(ctx); else render(ctx); });
    return true;
  },

  /** Backspace: remove the last ray. */
  undo(ctx) {
    const m = ctx.state.measure;
    if (!m.rays.length) { ctx.message("There is no ray to remove; Esc cancels the point."); return; }
    m.rays.pop();
    m.excluded.delete(m.rays.length);
    solveLive(ctx);
    ctx.updateStatus();
  },

  /** Enter: a new point's id is asked first (the ID prompt), Enter again stores it (POST); a
   *  reopened point is stored at once (PATCH). */
  async finish(ctx) {
    const { state } = ctx;
    const m = state.measure;
    if (!state.project) { ctx.message("Create or open a project first (top bar), then press Enter again.", true); return; }
    if (m.rays.length < 2) { ctx.message(tooFewRays(m.editing || m.pointId, m.rays.length), true); return; }
    if (!m.editing && !idPromptOpen()) { openIdPrompt(ctx); return; }
    const typedId = m.editing ? "" : promptedId();
    if (typedId && state.points.some((p) => p.id === typedId)) {
      idError(`${typedId} is taken by a stored point: type another id (Esc goes back to measuring).`);
      return;
    }
    const code = $("#pt-code").value.trim();
    const description = $("#pt-desc").value.trim();
    const pid = encodeURIComponent(state.project.id);
    const excluded = activeExcluded(m).sort((a, b) => a - b);
    try {
      let pt;
      if (m.editing) {
        const url = `/projects/${pid}/points/${encodeURIComponent(m.editing)}`;
        pt = await api("PATCH", url, { rays: m.rays, excluded, code, description });
      } else {
        pt = await api("POST", `/projects/${pid}/points`, {
          id: typedId || undefined, code, description, rays: m.rays, excluded, georef_version: m.georefVersion ?? ctx.georefVersion(),
        });
      }
      end(ctx);
      await ctx.pointStored(pt, m.editing || pt.id);
      ctx.selectPoint(pt.id, false);
      const r = pt.record || {};
      ctx.message(pt.status === "solved"
        ? `Stored ${pt.id}: ${r.crs ? `E ${fixed(r.easting)} N ${fixed(r.northing)} H ${fixed(r.height)}` : `lon ${fixed(r.lon, 8)} lat ${fixed(r.lat, 8)} h ${fixed(r.h_wgs84)}`}`
        : `Stored ${pt.id}, but it could not be solved: ${pt.error}`, pt.status !== "solved");
    } catch (exc) {
      if (exc.status === 409 && !m.editing) idError(exc.message); else ctx.fail(exc);
    }
  },

  /** Escape (`event` is the key) or the panel's Cancel button: drop the point; Escape in
   *  the ID prompt only closes the prompt (back to measuring). */
  cancel(ctx, event) {
    if (event && idPromptOpen()) { closeIdPrompt(); ctx.updateStatus(); return; }
    end(ctx);
    if (event) ctx.message("Point cancelled.");
  },

  status(ctx) {
    const m = ctx.state.measure;
    const n = m.rays.length;
    const name = m.editing ? `point ${m.editing}` : m.pointId;
    if (idPromptOpen()) return { text: `${n} rays: type the point's ID and press Enter to store it; Esc goes back to measuring.`, className: "measuring" };
    let text;
    if (n === 0) text = `Measuring ${name}: click the feature to add ray 1. Esc cancels.`;
    else if (n === 1) text = `Ray 1 of ${name} added. Move the camera to another viewpoint (30° or more away; V flies to a suggested one) and click the same feature for ray 2. Backspace removes ray 1, Esc cancels.`;
    else text = `${n} rays on ${name}. Click the feature from another viewpoint for ray ${n + 1}, or press Enter to name and store it. Backspace removes ray ${n}, Esc cancels.`;
    const sky = noHitRays(m);
    if (sky.length) text = `${noHitText(m, sky[0])}. ${n} rays on ${name}; Esc cancels.`;
    const auto = autoAimResult(m);
    if (auto && auto.text) text = auto.running ? auto.text : `${auto.text} ${text}`;
    return { text, className: "measuring" };
  },

  redraw: draw,
};

export default measure;
