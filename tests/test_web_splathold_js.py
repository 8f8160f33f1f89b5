"""Auto-aim's partial splat draw (web/js/render.js's holdSplats) in Node.js, on a mock of the
CesiumJS 1.145 splat primitive's state it reads: the splats it draws for a window box are
those whose 3-sigma footprint can reach the box, in back-to-front order for the camera, and
the primitive is given back to Cesium as it was.

Expectations are computed here with numpy from the pinhole model (f = H / (2 tan(fovy / 2)),
x right, y down, the camera looking along its view frame's -z), independently of render.js.
"""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

from tests.conftest import REPO

RENDER_JS = REPO / "web" / "js" / "render.js"
pytestmark = pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed")

# a Cesium-like Matrix4 (column-major, 16 numbers) and Cartesian3 helpers, enough for render.js
MOCK = """
const mul = (a, b, out) => { const r = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) for (let row = 0; row < 4; row++) { let s = 0;
    for (let k = 0; k < 4; k++) s += a[k * 4 + row] * b[c * 4 + k]; r[c * 4 + row] = s; }
  for (let i = 0; i < 16; i++) out[i] = r[i]; return out; };
function Matrix4() { return new Array(16).fill(0); }
Matrix4.multiply = mul;
Matrix4.ZERO = new Array(16).fill(0);
Matrix4.clone = (a, out) => { for (let i = 0; i < 16; i++) out[i] = a[i]; return out; };
const Cartesian3 = {
  distance: (a, b) => Math.hypot(a.x - b.x, a.y - b.y, a.z - b.z),
  angleBetween: (a, b) => Math.acos(Math.max(-1, Math.min(1, (a.x * b.x + a.y * b.y + a.z * b.z)
    / (Math.hypot(a.x, a.y, a.z) * Math.hypot(b.x, b.y, b.z))))),
};
globalThis.window = { Cesium: { Matrix4, Cartesian3 } };
"""


def look_at(eye, target, up) -> np.ndarray:
    """4x4 view matrix (world -> view, the camera looking along view -z)."""
    f = target - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = r, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def cesium(m: np.ndarray) -> list[float]:
    """A 4x4 matrix as Cesium's Matrix4 holds it (column-major)."""
    return [float(v) for v in m.T.ravel()]


