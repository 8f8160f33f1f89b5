"""The web client's pure JavaScript (web/js/linalg.js, web/js/rays.js) run in Node.js and
checked against numpy: the eigen-decomposition that orients and sizes the error ellipsoid,
covariance propagation through a model matrix, and the angular size of a pixel; and the
measuring tools' registry (web/js/tools/): every tool keeps the interface, switching follows
the workplace's rules."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

from tests.conftest import REPO

WEB_JS = REPO / "web" / "js"
pytestmark = pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed")


def run_js(body: str, data) -> object:
    """Run an ES module snippet with `data` bound; it must print one JSON value."""
    src = (f"import * as L from '{(WEB_JS / 'linalg.js').as_uri()}';\n"
           f"import * as R from '{(WEB_JS / 'rays.js').as_uri()}';\n"
           f"const data = {json.dumps(data)};\n{body}\n")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, check=True, timeout=60)
    return json.loads(out.stdout)


def test_eigsym3_matches_numpy(rng):
    mats = []
    for _ in range(50):
        a = rng.normal(size=(3, 3)) * rng.uniform(1e-4, 1e-1)
        mats.append((a @ a.T).tolist())
    mats.append(np.diag([4e-6, 9e-6, 1e-6]).tolist())          # already diagonal
    mats.append((np.eye(3) * 2.5e-5).tolist())                   # isotropic
    res = run_js("console.log(JSON.stringify(data.map((m) => L.eigSym3(m))));", mats)
    for m, r in zip(mats, res, strict=True):
        m = np.array(m)
        w = np.sort(np.linalg.eigvalsh(m))[::-1]
        assert np.allclose(r["values"], w, rtol=1e-9, atol=1e-18)
        v = np.array(r["vectors"])  # rows are the unit eigenvectors
        assert np.allclose(v @ v.T, np.eye(3), atol=1e-9)
        assert np.linalg.det(v) == pytest.approx(1.0, abs=1e-9)  # right-handed: a rotation
        assert np.allclose(v @ m @ v.T, np.diag(r["values"]), atol=1e-12 * np.abs(m).max() + 1e-20)


def test_covariance_through_model_matrix(rng):
    a = rng.normal(size=(3, 3))
    cov = a @ a.T * 1e-5
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    m = np.eye(4)
    m[:3, :3] = 1.7 * q
    m[:3, 3] = [10.0, -5.0, 3.0]
    col_major = m.T.reshape(-1).tolist()
    got = run_js("console.log(JSON.stringify([L.transformCovariance(data[0], data[1]), "
                 "L.applyPoint(data[0], [1, 2, 3])]));", [col_major, cov.tolist()])
    assert np.allclose(got[0], m[:3, :3] @ cov @ m[:3, :3].T, rtol=1e-12)
    assert np.allclose(got[1], m[:3, :3] @ [1, 2, 3] + m[:3, 3])


def _solid_angle(a, b, c) -> float:
    """Solid angle of the spherical triangle of unit vectors a, b, c (Van Oosterom-Strackee)."""
    num = abs(np.dot(a, np.cross(b, c)))
    den = 1 + np.dot(a, b) + np.dot(b, c) + np.dot(c, a)
    return 2 * np.arctan2(num, den)


def test_pixel_angle_is_sqrt_of_pixel_solid_angle():
    """ifov recorded with each ray: the square root of the solid angle of the clicked pixel of
    a pinhole camera, computed here from the pixel's four corner rays."""
    fovy, w, h = np.radians(60.0), 1000, 700
    f = h / (2 * np.tan(fovy / 2))
    pixels = [(500, 350), (0.5, 0.5), (999.5, 10.2), (123.4, 654.3), (700, 350)]
    got = run_js("console.log(JSON.stringify(data.px.map(([x, y]) => "
                 "R.pixelAngle(data.fovy, data.w, data.h, x, y))));",
                 {"px": pixels, "fovy": fovy, "w": w, "h": h})

    def ray(x, y):
        d = np.array([x - w / 2, -(y - h / 2), -f])
        return d / np.linalg.norm(d)

    for (x, y), g in zip(pixels, got, strict=True):
        c = [ray(x - 0.5, y - 0.5), ray(x + 0.5, y - 0.5), ray(x + 0.5, y + 0.5), ray(x - 0.5, y + 0.5)]
        omega = _solid_angle(c[0], c[1], c[2]) + _solid_angle(c[0], c[2], c[3])
        assert g == pytest.approx(np.sqrt(omega), rel=1e-5)
    assert got[0] == pytest.approx(2 * np.tan(fovy / 2) / h, rel=1e-12)


