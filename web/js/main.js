// gsgeo measuring workplace: scene and project, the points list, lines and polygons, check
// points, export. Talks to the gsgeo server's /api. Measuring is done by the tools
// (tools/index.js), to which clicks, keys and the panels' buttons go.

import { api, download, ApiError } from "./api.js";
import { Drawer, COLORS, SCALE_95_3D, cart } from "./draw.js";
import { applyPoint, applyDirection, norm, sub, IDENTITY16 } from "./linalg.js";
import { upsert, usesAny, without } from "./merge.js";
import { $, fixed, mm, h, measuresText, heightsText, sharedWarnings } from "./format.js";
import { TOOLS, activeTool, activate, handlerOf, release, toolByShortcut } from "./tools/index.js";
import { georefPanel } from "./georef.js";
import { buildingsPanel } from "./buildings.js";
import { georefVersion, moveCamera } from "./similarity.js";
import { tileFailureText } from "./scenehost.js";
import { RenderOnDemand, isSoftwareRenderer, msaaSamplesFor, rendererName, splatsShown } from "./render.js";
import { installGuide } from "./guide.js";
import { Still } from "./still.js";
import { nextView } from "./views.js";
import { raysInCurrentFrame } from "./rays.js";
import { installNavigation } from "./navigate.js";
import { installOcclusion } from "./occlusion.js";

const Cesium = window.Cesium;

// ---------------------------------------------------------------------------------------
// state

const state = {
  scenes: [],
  sceneName: null,
  tileset: null,
  projects: [],
  project: null,
  points: [],
  lines: [],
  polygons: [],
  checkPoints: 0,
  checkPointList: [], // the project's check and control points as the server lists them
  projectWarnings: [], // the warnings every stored point shares: shown once, above the list
  selected: null, // point id
  mode: "idle", // the active tool's id (tools/index.js): idle | measure | line | polygon
  measure: null, // the measure tool's point: {rays, excluded:Set, editing, pointId, solution, error, seq}
  feature: null, // the line or polygon tool's draft: {kind, points: []}
  building: null, // the building tool's capture: {faces: [[point ids]], current: [point ids]}
  buildings: [], // the project's LoD2 buildings (buildings.js)
  conf: "95",
};

// ---------------------------------------------------------------------------------------
// viewer

Cesium.Ion.defaultAccessToken = "";
// Nothing comes from Cesium ion, so no ion logo: CesiumJS is credited as text in its place
// (the credits of shown data, e.g. a tileset's glTF copyright, stay as Cesium lists them).
Cesium.CreditDisplay.cesiumCredit = new Cesium.Credit("CesiumJS", true);
const viewer = new Cesium.Viewer("cesium", {
  baseLayer: false,
  baseLayerPicker: false,
  geocoder: false,
  homeButton: false,
  sceneModePicker: false,
  navigationHelpButton: false,
  animation: false,
  timeline: false,
  fullscreenButton: false,
  infoBox: false,
  selectionIndicator: false,
  terrainProvider: new Cesium.EllipsoidTerrainProvider(),
  // the last frame stays readable: still.js copies it to show while auto-aim draws elsewhere
  contextOptions: { webgl: { preserveDrawingBuffer: true } },
});
viewer.scene.globe.baseColor = Cesium.Color.fromCssColorString("#3a4046");
viewer.scene.globe.showGroundAtmosphere = false;
// The globe is one colour on the bare ellipsoid (no imagery, no terrain): a finer tessellation
// draws the same pixels. At Cesium's default (2 px) every tile level it loads asks for a frame:
// 37 frames to open the tests' box scene and 29 after a turn of the camera, against 25 and 16
// at 64 px, the picture identical pixel for pixel (each frame 0.3 s of CPU in a software
// renderer, ~1 s with the demo's splats).
viewer.scene.globe.maximumScreenSpaceError = 64;
viewer.scene.fog.enabled = false;
viewer.cesiumWidget.screenSpaceEventHandler.removeInputAction(Cesium.ScreenSpaceEventType.LEFT_CLICK);
viewer.cesiumWidget.screenSpaceEventHandler.removeInputAction(Cesium.ScreenSpaceEventType.LEFT_DOUBLE_CLICK);
// no multisampling on a software renderer (render.js's msaaSamplesFor; ?msaa= overrides)
const glRenderer = (() => {
  const canvas = viewer.scene.canvas; // its WebGL context is Cesium's: getContext returns it
  return rendererName(canvas.getContext("webgl2") || canvas.getContext("webgl"));
})();
{
  const samples = msaaSamplesFor(new URLSearchParams(location.search).get("msaa"), glRenderer);
  if (samples !== null) viewer.scene.msaaSamples = samples;
}
// the scene is drawn on demand (render.js): what changes the drawing asks for a frame
const renderer = new RenderOnDemand(viewer, () => state.tileset);
// the operator's view kept as a still while auto-aim draws its views (still.js)
const still = new Still(viewer, renderer, () => state.tileset, $("#viewer-wrap"), $("#status"));
still.software = isSoftwareRenderer(glRenderer);
// the measuring graphics: a 2-D overlay, painted without a frame when only they change
const draw = new Drawer(viewer, { requestFrame: () => renderer.request(), fixedView: () => still.shown() });

window.gsgeo = {
  viewer,
  Cesium,
  draw,
  renderer,
  still,
  get tileset() { return state.tileset; },
  get state() { return state; },
  /** the loaded tileset's georeference version (extras.gsgeo.georef.version, 0 when absent) */
  get georefVersion() { return currentGeorefVersion(); },
};

function currentGeorefVersion() {
  return state.tileset ? georefVersion(state.tileset.extras) : 0;
}

function modelMatrix() {
  return state.tileset ? Cesium.Matrix4.toArray(state.tileset.modelMatrix) : IDENTITY16.slice();
}

// ---------------------------------------------------------------------------------------
// messages and status line

function message(text, isError = false) {
  const box = $("#messages");
  const el = h("div", { class: isError ? "error" : "" }, text);
  box.prepend(el);
  while (box.children.length > 4) box.lastChild.remove();
  setTimeout(() => el.remove(), isError ? 15000 : 6000);
}

function fail(exc) {
  message(exc instanceof ApiError || exc instanceof Error ? exc.message : String(exc), true);
}

function updateStatus() {
  const el = $("#status");
  const { text, className } = activeTool(state).status(ctx);
  el.className = className;
  el.textContent = text;
}

// ---------------------------------------------------------------------------------------
// scenes

async function loadScenes() {
  const data = await api("GET", "/scenes");
  state.scenes = data.scenes;
  const sel = $("#scene-select");
  sel.replaceChildren(...(state.scenes.length ? [] : [h("option", { value: "" }, "— no scenes —")]),
    ...state.scenes.map((s) => h("option", { value: s.name }, s.name)));
}

/** Load scene `name`; the camera views the whole scene, or takes `view` ({position,
 *  direction, up}, ECEF) when given (the same feature after a georeference change). */