def run(data: dict) -> dict:
    body = """
const R = await import(data.module);
const n = data.n;
let written = null;
const own = () => "own update";
const p = {
  _positions: Float32Array.from(data.positions), _scales: Float32Array.from(data.scales),
  _numSplats: n, _rootTransform: data.root, _indexes: Uint32Array.from(data.indexes),
  _drawCommand: { instanceCount: n }, _vertexArrayLen: n, _prevViewMatrix: new Array(16).fill(1),
  _vertexArray: { getAttribute: (i) => ({ vertexBuffer: {
    copyFromArrayView: (a) => { written = { i, a: Array.from(a) }; } } }) },
  _sorterState: 0, _hasLastSteadySortCameraPosition: true, _hasLastSteadySortCameraDirection: true,
  _lastSteadySortCameraPosition: data.sortedAt, _lastSteadySortCameraDirection: { x: 0, y: 0, z: -1 },
  _lastSteadySortFrameNumber: 7,
};
const root = { hasRenderableContent: true, children: [] };
p._selectedTileSet = new Set([root]);
const t = { show: true, tilesLoaded: true, root, gaussianSplatPrimitive: p };
const camera = { viewMatrix: data.view, frustum: { fovy: data.fovy },
  positionWC: { x: 0, y: 0, z: 0 }, directionWC: { x: 0, y: 0, z: -1 } };
const hold = R.holdSplats(t);
const held = R.splatsHeld(t) && R.holdSplats(t) === hold;  // nested: the same hold
hold.release(camera);                                        // the nested one's release
const count = hold.arm(camera, data.box, data.width, data.height);
const drawn = written;
const commands = [];
p.update({ passes: { render: true }, frameNumber: 5, commandList: commands });
const pushed = commands.length === 1 && commands[0].instanceCount === count && hold.drawnFrame === 5;
hold.disarm();
const none = []; p.update({ passes: { render: true }, frameNumber: 6, commandList: none });
hold.release(camera);
const back = { own: Object.prototype.hasOwnProperty.call(p, "update"), written: written.a.length,
  count: p._drawCommand.instanceCount, frame: p._lastSteadySortFrameNumber, held: R.splatsHeld(t) };
console.log(JSON.stringify({ held, count, drawn, pushed, afterDisarm: none.length, back }));
"""
    src = f"{MOCK}\nconst data = {json.dumps(data)};\n{body}\n"
    out = subprocess.run(["node", "--input-type=module"], input=src, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


@pytest.mark.parametrize("sorted_here", [True, False])
def test_the_splats_reaching_a_box_are_drawn_back_to_front_and_given_back(sorted_here):
    rng = np.random.default_rng(7)
    n = 3000
    pos = rng.uniform([-6, -6, -1], [6, 6, 3], (n, 3))
    scales = np.exp(rng.uniform(np.log(0.002), np.log(0.3), (n, 3)))
    pos[:5] = [[0, 0, 19.5], [0, 0, 25], [0.2, 0.1, 19.9], [3, 3, 20.5], [-2, 1, 19.0]]  # near/behind
    # root frame -> world: a turn about z and a shift; the camera 20 m up looking down
    a = 0.4
    root = np.eye(4)
    root[:3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    root[:3, 3] = [10, -5, 2]
    eye = root @ [0.5, 0.5, 22, 1]
    view = look_at(eye[:3], (root @ [0, 0, 0, 1])[:3], np.array([0.0, 1.0, 0.0]))
    width, height, fovy = 790, 683, 0.9259
    box = [300, 250, 120, 90]
    sorted_at = {"x": 0, "y": 0, "z": 0} if sorted_here else {"x": 5, "y": 0, "z": 0}
    data = {"module": RENDER_JS.as_uri(), "n": n, "positions": pos.ravel().tolist(),
            "scales": scales.ravel().tolist(), "root": cesium(root), "view": cesium(view),
            "indexes": list(range(n - 1, -1, -1)), "fovy": fovy, "width": width,
            "height": height, "box": box, "sortedAt": sorted_at}
    got = run(data)

    # the expectation: view coordinates, pinhole, 3-sigma reach + 2 px
    v = (view @ root @ np.c_[pos, np.ones(n)].T).T[:, :3]
    w = -v[:, 2]
    reach_m = 3 * scales.max(axis=1)
    f = height / (2 * np.tan(fovy / 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        u = width / 2 + f * v[:, 0] / w
        y = height / 2 - f * v[:, 1] / w
        r = f * reach_m / w + 2
    x0, y0, x1, y1 = box[0], box[1], box[0] + box[2], box[1] + box[3]
    reaches = (u + r >= x0) & (u - r <= x1) & (y + r >= y0) & (y - r <= y1)
    keep = np.where((w <= reach_m) | reaches)[0]
    assert 50 < keep.size < n // 2  # the box sees a part of the scene, not all of it
    assert w[1] < 0 and 1 in keep  # behind the camera: left to Cesium's shader

    assert got["held"] is True
    assert got["count"] == keep.size
    assert got["drawn"]["i"] == 1  # the instance buffer of the splat indexes
    drawn = np.array(got["drawn"]["a"][:keep.size])
    assert sorted(drawn.tolist()) == keep.tolist()
    assert np.all(np.diff(v[drawn, 2]) >= 0)  # farthest (most negative view z) first
    assert got["pushed"] is True and got["afterDisarm"] == 0
    back = got["back"]
    assert back["own"] is False and back["held"] is False  # Cesium's own update again
    assert back["written"] == n  # Cesium's sorted indexes back in the buffer
    if sorted_here:
        assert back["count"] == n and back["frame"] == 7
    else:  # Cesium's last sort is for another pose: muted until it sorts for this one, asked now
        assert back["count"] == 0 and back["frame"] == -1