#: Browser globals the client's modules touch when they are imported or a tool starts:
#: a Cesium stub (colours only), an empty location and session storage, and a document whose
#: elements (one per selector) record hidden, textContent, value and classes.
BROWSER_STUB = """
const el = () => ({ hidden: true, textContent: "", value: "", dataset: {}, disabled: false,
  classes: new Set(), addEventListener() {}, blur() {},
  get classList() { const c = this.classes; return { add: (x) => c.add(x), remove: (x) => c.delete(x),
    toggle: (x, on) => (on ? c.add(x) : c.delete(x)), contains: (x) => c.has(x) }; } });
const elements = new Map();
const byKey = (k) => { if (!elements.has(k)) elements.set(k, el()); return elements.get(k); };
const color = (css) => ({ css, toCssColorString: () => css, withAlpha() { return this; } });
globalThis.Cesium = { Color: { fromCssColorString: color, TRANSPARENT: color("transparent") } };
globalThis.window = globalThis;
globalThis.location = { hash: "", pathname: "/", search: "", port: "", protocol: "http:" };
globalThis.sessionStorage = { getItem: () => null, setItem() {} };
globalThis.document = { querySelector: (s) => byKey(s), getElementById: (id) => byKey("#" + id),
  cookie: "" };
"""


def run_tools_js(body: str) -> object:
    """Run `body` with the tool registry imported as T (web/js/tools/index.js) and a fake
    workplace context `ctx` whose messages are collected in `messages`."""
    src = (BROWSER_STUB
           + f"const T = await import('{(WEB_JS / 'tools' / 'index.js').as_uri()}');\n"
           + """const messages = [];
const state = { mode: "idle", project: null, points: [], measure: null, feature: null };
const ctx = { state, message: (text) => messages.push(text), updateStatus() {},
  draw: { clear() {}, path() {} }, modelMatrix: () => null, pointById: () => null,
  done: () => T.release(ctx) };
""" + body)
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_every_tool_implements_the_interface():
    """docs/architecture.md, "Web client": a tool is an object with a unique id and shortcut
    (not a key the workplace itself uses: E, H, ?), status(ctx), and, unless it is the
    default tool, start and cancel; the optional members are functions."""
    got = run_tools_js("""
const optional = ["setup", "click", "pick", "key", "undo", "finish", "leave", "redraw"];
console.log(JSON.stringify(T.TOOLS.map((t) => ({
  id: t.id, shortcut: t.shortcut ?? null, status: typeof t.status, start: typeof t.start,
  cancel: typeof t.cancel, badOptional: optional.filter((k) => k in t && typeof t[k] !== "function"),
  byShortcut: t.shortcut ? T.toolByShortcut(t.shortcut.toLowerCase()).id : null,
}))));""")
    assert [t["id"] for t in got][:1] == ["idle"]
    assert {t["id"]: t["shortcut"] for t in got}.items() >= {"measure": "M", "line": "L",
                                                              "polygon": "P"}.items()
    ids = [t["id"] for t in got]
    shortcuts = [t["shortcut"] for t in got if t["shortcut"]]
    assert len(set(ids)) == len(ids) and len(set(shortcuts)) == len(shortcuts)
    for t in got:
        assert t["status"] == "function" and t["badOptional"] == [], t
        if t["id"] != "idle":
            assert t["start"] == "function" and t["cancel"] == "function", t
        if t["shortcut"]:
            assert len(t["shortcut"]) == 1 and t["shortcut"].upper() not in "EH?", t
            assert t["byShortcut"] == t["id"]