async function loadScene(name, view = null) {
  if (state.tileset) {
    viewer.scene.primitives.remove(state.tileset);
    state.tileset = null;
  }
  state.sceneName = null;
  const info = state.scenes.find((s) => s.name === name);
  const msg = $("#scene-message");
  if (!info) {
    msg.hidden = false;
    msg.textContent = state.scenes.length ? `There is no scene '${name}'.`
      : "No scenes in the data directory. Make one with gsgeo tiles (see README).";
    updateStatus();
    return;
  }
  if (info.error) {
    msg.hidden = false;
    msg.textContent = `Scene '${name}': ${info.error}`;
    return;
  }
  msg.hidden = true;
  $("#scene-select").value = name;
  loading.scene = name;
  loading.pending = 0;
  showLoading();
  try {
    const tileset = await Cesium.Cesium3DTileset.fromUrl(info.url, { maximumScreenSpaceError: 8 });
    tileset.loadProgress.addEventListener((pending, processing) => {
      loading.pending = pending + processing;
      showLoading();
    });
    let hostFailed = false; // one message per scene load, not one per tile
    tileset.tileFailed.addEventListener((e) => {
      const text = tileFailureText(name, info.tiles_url, e, location.origin);
      if (info.tiles_url) {
        if (hostFailed) return;
        hostFailed = true;
        msg.hidden = false;
        msg.textContent = text;
      }
      message(text, true);
    });
    window.gsgeo.tilesReady = false;
    tileset.initialTilesLoaded.addEventListener(() => { window.gsgeo.tilesReady = true; });
    viewer.scene.primitives.add(tileset);
    state.tileset = tileset;
    state.sceneName = name;
    lastModelMatrix = modelMatrix();
    if (view) {
      const c3 = (v) => new Cesium.Cartesian3(v[0], v[1], v[2]);
      viewer.camera.setView({ destination: c3(view.position),
        orientation: { direction: c3(view.direction), up: c3(view.up) } });
    } else {
      await overview();
    }
  } catch (exc) {
    loading.scene = null;
    msg.hidden = false;
    msg.textContent = `Scene '${name}' cannot be loaded: ${exc.message || exc}`;
  }
  showLoading();
  setUrl();
  redrawAll();
  updateStatus();
  georef.banner();
}

// The loading indicator: from the start of a scene's load until its first splats are drawn,
// and while tiles are pending afterwards.
const loading = { scene: null, pending: 0 };

function showLoading() {
  if (loading.scene && state.tileset && state.sceneName === loading.scene && window.gsgeo.tilesReady
      && splatsShown(state.tileset)) loading.scene = null;
  const el = $("#loading");
  el.hidden = !loading.scene && loading.pending === 0;
  if (el.hidden) return;
  const tiles = loading.pending ? ` (${loading.pending} tile${loading.pending === 1 ? "" : "s"} pending)` : "";
  $("#loading-text").textContent = loading.scene ? `Loading scene '${loading.scene}'…${tiles}` : `Loading tiles…${tiles}`;
}
viewer.scene.postRender.addEventListener(() => { if (loading.scene) showLoading(); });

/** The server changed the scene's root transform by similarity `sim16` (column-major, old
 *  ECEF -> new ECEF) and re-solved the points: reload the tileset, carry the camera by it
 *  (the view stays on the same feature) and fetch the re-solved points. */
async function georeferenceChanged(sim16) {
  const cam = viewer.camera;
  cam.cancelFlight(); // a flight would go on towards its goal in the old frame
  const arr = (c) => [c.x, c.y, c.z];
  const view = moveCamera(sim16, { position: arr(cam.positionWC), direction: arr(cam.directionWC), up: arr(cam.upWC) });
  await loadScenes();
  await loadScene(state.sceneName, view);
  await refreshProjectData();
}

/** The camera at the scene's overview: the whole tileset from the south-west, 34 degrees
 *  down (the view a scene opens with; Home returns to it). */
async function overview() {
  const t = state.tileset;
  if (!t) return;
  viewer.camera.cancelFlight();
  await viewer.zoomTo(t, new Cesium.HeadingPitchRange(0.4, -0.6, t.boundingSphere.radius * 2.2));
}

function sceneCentre() {
  if (!state.tileset) return null;
  const c = state.tileset.boundingSphere.center;
  return [c.x, c.y, c.z];
}

// ---------------------------------------------------------------------------------------
// projects

async function loadProjects() {
  const data = await api("GET", "/projects");
  state.projects = data.projects;
  renderProjectSelect();
}

function renderProjectSelect() {
  const sel = $("#project-select");
  sel.replaceChildren(h("option", { value: "" }, state.projects.length ? "— choose —" : "— none yet —"),
    ...state.projects.map((p) => h("option", { value: p.id }, p.name)));
  sel.value = state.project ? state.project.id : "";
}

function renderProjectInfo() {
  const p = state.project;
  const el = $("#project-info");
  if (!p) { el.textContent = ""; return; }
  const vert = p.vertical ? ` + ${p.vertical}` : (p.geoid ? ` + geoid ${p.geoid}` : ", ellipsoidal heights");
  el.textContent = `${p.crs || "no grid CRS (WGS 84 only)"}${vert} · σpx ${p.sigma_px}`;
  el.title = `source ${p.source_crs}; ${el.textContent}`;
  const unit = p.crs ? "" : " (lon/lat/h)";
  $("#th-e").textContent = p.crs ? "E" : "lon";
  $("#th-n").textContent = p.crs ? "N" : "lat";
  $("#th-h").textContent = "H" + unit.slice(0, 0);
}

async function openProject(pid) {
  if (!pid) {
    state.project = null;
    state.points = []; state.lines = []; state.polygons = [];
    renderAll();
    await buildings.load();
    georef.refresh();
    return;
  }
  state.project = await api("GET", `/projects/${encodeURIComponent(pid)}`);
  renderProjectSelect();
  renderProjectInfo();
  if (state.project.scene && state.project.scene !== state.sceneName
      && state.scenes.some((s) => s.name === state.project.scene)) {
    await loadScene(state.project.scene);
  }
  state.selected = null;
  await refreshProjectData();
  setUrl();
}

async function refreshProjectData() {
  if (!state.project) return;
  const pid = encodeURIComponent(state.project.id);
  const [pts, lines, polys, cps] = await Promise.all([
    api("GET", `/projects/${pid}/points`), api("GET", `/projects/${pid}/lines`),
    api("GET", `/projects/${pid}/polygons`), api("GET", `/projects/${pid}/checkpoints`),
  ]);
  state.points = pts.points;
  state.lines = lines.lines;
  state.polygons = polys.polygons;
  state.checkPoints = cps.check_points.length;
  state.checkPointList = cps.check_points;
  renderAll();
  await buildings.load();
  await refreshAccuracy();
  georef.refresh();
}

// After a store the server's answer goes into the state (merge.js); only what the server
// derives from several objects is fetched again: the measures of the lines and polygons on a
// changed point, and the accuracy against check points.

/** Point `pt` as the server stored it (its id was `oldId` before a rename). */
async function pointStored(pt, oldId = pt.id) {
  state.points = upsert(state.points, pt, oldId);
  const ids = [oldId, pt.id];
  const pid = encodeURIComponent(state.project.id);
  const [lines, polys] = await Promise.all([
    usesAny(state.lines, ids) ? api("GET", `/projects/${pid}/lines`) : null,
    usesAny(state.polygons, ids) ? api("GET", `/projects/${pid}/polygons`) : null,
  ]);
  if (lines) state.lines = lines.lines;
  if (polys) state.polygons = polys.polygons;
  renderAll();
  if (buildings.uses(ids)) await buildings.load();
  await refreshAccuracy();
  georef.refresh();
}

/** Point `id` is deleted (the server refuses while a line or polygon uses it). */
async function pointDeleted(id) {
  state.points = without(state.points, id);
  if (state.selected === id) state.selected = null;
  renderAll();
  await refreshAccuracy();
  georef.refresh();
}

/** Line or polygon `f` as the server stored it, with its measures. */
function featureStored(f) {
  if (f.kind === "line") state.lines = upsert(state.lines, f);
  else state.polygons = upsert(state.polygons, f);
  renderAll();
}

function featureDeleted(kind, id) {
  if (kind === "line") state.lines = without(state.lines, id);
  else state.polygons = without(state.polygons, id);
  renderAll();
}

async function refreshAccuracy() {
  $("#accuracy-section").hidden = !state.checkPoints;
  if (state.checkPoints) await loadAccuracy();
  else $("#accuracy").replaceChildren();
}

function setUrl() {
  const q = new URLSearchParams();
  if (state.sceneName) q.set("scene", state.sceneName);
  if (state.project) q.set("project", state.project.id);
  history.replaceState(null, "", `${location.pathname}?${q}`);
}

// project dialog ---------------------------------------------------------------------------

let dialogMode = "new";
let crsTimer = null;

function openProjectDialog(mode) {
  dialogMode = mode;
  const p = mode === "edit" ? state.project : null;
  if (mode === "edit" && !p) { message("Open a project first.", true); return; }
  $("#project-dialog-title").textContent = p ? `Settings of ${p.name}` : "New project";
  $("#pf-submit").textContent = p ? "Save" : "Create";
  $("#pf-name").value = p ? p.name : "";
  $("#pf-scene").replaceChildren(h("option", { value: "" }, "—"),
    ...state.scenes.map((s) => h("option", { value: s.name }, s.name)));
  $("#pf-scene").value = p ? (p.scene || "") : (state.sceneName || "");
  $("#pf-crs").textContent = p && p.crs ? p.crs : "none (WGS 84 positions only)";
  $("#pf-crs").dataset.code = p && p.crs ? p.crs : "";
  $("#pf-crs-q").value = "";
  $("#pf-crs-results").replaceChildren();
  $("#pf-vertical").value = p && p.vertical ? p.vertical : "";
  $("#pf-vertical-results").replaceChildren();
  $("#pf-geoid").value = p && p.geoid ? p.geoid : "";
  $("#pf-source").value = p ? p.source_crs : "EPSG:4978";
  $("#pf-sigma").value = p ? p.sigma_px : 1.0;
  $("#pf-error").textContent = "";
  $("#project-dialog").hidden = false;
  $("#pf-name").focus();
}

async function searchCrs() {
  const q = $("#pf-crs-q").value.trim();
  const list = $("#pf-crs-results");
  if (!q) { list.replaceChildren(); return; }
  try {
    const data = await api("GET", `/crs?q=${encodeURIComponent(q)}&limit=30`);
    if ($("#pf-crs-q").value.trim() !== q) return;
    list.replaceChildren(...(data.results.length ? data.results.map((r) => h("li", {
      "data-code": r.code, title: r.area || "",
      onclick: () => {
        $("#pf-crs").textContent = `${r.code} — ${r.name}`;
        $("#pf-crs").dataset.code = r.code;
        list.querySelectorAll("li").forEach((li) => li.classList.toggle("selected", li.dataset.code === r.code));
      },
    }, `${r.code} — ${r.name}${r.kind === "compound" ? " (compound)" : ""}`))
      : [h("li", {}, `nothing matches '${q}'`)]));
  } catch (exc) {
    list.replaceChildren(h("li", { class: "error" }, exc.message));
  }
}

let verticalTimer = null;

async function searchVertical() {
  const input = $("#pf-vertical");
  const q = input.value.trim();
  const list = $("#pf-vertical-results");
  if (!q || /^[A-Za-z]+:\d+$/.test(q)) { list.replaceChildren(); return; }
  try {
    const data = await api("GET", `/crs?q=${encodeURIComponent(q)}&kind=vertical&limit=20`);
    if (input.value.trim() !== q) return;
    list.replaceChildren(...data.results.map((r) => h("li", {
      "data-code": r.code, title: r.area || "",
      onclick: () => { input.value = r.code; list.replaceChildren(); },
    }, `${r.code} — ${r.name}`)));
  } catch (exc) {
    list.replaceChildren(h("li", { class: "error" }, exc.message));
  }
}

async function submitProject(ev) {
  ev.preventDefault();
  let crs = $("#pf-crs").dataset.code || null;
  const typed = $("#pf-crs-q").value.trim();
  if (!crs && /^[A-Za-z]+:\d+$/.test(typed)) crs = typed.toUpperCase();
  const body = {
    name: $("#pf-name").value.trim(),
    scene: $("#pf-scene").value || null,
    crs,
    vertical: $("#pf-vertical").value.trim() || null,
    geoid: $("#pf-geoid").value.trim() || null,
    source_crs: $("#pf-source").value.trim() || "EPSG:4978",
    sigma_px: Number($("#pf-sigma").value),
  };
  try {
    let p;
    if (dialogMode === "edit") {
      p = await api("PATCH", `/projects/${encodeURIComponent(state.project.id)}`, body);
    } else {
      p = await api("POST", "/projects", body);
    }
    // the new project's settings are on show as the dialog closes, not a request later
    state.project = p;
    renderProjectInfo();
    $("#project-dialog").hidden = true;
    await loadProjects();
    await openProject(p.id);
    message(dialogMode === "edit" ? `Saved the settings of ${p.name}; points were re-solved.` : `Created project ${p.name}.`);
  } catch (exc) {
    $("#pf-error").textContent = exc.message;
  }
}

// ---------------------------------------------------------------------------------------
// tools

function solveSettings() {
  const p = state.project;
  return p ? { crs: p.crs, vertical: p.vertical, geoid: p.geoid, source_crs: p.source_crs, sigma_px: p.sigma_px }
    : { crs: null, vertical: null, geoid: null, source_crs: "EPSG:4978", sigma_px: 1.0 };
}

function confScale() { return state.conf === "95" ? SCALE_95_3D : 1; }

/** What the tools (tools/*.js) may use of the workplace. pointStored(pt, oldId) and
 *  featureStored(f) take the server's answer to a store; done() returns to the default tool. */