def test_tool_switching_rules():
    """Line and polygon need a project; a point being measured must be finished or
    cancelled before another tool starts (M again does nothing); starting a tool cancels
    a line or polygon in progress, and only the active tool's button is marked."""
    got = run_tools_js("""
const r = {};
r.noProject = [T.activate(ctx, "line"), state.mode, messages.splice(0)];
state.project = { id: "p" };
r.line = [T.activate(ctx, "line"), state.mode, state.feature && state.feature.kind,
          document.getElementById("btn-line").classList.contains("active")];
r.polygon = [T.activate(ctx, "polygon"), state.mode, state.feature.kind,
             document.getElementById("btn-line").classList.contains("active"),
             document.getElementById("btn-polygon").classList.contains("active")];
T.activeTool(state).cancel(ctx);
r.cancelled = [state.mode, state.feature,
               document.getElementById("btn-polygon").classList.contains("active")];
state.mode = "measure";
r.whileMeasuring = [T.activate(ctx, "polygon"), state.mode, messages.splice(0),
                    T.activate(ctx, "measure"), messages.splice(0)];
console.log(JSON.stringify(r));""")
    assert got["noProject"] == [False, "idle", ["Open a project first."]]
    assert got["line"] == [True, "line", "line", True]
    assert got["polygon"] == [True, "polygon", "polygon", False, True]
    assert got["cancelled"] == ["idle", None, False]
    assert got["whileMeasuring"] == [False, "measure", ["Finish or cancel the point first (Enter / Esc)."],
                                     False, []]


def test_stored_objects_merge_into_the_lists_in_server_order():
    """web/js/merge.js: a stored object replaces its entry in place (also under a new id after
    a rename), a new one goes last as the server lists it, a deleted one leaves; a changed
    point's lines and polygons are found for re-fetching their measures."""
    src = (f"import * as M from '{(WEB_JS / 'merge.js').as_uri()}';\n" + """
const list = [{ id: "P1", v: 1 }, { id: "P2", v: 1 }, { id: "P3", v: 1 }];
const feats = [{ id: "L1", points: ["P1", "P2"] }, { id: "L2", points: ["P3", "P4"] }];
console.log(JSON.stringify({
  replaced: M.upsert(list, { id: "P2", v: 2 }),
  added: M.upsert(list, { id: "P9", v: 2 }),
  renamed: M.upsert(list, { id: "Q2", v: 2 }, "P2"),
  removed: M.without(list, "P1"),
  missing: M.without(list, "X"),
  same: list,
  uses: [M.usesAny(feats, ["P2"]), M.usesAny(feats, ["P5", "P4"]), M.usesAny(feats, ["P5"])],
}));""")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, check=True, timeout=60)
    got = json.loads(out.stdout)
    ids = {k: [(x["id"], x["v"]) for x in v] for k, v in got.items() if k != "uses"}
    assert ids["replaced"] == [("P1", 1), ("P2", 2), ("P3", 1)]
    assert ids["added"] == [("P1", 1), ("P2", 1), ("P3", 1), ("P9", 2)]
    assert ids["renamed"] == [("P1", 1), ("Q2", 2), ("P3", 1)]
    assert ids["removed"] == [("P2", 1), ("P3", 1)]
    assert ids["missing"] == ids["same"] == [("P1", 1), ("P2", 1), ("P3", 1)]  # never mutated
    assert got["uses"] == [True, True, False]


def run_module_js(module: str, body: str, data) -> object:
    """Run `body` with web/js/`module` imported as S and `data` bound; it prints one JSON value."""
    src = (f"import * as S from '{(WEB_JS / module).as_uri()}';\n"
           f"const data = {json.dumps(data)};\n{body}\n")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, check=True, timeout=60)
    return json.loads(out.stdout)


def _similarity(s: float, axis, deg: float, t) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    th = np.radians(deg)
    m = np.eye(4)
    m[:3, :3] = s * (np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * k @ k)
    m[:3, 3] = t
    return m