const ctx = {
  state, viewer, draw, still, message, fail, modelMatrix, solveSettings, confScale,
  pointById, nearestPoint, selectPoint, updateStatus, pointStored, featureStored,
  buildingStored: (b) => buildings.stored(b),
  georefVersion: currentGeorefVersion,
  done: () => release(ctx),
  // the active tool changed: whether the selected point's rays show depends on it
  modeChanged: () => drawSelected(),
};

const georef = georefPanel({ state, message, fail, sceneCentre, georeferenceChanged, viewKnown, knownText,
  localScene });

/** A scene still in its trainer's frame sits at lat 0, lon 0 with the Earth's surface cutting
 *  through it where its z is 0: the globe hid what lay below, and from a camera under that
 *  surface a black wedge showed where the globe is not drawn. The globe is shown only under a
 *  georeferenced scene. */
function localScene(local) {
  if (viewer.scene.globe.show === !local) return;
  viewer.scene.globe.show = !local;
  viewer.scene.requestRender();
}
const buildings = buildingsPanel({ state, draw, modelMatrix, message, fail });
installGuide(ctx, draw.overlay);
const navigation = installNavigation(ctx, { overview });
installOcclusion(ctx, draw.overlay);

// ---------------------------------------------------------------------------------------
// points

function pointById(id) { return state.points.find((p) => p.id === id); }

function renderPoints() {
  const tbody = $("#points-table tbody");
  $("#points-count").textContent = state.points.length ? `(${state.points.length})` : "";
  state.projectWarnings = sharedWarnings(state.points);
  const shared = $("#project-warnings");
  shared.hidden = !state.projectWarnings.length;
  shared.replaceChildren(...state.projectWarnings.map((w) => h("div", { title: "every point of this project has this warning" }, `⚠ every point: ${w}`)));
  const rows = state.points.map((p) => {
    const r = p.record || {};
    const grid = r.easting !== null && r.easting !== undefined;
    const warns = ownWarnings(p);
    const flag = p.status !== "solved" ? "✖" : (warns.length ? "⚠" : "");
    return h("tr", {
      "data-id": p.id, class: p.id === state.selected ? "selected" : "",
      title: p.status !== "solved" ? p.error : warns.join("\n"),
      onclick: () => onPointRowClick(p.id),
    },
    h("td", {}, p.id),
    h("td", {}, p.code || ""),
    h("td", { class: "num" }, grid ? fixed(r.easting) : fixed(r.lon, 7)),
    h("td", { class: "num" }, grid ? fixed(r.northing) : fixed(r.lat, 7)),
    h("td", { class: "num" }, grid ? fixed(r.height) : fixed(r.h_wgs84)),
    h("td", { class: "num" }, grid ? `${mm(r.sigma_e)}/${mm(r.sigma_n)}/${mm(r.sigma_h)}` : "—"),
    h("td", { class: "num" }, fixed(r.sigma0, 2)),
    h("td", { class: "num" }, `${r.n_rays ?? p.rays.length}${p.excluded.length ? `+${p.excluded.length}✕` : ""}`),
    h("td", { class: flag === "✖" ? "error" : "warn" }, flag));
  });
  tbody.replaceChildren(...(rows.length ? rows : [h("tr", {}, h("td", { colspan: 9, class: "muted" }, "No points yet: press M to measure one."))]));
}

/** A point's warnings but those every point shares (shown once, above the list). */
function ownWarnings(p) {
  return ((p.result && p.result.warnings) || []).filter((w) => !state.projectWarnings.includes(w));
}

function onPointRowClick(id) {
  handlerOf(state, "pick").pick(ctx, id);
}

function selectPoint(id, fly) {
  state.selected = id;
  renderPoints();
  renderPointDetail();
  drawSelected();
  const p = pointById(id);
  if (fly && p && p.result) {
    const pos = cart(applyPoint(modelMatrix(), p.result.point_ecef));
    viewer.camera.flyToBoundingSphere(new Cesium.BoundingSphere(pos, 1.5), {
      offset: new Cesium.HeadingPitchRange(viewer.camera.heading, -0.5, 8), duration: 0.8,
    });
  }
}

// Undo and redo (Ctrl+Z, Ctrl+Shift+Z or Ctrl+Y) of what the operator changed, each step
// through the API so that the store and its audit trail say what happened: {label, undo, redo}
// of async functions, for the open project.
const undoSteps = { done: [], undone: [], project: null };

function remember(step) {
  if (undoSteps.project !== (state.project && state.project.id)) {
    undoSteps.done = []; undoSteps.undone = [];
    undoSteps.project = state.project && state.project.id;
  }
  undoSteps.done.push(step);
  undoSteps.undone = [];
}

let undoChain = Promise.resolve();

/** Undo (or redo) the last step; presses made meanwhile wait their turn. */
function undoRedo(redo) {
  undoChain = undoChain.then(() => undoRedoNow(redo));
  return undoChain;
}

async function undoRedoNow(redo) {
  if (undoSteps.project !== (state.project && state.project.id)) return;
  const from = redo ? undoSteps.undone : undoSteps.done;
  const step = from.pop();
  if (!step) { message(redo ? "Nothing to redo." : "Nothing to undo."); return; }
  try {
    await (redo ? step.redo() : step.undo());
    (redo ? undoSteps.done : undoSteps.undone).push(step);
    message(`${redo ? "Redone" : "Undone"}: ${step.label}.`);
  } catch (exc) { fail(exc); }
}

/** Delete point `id` (one click; Ctrl+Z brings it back with its rays, id, code and
 *  description, measured again in the scene's current frame). */
async function deletePoint(id) {
  const pt = pointById(id);
  try {
    // remembered as soon as the server has deleted it, before the lists are redrawn
    await removePoint(id, () => {
      if (pt) remember({ label: `delete ${id}`, undo: () => restorePoint(pt), redo: () => removePoint(id) });
    });
    message(`Deleted ${id}. Ctrl+Z brings it back.`);
  } catch (exc) { fail(exc); }
}

async function removePoint(id, answered = () => {}) {
  await api("DELETE", `/projects/${encodeURIComponent(state.project.id)}/points/${encodeURIComponent(id)}`);
  answered();
  await pointDeleted(id);
}

/** Store point `pt` (as the server gave it before its deletion) again. */
async function restorePoint(pt) {
  const stored = await api("POST", `/projects/${encodeURIComponent(state.project.id)}/points`, {
    id: pt.id, code: pt.code || "", description: pt.description || "",
    rays: raysInCurrentFrame(pt, modelMatrix()), excluded: pt.excluded || [],
    georef_version: currentGeorefVersion(),
  });
  await pointStored(stored);
}

function renderPointDetail() {
  const box = $("#point-detail");
  const p = state.selected ? pointById(state.selected) : null;
  if (!p) { box.hidden = true; box.replaceChildren(); return; }
  box.hidden = false;
  const r = p.record || {};
  const res = p.result || {};
  const kv = [];
  const row = (k, v) => kv.push(h("div", {}, k), h("div", { class: "mono" }, v));
  row("Point", `${p.id}${p.code ? ` · ${p.code}` : ""}`);
  if (p.description) row("Description", p.description);
  if (p.status !== "solved") row("Error", p.error || "not solved");
  if (r.crs) {
    row("E / N / H", `${fixed(r.easting)} / ${fixed(r.northing)} / ${fixed(r.height)} m`);
    row("CRS", r.crs);
    row("Heights", heightsText(r.height_type, r.vertical_datum));
    row("σ E/N/H (1σ)", `${mm(r.sigma_e)} / ${mm(r.sigma_n)} / ${mm(r.sigma_h)} mm`);
    row("95 % ellipse", `${mm(r.ellipse_major_95)} × ${mm(r.ellipse_minor_95)} mm, bearing ${fixed(r.ellipse_bearing_deg, 1)}°`);
  }
  if (r.lon !== undefined && r.lon !== null) row("WGS 84", `${fixed(r.lon, 8)}, ${fixed(r.lat, 8)}, h ${fixed(r.h_wgs84)} m`);
  row("σ0", fixed(r.sigma0, 2));
  row("Rays", `${r.n_rays ?? "—"} used${p.excluded.length ? `, ${p.excluded.length} excluded` : ""}; max angle ${fixed(r.max_angle_deg, 1)}°`);
  row("RMS / max res.", `${mm(r.rms_m)} mm / ${fixed(r.max_residual_px, 2)} px`);
  if (r.operation) row("Operation", `${r.operation}${r.operation_accuracy_m !== null && r.operation_accuracy_m !== undefined ? ` (±${r.operation_accuracy_m} m)` : ""}`);
  const warns = ownWarnings(p);
  const rays = (res.rays || []).map((rr) => h("tr", { class: rr.excluded ? "excluded" : (rr.outlier ? "outlier" : "") },
    h("td", {}, `${rr.index + 1}${rr.outlier ? " ⚑" : ""}`),
    h("td", { class: "num" }, fixed(rr.residual_px, 2)),
    h("td", { class: "num" }, mm(rr.residual_m)),
    h("td", {}, h("button", {
      onclick: () => changePoint(p.id, rr.excluded ? { restore_ray: rr.index } : { exclude_ray: rr.index },
        rr.excluded ? { exclude_ray: rr.index } : { restore_ray: rr.index },
        `${rr.excluded ? "restore" : "exclude"} ray ${rr.index + 1} of ${p.id}`),
    }, rr.excluded ? "restore" : "exclude"))));
  const delBtn = h("button", { class: "danger", title: "delete (Ctrl+Z undoes)", onclick: () => deletePoint(p.id) }, "Delete");
  box.replaceChildren(
    h("div", { class: "kv" }, ...kv),
    renameRow(p.id),
    editRow(p),
    warns.length ? h("div", { class: "warn" }, ...warns.map((w) => h("div", {}, `⚠ ${w}`))) : "",
    rays.length ? h("table", { class: "grid" }, h("thead", {}, h("tr", {}, h("th", {}, "Ray"), h("th", {}, "res px"), h("th", {}, "res mm"), h("th", {}, ""))), h("tbody", {}, ...rays)) : "",
    h("div", { class: "buttons" },
      h("button", { onclick: () => selectPoint(p.id, true) }, "Fly to"),
      h("button", { onclick: () => activate(ctx, "measure", p), title: "reopen: add rays to this point" }, "Add rays"),
      h("button", { id: "btn-rename", onclick: () => openRename(), title: "give the point another id" }, "Rename"),
      h("button", { id: "btn-edit", onclick: () => { $("#edit-row").hidden = false; $("#edit-code").focus(); }, title: "change the code and description" }, "Edit"),
      delBtn));
}

/** The rename field of the point panel (hidden until Rename): Enter renames, Esc closes. */
function renameRow(id) {
  const input = h("input", { id: "rename-input", maxlength: "100", value: id, autocomplete: "off", spellcheck: "false" });
  const error = h("span", { id: "rename-error", class: "error" });
  input.addEventListener("keydown", (ev) => {
    if (ev.key === "Enter") { ev.preventDefault(); renamePoint(id, input.value.trim(), error); }
    else if (ev.key === "Escape") { ev.preventDefault(); ev.stopPropagation(); $("#rename-row").hidden = true; }
  });
  return h("div", { id: "rename-row", class: "rename", hidden: true },
    h("label", {}, "New ID ", input),
    h("button", { onclick: () => renamePoint(id, input.value.trim(), error) }, "Rename"), error);
}

/** The code and description of point `p`, editable (Enter or Save stores; Ctrl+Z undoes). */
function editRow(p) {
  const code = h("input", { id: "edit-code", maxlength: "200", value: p.code || "", autocomplete: "off" });
  const desc = h("input", { id: "edit-description", maxlength: "2000", value: p.description || "", autocomplete: "off" });
  const save = () => {
    const next = { code: code.value.trim(), description: desc.value.trim() };
    code.blur(); desc.blur(); // the keys go back to the viewer (Ctrl+Z)
    $("#edit-row").hidden = true;
    if (next.code === (p.code || "") && next.description === (p.description || "")) return;
    changePoint(p.id, next, { code: p.code || "", description: p.description || "" }, `edit ${p.id}`);
  };
  for (const el of [code, desc]) {
    el.addEventListener("keydown", (ev) => {
      if (ev.key === "Enter") { ev.preventDefault(); save(); }
      else if (ev.key === "Escape") { ev.preventDefault(); ev.stopPropagation(); $("#edit-row").hidden = true; }
    });
  }
  return h("div", { id: "edit-row", class: "rename", hidden: true },
    h("label", {}, "Code ", code), h("label", {}, " Description ", desc),
    h("button", { onclick: save }, "Save"));
}

/** PATCH point `id` with `body` and remember the step: `back` undoes it (a PATCH too). */
async function changePoint(id, body, back, label) {
  try {
    await patchStored(id, body, (pt) => {
      remember({ label, undo: () => patchStored(pt.id, back), redo: () => patchStored(id, body) });
    });
  } catch (exc) { fail(exc); }
}

/** PATCH point `id` and put the server's answer into the state (the selection follows a
 *  rename); `answered(pt)` is called with the stored point as soon as the server answers
 *  (before the lists are redrawn). The stored point. */
async function patchStored(id, body, answered = () => {}) {
  const pt = await api("PATCH", `/projects/${encodeURIComponent(state.project.id)}/points/${encodeURIComponent(id)}`, body);
  answered(pt);
  if (state.selected === id) state.selected = pt.id;
  await pointStored(pt, id);
  return pt;
}

function openRename() {
  $("#rename-row").hidden = false;
  $("#rename-error").textContent = "";
  $("#rename-input").focus();
  $("#rename-input").select();
}