def test_similarity_parameters_and_camera_match_numpy():
    """web/js/similarity.js: a georeference similarity (column-major) as scale, ppm, angle
    and axis; the camera carried by it (position S p, direction and up turned) keeps the
    angle between any two viewing directions and puts S x where x was on the screen."""
    m = _similarity(0.37, [0.3, -0.5, 0.8], 25.0, [3.9e6, -8.3e3, 4.97e6])
    cam = {"position": [6378150.0, 4.5, 7.8], "direction": [-0.6, -0.4, -0.69],
           "up": [0.8, -0.3, -0.5]}
    got = run_module_js("similarity.js", """
const m = data.m;
console.log(JSON.stringify({d: S.decompose(m), cam: S.moveCamera(m, data.cam),
  x: S.applySimilarity(m, [1, 2, 3]), id: S.decompose([1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1])}));""",
                        {"m": m.T.reshape(-1).tolist(), "cam": cam})
    d = got["d"]
    assert d["scale"] == pytest.approx(0.37, rel=1e-12)
    assert d["ppm"] == pytest.approx(-630000.0, rel=1e-9)
    assert d["angleDeg"] == pytest.approx(25.0, rel=1e-9)
    assert np.allclose(d["axis"], np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8]))
    assert np.allclose(d["translation"], m[:3, 3])
    assert got["id"]["scale"] == 1 and got["id"]["angleDeg"] == 0 and got["id"]["ppm"] == 0
    q = m[:3, :3] / 0.37
    assert np.allclose(got["x"], m[:3, :3] @ [1, 2, 3] + m[:3, 3])
    assert np.allclose(got["cam"]["position"], m[:3, :3] @ cam["position"] + m[:3, 3], atol=1e-6)
    assert np.allclose(got["cam"]["direction"], q @ cam["direction"])
    assert np.allclose(got["cam"]["up"], q @ cam["up"])
    # a point x seen along p -> x is seen along the moved direction from the moved camera
    x = np.array(cam["position"]) + 7.0 * np.array(cam["direction"])
    seen = (m[:3, :3] @ x + m[:3, 3]) - np.array(got["cam"]["position"])
    assert np.allclose(seen / np.linalg.norm(seen),
                       np.array(got["cam"]["direction"]) / np.linalg.norm(cam["direction"]))


def test_georeference_state_of_scenes_and_tilesets():
    """The banner shows on a scene that was never fitted or sits at lat 0, lon 0; the version
    sent with every stored point is the tileset's extras.gsgeo.georef.version, 0 without it."""
    got = run_module_js("similarity.js", """
console.log(JSON.stringify({
  banner: data.scenes.map((s) => S.notGeoreferenced(s)),
  version: [S.georefVersion(undefined), S.georefVersion({}), S.georefVersion({gsgeo: {}}),
            S.georefVersion({gsgeo: {georef: {version: 3}}}),
            S.georefVersion({gsgeo: {georef: {version: -1}}})],
}));""", {"scenes": [
        {"georeferenced": False, "origin": {"lat": 51.5, "lon": -0.1}},
        {"georeferenced": None, "origin": {"lat": 0.0, "lon": 0.0}},
        {"georeferenced": True, "origin": {"lat": 51.5, "lon": -0.1}},
        {"georeferenced": None, "origin": None}, None]})
    assert got["banner"] == [True, True, False, False, False]
    assert got["version"] == [0, 0, 0, 3, 0]


def test_apply_confirmation_says_what_changes():
    """The Apply confirmation names the scale in ppm, the rotation angle, how far the scene's
    centre moves, accepted outliers and the points of every project on the scene re-solved."""
    m = _similarity(1.0002, [0, 0, 1], 0.5, [1.0, 2.0, 2.0])
    centre = [10.0, 0.0, 0.0]
    got = run_module_js("similarity.js", "console.log(JSON.stringify(S.applySummary(data.fit, "
                        "data.centre, data.projects)));",
                        {"fit": {"matrix": m.T.reshape(-1).tolist(), "scale_sigma": 3e-6,
                                 "translation": m[:3, 3].tolist(), "outliers": ["GCP4"]},
                         "centre": centre,
                         "projects": [{"name": "a", "points": 12}, {"name": "b", "points": 3}]})
    text = "\n".join(got)
    assert "Scale: × 1.000200 (+200 ppm ± 3.0 ppm)" in text, text
    assert "Rotation: 0.5000° about the axis (0.000, 0.000, 1.000)" in text, text
    shift = np.linalg.norm(m[:3, :3] @ centre + m[:3, 3] - centre)
    assert f"the scene's centre moves {shift:.3f} m" in text, text
    assert "Outliers kept in the fit (you accept them): GCP4" in text
    assert "Re-solved: 15 points in 2 projects on this scene (a: 12, b: 3)" in text


def test_a_fit_that_changes_nothing_is_recognised():
    """After an Apply the fit in the new frame is the identity up to rounding: recognised (Apply
    is off); 0.01 ppm of scale, 1e-5 degrees of rotation or a 1 mm shift of the centre are not."""
    centre = [3.9e6, -8.3e3, 4.97e6]
    eye = np.eye(4)
    cases = [eye, _similarity(1 + 1e-12, [0, 0, 1], 1e-9, [1e-6, 0, 0]),
             _similarity(1 + 1e-8, [0, 0, 1], 0.0, [0, 0, 0]),
             _similarity(1.0, [1, 0, 0], 1e-5, [0, 0, 0]),
             _similarity(1.0, [1, 0, 0], 0.0, [0.001, 0, 0])]
    got = run_module_js("similarity.js", "console.log(JSON.stringify(data.ms.map((m) => "
                        "S.changesNothing(m, data.c))));",
                        {"ms": [m.T.reshape(-1).tolist() for m in cases], "c": centre})
    assert got == [True, True, False, False, False]


def test_no_tool_takes_the_georeference_key():
    """G opens the Georeference panel (main.js): no tool may have it as its shortcut."""
    got = run_tools_js("console.log(JSON.stringify(T.TOOLS.map((t) => t.shortcut || '')));")
    assert "G" not in [s.upper() for s in got]


def test_reopened_point_rays_come_into_the_current_frame():
    """web/js/rays.js raysInCurrentFrame: a point's stored rays that the server's solution
    carries elsewhere (the scene's georeference changed since they were taken) are rebuilt from
    the carried rays, rendered by the current model matrix; rays already in the current frame,
    and a point without a solution, keep the stored rays as they are."""
    sim = _similarity(0.37, [0.2, 0.1, 1.0], 30.0, [100.0, -50.0, 20.0])
    mm_then = np.eye(4)
    mm_then[:3, 3] = [0.0, 0.0, 10.0]  # the tileset lifted 10 m when the rays were taken
    mm_now = np.eye(4)
    mm_now[:3, 3] = [5.0, 0.0, 0.0]
    geo = [np.array([6378100.0, 10.0, 20.0]), np.array([6378090.0, -15.0, 25.0])]
    dirs = [np.array([-0.8, 0.1, -0.2]), np.array([-0.7, 0.3, -0.1])]
    stored = [{"origin": (mm_then[:3, :3] @ g + mm_then[:3, 3]).tolist(),
               "direction": (d / np.linalg.norm(d)).tolist(), "ifov": 1e-3, "pixel": [1, 2],
               "model_matrix": mm_then.T.reshape(-1).tolist()} for g, d in zip(geo, dirs, strict=True)]
    col = lambda m: m.T.reshape(-1).tolist()  # noqa: E731

    def carried(m: np.ndarray) -> list[dict]:
        return [{"index": i, "origin_ecef": (m[:3, :3] @ g + m[:3, 3]).tolist(),
                 "direction_ecef": (m[:3, :3] @ (d / np.linalg.norm(d))).tolist()}
                for i, (g, d) in enumerate(zip(geo, dirs, strict=True))]

    got = run_module_js("rays.js", """
console.log(JSON.stringify(data.cases.map((c) => S.raysInCurrentFrame(c.pt, c.mm))));""",
                        {"cases": [{"pt": {"rays": stored, "result": r}, "mm": col(mm_now)} for r in (
                            {"rays": carried(sim)}, {"rays": carried(np.eye(4))}, None)]})
    moved, same, unsolved = got
    for r, g, d in zip(moved, geo, dirs, strict=True):
        assert np.allclose(r["origin"], mm_now[:3, :3] @ (sim[:3, :3] @ g + sim[:3, 3]) + mm_now[:3, 3],
                           rtol=0, atol=1e-6)
        q = sim[:3, :3] @ d
        assert np.allclose(r["direction"], q / np.linalg.norm(q))
        assert r["model_matrix"] == col(mm_now) and r["ifov"] == 1e-3 and r["pixel"] == [1, 2]
    assert same == stored and unsolved == stored