/** PATCH the point's id (with If-Match, as every change); a taken id is said in the panel. */
async function renamePoint(oldId, id, errorEl) {
  if (!id || id === oldId) { $("#rename-row").hidden = true; return; }
  if (pointById(id)) { errorEl.textContent = `${id} is taken by another point: choose another id.`; return; }
  try {
    const pt = await patchStored(oldId, { id }, (answer) => remember({
      label: `rename ${oldId} to ${answer.id}`, undo: () => patchStored(answer.id, { id: oldId }),
      redo: () => patchStored(oldId, { id: answer.id }) }));
    message(`Renamed ${oldId} to ${pt.id}.`);
  } catch (exc) {
    errorEl.textContent = exc.status === 409 ? `${id} is taken: ${exc.message}` : exc.message;
  }
}

function drawPoints() {
  draw.clear("points");
  const mmNow = modelMatrix();
  for (const p of state.points) {
    if (!p.result || !p.result.point_ecef) continue;
    draw.marker("points", p.id, applyPoint(mmNow, p.result.point_ecef),
      p.id === state.selected ? COLORS.selected : COLORS.point);
  }
}

function drawSelected() {
  draw.clear("selected");
  drawPoints();
  const p = state.selected ? pointById(state.selected) : null;
  if (!p || !p.result || activeTool(state).hidesSelection) return;
  const res = p.result;
  const mmNow = modelMatrix();
  const pr = applyPoint(mmNow, res.point_ecef);
  for (const rr of res.rays || []) {
    const o = applyPoint(mmNow, rr.origin_ecef);
    const d = applyDirection(mmNow, rr.direction_ecef);
    const dn = norm(d);
    const color = rr.excluded ? COLORS.excluded : (rr.outlier ? COLORS.outlier : COLORS.ray.withAlpha(0.8));
    draw.ray("selected", o, d.map((x) => x / dn), norm(sub(pr, o)) * 1.1, color, null);
  }
  draw.ellipsoid("selected", res.point_ecef, res.cov_ecef, mmNow, confScale(), COLORS.selected);
}

// ---------------------------------------------------------------------------------------
// lines and polygons

async function deleteFeature(kind, id) {
  const plural = kind === "line" ? "lines" : "polygons";
  try {
    await api("DELETE", `/projects/${encodeURIComponent(state.project.id)}/${plural}/${encodeURIComponent(id)}`);
    featureDeleted(kind, id);
  } catch (exc) { fail(exc); }
}

function renderFeatures() {
  const rows = [...state.lines.map((f) => ["line", f]), ...state.polygons.map((f) => ["polygon", f])]
    .map(([kind, f]) => h("tr", {},
      h("td", {}, `${f.id}`, h("span", { class: "muted" }, kind === "line" ? " line" : " polygon")),
      h("td", {}, f.points.join(kind === "line" ? "→" : ",")),
      h("td", { style: "white-space: normal" }, measuresText(f.measures)),
      h("td", {}, h("button", { onclick: () => deleteFeature(kind, f.id), title: `delete ${f.id}` }, "✕"))));
  $("#features-table tbody").replaceChildren(...(rows.length ? rows
    : [h("tr", {}, h("td", { colspan: 4, class: "muted" }, "None yet: L or P, then click measured points."))]));
}

function drawFeatures() {
  draw.clear("features");
  const mmNow = modelMatrix();
  const posOf = (id) => {
    const p = pointById(id);
    return p && p.result ? applyPoint(mmNow, p.result.point_ecef) : null;
  };
  for (const f of state.lines) draw.path("features", f.points.map(posOf).filter(Boolean), COLORS.line, false);
  for (const f of state.polygons) draw.path("features", f.points.map(posOf).filter(Boolean), COLORS.polygon, true);
}

// ---------------------------------------------------------------------------------------
// check points and accuracy

async function importCheckPoints(ev) {
  ev.preventDefault();
  if (!state.project) { message("Open a project first.", true); return; }
  const file = $("#check-file").files[0];
  if (!file) { message("Choose a CSV, GeoJSON or GeoPackage file of check points.", true); return; }
  const form = new FormData();
  form.append("file", file, file.name);
  const crs = $("#check-crs").value.trim() || (file.name.toLowerCase().endsWith(".csv") ? state.project.crs : "");
  if (crs) form.append("crs", crs);
  form.append("replace", $("#check-replace").checked ? "true" : "false");
  const role = $("#check-role").value;
  form.append("role", role);
  try {
    const r = await api("POST", `/projects/${encodeURIComponent(state.project.id)}/checkpoints/import`, form);
    message(`Imported ${r.imported} ${role === "control" ? "control" : "check"} points (${r.crs}).`);
    georef.refresh();
    // an import adds or replaces check points by id: the server counts them
    const cps = await api("GET", `/projects/${encodeURIComponent(state.project.id)}/checkpoints`);
    state.checkPoints = cps.check_points.length;
    state.checkPointList = cps.check_points;
    drawKnown();
    await refreshAccuracy();
  } catch (exc) { fail(exc); }
}

async function loadAccuracy() {
  const box = $("#accuracy");
  if (!state.project.crs) {
    box.replaceChildren(h("p", { class: "note" }, `${state.checkPoints} check points; set a grid CRS to compare.`));
    return;
  }
  try {
    const acc = await api("GET", `/projects/${encodeURIComponent(state.project.id)}/accuracy`);
    const s = acc.statistics;
    const rows = acc.points.map((d) => h("tr", {},
      h("td", {}, d.id), h("td", { class: "num" }, mm(d.dE)), h("td", { class: "num" }, mm(d.dN)),
      h("td", { class: "num" }, mm(d.dH)), h("td", { class: "num" }, mm(d.d3D))));
    const c = acc.counts;
    const unmeasured = c.check_points_not_measured.length
      ? h("div", { class: "known-list", id: "accuracy-unmeasured" }, "Not measured (look at): ",
        ...knownButtons(c.check_points_not_measured)) : "";
    if (!c.matched) {
      box.replaceChildren(h("p", { class: "note", id: "accuracy-summary" },
        `${c.check_points} check points; none measured yet. Give a measured point `
        + "the ID of a check point (asked at Enter while measuring) to compare it."), unmeasured);
      return;
    }
    // H is the height here as everywhere in the viewer: the API's RMSE_H (horizontal) is shown
    // as EN, its V (vertical) as H
    box.replaceChildren(
      h("div", { class: "table-wrap short" }, h("table", { class: "grid", id: "accuracy-table" },
        h("thead", {}, h("tr", {}, h("th", {}, "Point"), h("th", {}, "dE mm"), h("th", {}, "dN mm"), h("th", {}, "dH mm"), h("th", {}, "d3D mm"))),
        h("tbody", {}, ...rows))),
      h("div", { class: "solution", id: "accuracy-summary" },
        `RMSE E ${mm(s.RMSE_E)}  N ${mm(s.RMSE_N)}  EN ${mm(s.RMSE_H)}  H ${mm(s.RMSE_V)}  3D ${mm(s.RMSE_3D)} mm\n`
        + `ME   E ${mm(s.ME_E)}  N ${mm(s.ME_N)}  H ${mm(s.ME_V)} mm;  SD E ${mm(s.SD_E)}  N ${mm(s.SD_N)}  H ${mm(s.SD_V)} mm\n`
        + `${c.matched} of ${c.check_points} check points measured`), unmeasured,
      h("p", { class: "note", id: "accuracy-note" }, `Millimetres; differences are measured minus check; EN is the `
        + `horizontal (2-D) RMSE. Heights: ${acc.heights}.`));
  } catch (exc) {
    box.replaceChildren(h("p", { class: "error" }, exc.message));
  }
}

// ---------------------------------------------------------------------------------------
// export

async function exportAs(fmt) {
  if (!state.project) { message("Open a project first.", true); return; }
  try {
    const name = await download(`/projects/${encodeURIComponent(state.project.id)}/export?format=${fmt}`,
      `${state.project.id}.${fmt}`);
    message(`Downloaded ${name}.`);
  } catch (exc) { fail(exc); }
}

// ---------------------------------------------------------------------------------------
// rendering all, modelMatrix watch

function renderAll() {
  renderProjectSelect();
  renderProjectInfo();
  if (state.selected && !pointById(state.selected)) state.selected = null;
  renderPoints();
  renderPointDetail();
  renderFeatures();
  redrawAll();
  updateStatus();
}

/** The project's check and control points not measured yet (no point has their id), drawn
 *  where the server put them in ECEF (GET .../checkpoints: the frame of a georeferenced scene's
 *  tiles, the measured points' frame), under the tileset's model matrix as the points are. */
function drawKnown() {
  draw.clear("known");
  const measured = new Set(state.points.map((p) => p.id));
  const mmNow = modelMatrix();
  for (const c of state.checkPointList || []) {
    if (c.ecef && !measured.has(c.id)) draw.known("known", c.id, applyPoint(mmNow, c.ecef), c.role);
  }
}

/** Look at known point `id` (a check or control point) from 45 degrees above, at the
 *  camera's heading, from a range of 12 m (less in a smaller scene). */
function viewKnown(id) {
  const c = (state.checkPointList || []).find((k) => k.id === id);
  if (!c || !c.ecef) { message(`${id} has no position to look at (no height, or its CRS has no transformation here).`, true); return; }
  const t = state.tileset;
  const range = Math.min(12, Math.max(2, t ? t.boundingSphere.radius : 12));
  const cam = viewer.camera;
  cam.cancelFlight();
  cam.lookAt(new Cesium.Cartesian3(...applyPoint(modelMatrix(), c.ecef)), new Cesium.HeadingPitchRange(cam.heading, Cesium.Math.toRadians(-45), range));
  cam.lookAtTransform(Cesium.Matrix4.IDENTITY);
  message(`Looking at ${c.role === "control" ? "control" : "check"} point ${id}.`);
}

/** The known point's coordinates as given, in its CRS's axis order, and its description:
 *  "545012.345, 258012.345, 12.345 (EPSG:27700) · PK nail in kerb" (up to 9 decimals:
 *  degrees keep theirs). */
function knownText(c) {
  const f = (v) => (v === null || v === undefined ? "—" : String(Number(Number(v).toFixed(9))));
  return `${f(c.x)}, ${f(c.y)}, ${f(c.z)} (${c.crs})${c.description ? ` · ${c.description}` : ""}`;
}

/** Buttons for known points `ids`: each flies to a view of its point. */
function knownButtons(ids) {
  return ids.map((id) => {
    const c = (state.checkPointList || []).find((k) => k.id === id);
    return h("button", { class: "known", "data-id": id, title: c ? `${knownText(c)}: look at it` : id,
      disabled: !(c && c.ecef), onclick: () => viewKnown(id) }, id);
  });
}

function redrawAll() {
  drawKnown();
  drawSelected();
  drawFeatures();
  buildings.redraw();
  const tool = activeTool(state);
  if (tool.redraw) tool.redraw(ctx);
}

let lastModelMatrix = IDENTITY16.slice();
viewer.scene.postRender.addEventListener(() => {
  if (!state.tileset) return;
  const now = modelMatrix();
  if (now.some((v, i) => v !== lastModelMatrix[i])) {
    lastModelMatrix = now;
    redrawAll();
  }
});

// ---------------------------------------------------------------------------------------
// input

/** The stored point whose marker is nearest to a window position (CSS px), within `tol` px. */
function nearestPoint(windowPosition, tol) {
  const mmNow = modelMatrix();
  let best = null;
  let bestD = tol;
  for (const p of state.points) {
    if (!p.result || !p.result.point_ecef) continue;
    const pos = applyPoint(mmNow, p.result.point_ecef);
    const cam = viewer.camera.positionWC;
    const dir = viewer.camera.directionWC;
    if ((pos[0] - cam.x) * dir.x + (pos[1] - cam.y) * dir.y + (pos[2] - cam.z) * dir.z <= 0) continue;
    const win = Cesium.SceneTransforms.worldToWindowCoordinates(viewer.scene, cart(pos));
    if (!win) continue;
    const d = Math.hypot(win.x - windowPosition.x, win.y - windowPosition.y);
    if (d <= bestD) { bestD = d; best = p.id; }
  }
  return best;
}

const clicks = new Cesium.ScreenSpaceEventHandler(viewer.scene.canvas);
clicks.setInputAction((ev) => {
  handlerOf(state, "click").click(ctx, ev);
}, Cesium.ScreenSpaceEventType.LEFT_CLICK);

function toggleHelp(show) {
  const el = $("#help");
  el.hidden = show === undefined ? !el.hidden : !show;
}

document.addEventListener("keydown", (ev) => {
  const t = ev.target;
  const typing = t && (t.tagName === "INPUT" || t.tagName === "TEXTAREA" || t.tagName === "SELECT");
  if ((ev.ctrlKey || ev.metaKey) && !ev.altKey && !typing && (ev.key === "z" || ev.key === "Z" || ev.key === "y")) {
    undoRedo(ev.key === "y" || ev.shiftKey);
    ev.preventDefault();
    return;
  }
  if (ev.ctrlKey || ev.altKey || ev.metaKey) return;
  if (!$("#help").hidden) {
    if (ev.key === "Escape" || ev.key === "?") { toggleHelp(false); ev.preventDefault(); }
    return;
  }
  if (!$("#project-dialog").hidden) {
    if (ev.key === "Escape") { $("#project-dialog").hidden = true; ev.preventDefault(); }
    return;
  }
  if (georef.confirming) {
    if (ev.key === "Escape") { georef.closeConfirm(); ev.preventDefault(); }
    return;
  }
  // Enter and Escape typed in a tool's panel (its code, description, ...) go to the tool
  const inPanel = typing && t.closest("[data-tool-panel]");
  if (typing && !(inPanel && (ev.key === "Enter" || ev.key === "Escape"))) return;
  const key = ev.key;
  const tool = activeTool(state);
  if (tool.key && tool.key(ctx, ev)) { ev.preventDefault(); return; }
  const action = { Enter: "finish", Escape: "cancel", Backspace: "undo" }[key];
  if (action && tool[action]) { tool[action](ctx, ev); ev.preventDefault(); return; }
  const shortcut = toolByShortcut(key);
  if (shortcut) { activate(ctx, shortcut.id); ev.preventDefault(); }
  else if (key === "e" || key === "E") { setConf(state.conf === "95" ? "1" : "95"); ev.preventDefault(); }
  else if (key === "g" || key === "G") { georef.toggle(); ev.preventDefault(); }
  else if (key === "v" || key === "V") { nextView(ctx); ev.preventDefault(); }
  else if (key === "Home") { navigation.home(); ev.preventDefault(); }
  else if (key.startsWith("Arrow")) { navigation.keyMove(key.slice(5).toLowerCase(), ev.shiftKey); ev.preventDefault(); }
  else if (key === "+" || key === "=" || key === "-") {
    const c = viewer.scene.canvas;
    navigation.zoom([c.clientWidth / 2, c.clientHeight / 2], key === "-" ? -1 : 1);
    ev.preventDefault();
  }
  else if (key === "?") { toggleHelp(true); ev.preventDefault(); }
  else if (key === "h" || key === "H") { setAidsHidden(true); ev.preventDefault(); }
  else if (key === "Escape" && state.selected) { selectPoint(null, false); }
});