def test_building_capture_state_machine():
    """web/js/tools/building.js (B): picked corners go into the face being clicked (a repeated
    or unsolved point is refused by name), Enter closes a face of 3 or more corners (fewer: a
    message, nothing changes), a click on the face's first corner closes it too, Backspace
    removes the last corner and on an empty face reopens the previous one; Enter on an empty
    face without a ground is refused, with one POSTs {id, roofs, ground} (the next free id
    B<n>, the ground a height or a point id) and returns to the default tool; the server's
    refusal is shown and keeps the faces; Esc cancels."""
    got = run_tools_js("""
const solved = new Set(["E1", "E2", "E3", "E4", "R1", "R2"]);
ctx.pointById = (id) => (solved.has(id) ? { id, result: { point_ecef: [1, 2, 3] } }
  : (id === "U" ? { id, result: null } : null));
ctx.modelMatrix = () => [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1];
const stored = [];
ctx.buildingStored = (b) => stored.push(b.id);
ctx.fail = (e) => messages.push(`fail: ${e.message}`);
const sent = [];
globalThis.fetch = async (url, init) => {
  sent.push({ url, method: init.method, body: JSON.parse(init.body) });
  const made = { id: "B2", measures: { roof_type: "gable", volume: 437.5 } };
  return { ok: true, status: 201, json: async () => made };
};
state.project = { id: "p" };
state.buildings = [{ id: "B1" }, { id: "X" }];
const B = () => JSON.parse(JSON.stringify(state.building));
const r = {};
r.start = [T.activate(ctx, "building"), state.mode, B(), document.getElementById("bld-id").value];
const tool = T.activeTool(state);
for (const id of ["E1", "E2", "R2", "R1", "E2", "U"]) tool.pick(ctx, id);
r.picked = [B(), messages.splice(0)];
await tool.finish(ctx);
r.closed = B();
tool.pick(ctx, "E3"); tool.pick(ctx, "E4");
await tool.finish(ctx);
r.short = [B(), messages.splice(0)];
tool.undo(ctx); tool.undo(ctx);
r.undone = B();
tool.undo(ctx);
r.reopened = B();
tool.pick(ctx, "E1");
r.closedByFirst = B();
for (const id of ["E3", "E4", "R1", "R2"]) tool.pick(ctx, id);
await tool.finish(ctx);
r.twoFaces = B();
await tool.finish(ctx);
r.noGround = [sent.length, state.mode, messages.splice(0)];
document.querySelector("#bld-ground").value = " 10,25 ";
const ok = globalThis.fetch;
globalThis.fetch = async () => ({ ok: false, status: 422, statusText: "Unprocessable Entity",
  json: async () => ({ message: "roof face 2 is not planar: B5 is 0.300 m off", field: "roofs" }) });
await tool.finish(ctx);
r.refused = [state.mode, B(), messages.splice(0)];
globalThis.fetch = ok;
await tool.finish(ctx);
r.stored = [sent, state.mode, state.building, stored, messages.splice(0)];
T.activate(ctx, "building");
T.activeTool(state).pick(ctx, "E1");
T.activeTool(state).cancel(ctx, { key: "Escape" });
r.cancelled = [state.mode, state.building, messages.splice(0)];
console.log(JSON.stringify(r));""")
    assert got["start"] == [True, "building", {"faces": [], "current": []}, "B2"]
    face1 = ["E1", "E2", "R2", "R1"]
    assert got["picked"] == [{"faces": [], "current": face1},
                             ["E2 is already a corner of this face.", "U has no solved position."]]
    assert got["closed"] == {"faces": [face1], "current": []}
    assert got["short"] == [{"faces": [face1], "current": ["E3", "E4"]},
                            ["A roof face needs at least 3 corners (2 so far)."]]
    assert got["undone"] == {"faces": [face1], "current": []}
    assert got["reopened"] == {"faces": [], "current": face1}
    assert got["closedByFirst"] == {"faces": [face1], "current": []}
    face2 = ["E3", "E4", "R1", "R2"]
    assert got["twoFaces"] == {"faces": [face1, face2], "current": []}
    assert got["noGround"][:2] == [0, "building"]
    assert "Give the ground" in got["noGround"][2][0]
    # the server's refusal is shown; the faces stay for the operator to fix
    assert got["refused"] == ["building", {"faces": [face1, face2], "current": []},
                              ["fail: roof face 2 is not planar: B5 is 0.300 m off"]]
    sent, mode, building, stored, msgs = got["stored"]
    assert sent == [{"url": "/api/projects/p/buildings", "method": "POST",
                     "body": {"id": "B2", "roofs": [face1, face2], "ground": 10.25}}]
    assert (mode, building, stored) == ("idle", None, ["B2"])
    assert msgs == ["Stored building B2 (gable roof), volume 437.5 m³."]
    assert got["cancelled"] == ["idle", None, ["Building cancelled."]]


def test_building_ground_field():
    """The ground field: a number (comma or point as the decimal sign) is a height, other text
    the id of a measured ground point, an empty field nothing."""
    texts = ["12.5", " -3 ", "12,5", "1e2", "G7", "12a", "", "   ", ".5"]
    got = run_tools_js(f"""
const S = await import('{(WEB_JS / "tools" / "building.js").as_uri()}');
console.log(JSON.stringify({json.dumps(texts)}.map((t) => S.parseGround(t))));""")
    assert got == [12.5, -3, 12.5, 100, "G7", "12a", None, None, 0.5]