/** While H is held the scene is shown alone: every aid drawn over it is hidden (style.css). */
function setAidsHidden(hidden) {
  $("#viewer-wrap").classList.toggle("aids-hidden", hidden);
}
document.addEventListener("keyup", (ev) => { if (ev.key === "h" || ev.key === "H") setAidsHidden(false); });
window.addEventListener("blur", () => setAidsHidden(false));

function setConf(value) {
  state.conf = value;
  document.querySelectorAll("input[name=conf]").forEach((r) => { r.checked = r.value === value; });
  redrawAll();
}

/** A toolbar button (id btn-<tool id>) for every tool with a label, in the registry's order. */
function toolButtons() {
  const bar = $("#tools");
  for (const tool of TOOLS) {
    if (!tool.label) continue;
    const button = h("button", { id: `btn-${tool.id}`, class: tool.primary ? "primary" : "", title: tool.title },
      `${tool.label} `, tool.shortcut ? h("kbd", {}, tool.shortcut) : "");
    button.addEventListener("click", () => { activate(ctx, tool.id); button.blur(); });
    bar.insertBefore(button, bar.querySelector(".conf"));
  }
}

function wire() {
  toolButtons();
  for (const tool of TOOLS) if (tool.setup) tool.setup(ctx);
  // the panels' Finish / Undo / Cancel buttons act on the active tool
  document.querySelectorAll("[data-tool-action]").forEach((b) => b.addEventListener("click", () => {
    const tool = activeTool(state);
    const action = b.dataset.toolAction;
    if (tool[action]) tool[action](ctx);
  }));
  $("#btn-help").addEventListener("click", () => toggleHelp(true));
  $("#btn-help-close").addEventListener("click", () => toggleHelp(false));
  $("#help").addEventListener("click", (ev) => { if (ev.target.id === "help") toggleHelp(false); });
  $("#btn-new-project").addEventListener("click", () => openProjectDialog("new"));
  $("#btn-settings").addEventListener("click", () => openProjectDialog("edit"));
  $("#pf-cancel").addEventListener("click", () => { $("#project-dialog").hidden = true; });
  $("#project-form").addEventListener("submit", submitProject);
  $("#pf-crs-q").addEventListener("input", () => { clearTimeout(crsTimer); crsTimer = setTimeout(searchCrs, 250); });
  $("#pf-crs-q").addEventListener("keydown", (ev) => { if (ev.key === "Enter") { ev.preventDefault(); searchCrs(); } });
  $("#pf-vertical").addEventListener("input", () => { clearTimeout(verticalTimer); verticalTimer = setTimeout(searchVertical, 250); });
  $("#scene-select").addEventListener("change", (ev) => loadScene(ev.target.value).catch(fail));
  $("#project-select").addEventListener("change", (ev) => openProject(ev.target.value).catch(fail));
  document.querySelectorAll("input[name=conf]").forEach((r) => r.addEventListener("change", () => setConf(r.value)));
  document.querySelectorAll("[data-export]").forEach((b) => b.addEventListener("click", () => exportAs(b.dataset.export)));
  $("#check-form").addEventListener("submit", importCheckPoints);
  // (blurred: the keys go back to the tools)
  $("#ellipsoid-true").addEventListener("change", (ev) => { draw.trueSize = ev.target.checked; ev.target.blur(); redrawAll(); });
  // an exaggerated ellipsoid is sized for the camera's range: drawn again when the camera has
  // moved (a redraw asks for a frame: only when there is an ellipsoid and a new pose)
  let pose = "";
  viewer.camera.moveEnd.addEventListener(() => {
    const c = viewer.camera;
    const now = [c.positionWC, c.directionWC].map((v) => `${v.x.toFixed(2)},${v.y.toFixed(2)},${v.z.toFixed(2)}`).join(";");
    if (draw.trueSize || !draw.ellipsoids.size || now === pose) return;
    pose = now;
    redrawEllipsoids();
  });
}

function redrawEllipsoids() {
  drawSelected();
  const tool = activeTool(state);
  if (tool.redraw) tool.redraw(ctx);
}

/** ?lon=&lat= (WGS 84 degrees, as the QGIS plugin sends): look down at that place, at the
 *  height of the scene's centre (the ground is not known before the tiles load). */
function lookAtPlace(params) {
  if (!params.has("lon") && !params.has("lat")) return;
  const lon = Number(params.get("lon")), lat = Number(params.get("lat"));
  if (!params.get("lon") || !params.get("lat") || !Number.isFinite(lon) || !Number.isFinite(lat)
      || Math.abs(lat) > 90 || Math.abs(lon) > 180) {
    message(`lon=${params.get("lon")}&lat=${params.get("lat")} is not a place (degrees, both needed).`, true);
    return;
  }
  const h = state.tileset ? Cesium.Cartographic.fromCartesian(state.tileset.boundingSphere.center).height : 0;
  viewer.camera.flyToBoundingSphere(new Cesium.BoundingSphere(Cesium.Cartesian3.fromDegrees(lon, lat, h), 5), {
    offset: new Cesium.HeadingPitchRange(0, -0.7, 40), duration: 0,
  });
}

// ---------------------------------------------------------------------------------------
// start

async function start() {
  wire();
  updateStatus();
  const params = new URLSearchParams(location.search);
  try {
    await Promise.all([loadScenes(), loadProjects()]);
  } catch (exc) {
    fail(exc);
    $("#status").textContent = `The gsgeo API does not answer: ${exc.message}`;
    return;
  }
  const pid = params.get("project");
  const project = pid ? state.projects.find((p) => p.id === pid) : null;
  const sceneName = params.get("scene") || (project && project.scene) || (state.scenes[0] && state.scenes[0].name);
  if (sceneName) await loadScene(sceneName);
  else await loadScene(null);
  if (project) await openProject(project.id);
  else if (pid) message(`There is no project '${pid}'.`, true);
  lookAtPlace(params);
  renderAll();
  window.gsgeo.ready = true;
}

start().catch(fail);
