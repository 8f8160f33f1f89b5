"""The viewer's measuring-experience helpers in Node.js: the id offered for a new point
(web/js/pointid.js), the error ellipsoid's exaggeration and quality colour (web/js/quality.js),
and the height system and project warnings as the panels show them (web/js/format.js)."""

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
    """Run `body` with pointid.js as I, quality.js as Q, format.js as F, autoaimtext.js as T
    and `data` bound; it prints one JSON value."""
    src = (f"import * as I from '{(WEB_JS / 'pointid.js').as_uri()}';\n"
           f"import * as T from '{(WEB_JS / 'autoaimtext.js').as_uri()}';\n"
           f"import * as Q from '{(WEB_JS / 'quality.js').as_uri()}';\n"
           f"import * as F from '{(WEB_JS / 'format.js').as_uri()}';\n"
           f"const data = {json.dumps(data)};\n{body}\n")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


SOLUTION = {"crs": "EPSG:27700", "easting": 545386.012, "northing": 258102.004, "height": 63.5,
            "lon": 0.1234, "lat": 52.2, "h_wgs84": 63.5}
CHECKS = [
    {"id": "B1", "x": 545386.0, "y": 258102.0, "z": 63.509, "crs": "EPSG:27700"},  # 1.5 cm away
    {"id": "B2", "x": 545386.3, "y": 258102.0, "z": 63.5, "crs": "EPSG:27700"},    # 29 cm away
    {"id": "G1", "x": 545380.0, "y": 258095.0, "z": 52.0, "crs": "EPSG:27700"},    # 15 m away
]


def test_offered_id_is_the_nearest_unmeasured_check_point():
    got = run_js("""console.log(JSON.stringify([
      I.suggestPointId(data.sol, data.checks, []),
      I.suggestPointId(data.sol, data.checks, [{ id: "B1" }]),
      I.suggestPointId(data.sol, data.checks, [{ id: "B1" }, { id: "B2" }, { id: "P4" }]),
      I.suggestPointId(null, data.checks, [{ id: "P1" }]),
      I.suggestPointId(data.sol, [], [{ id: "P2" }, { id: "P3" }]),
      I.suggestPointId({ ...data.sol, crs: null, easting: null, lon: 0.1234, lat: 52.2 },
        [{ id: "W1", x: 0.12341, y: 52.2, z: 63.5, crs: "EPSG:4979" }], []),
    ]));""", {"sol": SOLUTION, "checks": CHECKS})
    # the measured B1 is not offered again; G1 is too far (beyond 1 m) to be this point
    assert got == ["B1", "B2", "P5", "P2", "P4", "W1"]


def test_exaggeration_makes_the_ellipsoid_visible_in_1_2_5_steps():
    got = run_js("""console.log(JSON.stringify(data.map(([r, d]) =>
      Q.exaggeration(r, d, Math.PI / 3, 720))));""",
                 [[0.02, 10.0], [0.02, 40.0], [0.5, 10.0], [0.001, 100.0], [0.0001, 100.0], [0.0, 10.0]])
    # 2 cm at 10 m: 0.02 * 720 / (2 * 10 * tan 30 deg) = 1.25 px -> x20 (25 px, >= 24)
    assert got == [20, 100, 1, 5000, 10000, 1]  # capped at 10000


def test_quality_against_the_default_tolerance():
    got = run_js("console.log(JSON.stringify([0.015, 0.02, 0.021, 0.05, 0.2, NaN]"
                 ".map((r) => Q.quality(r))));", None)
    assert got == ["good", "good", "fair", "fair", "poor", None]


def test_height_system_is_said_once():
    got = run_js("""console.log(JSON.stringify([
      F.heightsText("ellipsoidal", "ellipsoidal height on WGS 84 (EPSG:4979)"),
      F.heightsText("orthometric", "ODN height (EPSG:5701)"),
      F.heightsText("ellipsoidal", null)]));""", None)
    assert got == ["ellipsoidal height on WGS 84 (EPSG:4979)",
                   "ODN height (EPSG:5701) (orthometric height)", "ellipsoidal height"]


def test_warnings_every_point_shares_are_the_projects():
    datum = "EPSG:4978 -> EPSG:27700 goes through ..., accurate to 2 m only"
    pts = [{"status": "solved", "result": {"warnings": [datum]}},
           {"status": "solved", "result": {"warnings": [datum, "ray(s) 2 excluded by request"]}},
           {"status": "failed", "result": None}]
    got = run_js("console.log(JSON.stringify([F.sharedWarnings(data), "
                 "F.sharedWarnings(data.slice(1))]));", pts)
    # one point alone: its warnings stay its own
    assert got == [[datum], []]


def test_auto_aim_and_enter_say_what_happened_and_what_to_do_next():
    """An auto-aim that matched no view does not offer Enter (one ray cannot be stored) but
    says to click another view; one that did says how many rays it added; the reasons stay in
    the panel, so the status line stays short; Enter with one ray says why nothing was
    stored."""
    t = run_js("""console.log(JSON.stringify({none: T.autoAimSummary(0, 4, 4),
        some: T.autoAimSummary(3, 4, 1), all: T.autoAimSummary(4, 4, 0),
        whole: T.autoAimDeclined('ray 1 hits no splat (sky?).'),
        one: T.tooFewRays('P3', 1), zero: T.tooFewRays('P3', 0), snap: T.snapText(1.456)}));""", None)
    assert "Enter" not in t["none"] and "another view" in t["none"] and "none of the 4 views" in t["none"]
    assert t["some"].startswith("Auto-aim added 3 rays of 4 views; 1 declined")
    assert "Enter stores" in t["some"]
    assert "declined" not in t["all"] and "4 rays" in t["all"]
    assert t["whole"].startswith("Auto-aim declined: ray 1 hits no splat (sky?). Click it yourself")
    assert t["one"].startswith("Nothing stored: P3 has 1 ray and a point needs 2 or more.")
    assert "another view" in t["one"] and "add ray 1" in t["zero"]
    assert t["snap"].startswith("Ray 1 moved 1.5 px onto the point feature")
    assert max(len(x) for x in t.values()) < 130, t


def test_navigation_arithmetic():
    """web/js/navmath.js: wheel notches, the zoom about a point (checked by hand: the camera
    stays on the line through the point, 0.8 of the distance per notch, stops 0.3 m short),
    and the scale bar's 1-2-5 lengths."""
    src = (f"import * as N from '{(WEB_JS / 'navmath.js').as_uri()}';\n"
           """console.log(JSON.stringify({
      notches: [N.notches({ deltaY: -100, deltaMode: 0 }), N.notches({ deltaY: 3, deltaMode: 1 }),
                N.notches({ deltaY: -1, deltaMode: 2 })],
      in1: N.zoomedPosition([10, 0, 0], [0, 0, 0], 1),
      out2: N.zoomedPosition([0, 10, 0], [0, 0, 0], -2),
      stop: N.zoomedPosition([0, 0, 1], [0, 0, 0], 20),
      stopped: N.zoomedPosition([0, 0, 0.3], [0, 0, 0], 1),
      bars: [N.scaleBar(0.01), N.scaleBar(0.5), N.scaleBar(30), N.scaleBar(0)],
    }));""")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["notches"] == [1, -1, 1]
    assert got["in1"] == pytest.approx([8.0, 0, 0])
    assert got["out2"] == pytest.approx([0, 10 / 0.64, 0])
    assert got["stop"] == pytest.approx([0, 0, 0.3])
    assert got["stopped"] is None
    # 120 px at 1 cm/px = 1.2 m -> 1 m (100 px); 60 m -> 50 m; 3.6 km -> 2 km; none at 0
    assert [(b["metres"], b["label"]) for b in got["bars"][:3]] == [
        (1, "1 m"), (50, "50 m"), (2000, "2 km")]
    assert got["bars"][0]["px"] == pytest.approx(100.0)
    assert got["bars"][3] is None


def test_pan_and_orbit_arithmetic():
    """web/js/navmath.js: a pan moves the camera in its image plane by metres-per-pixel at the
    grabbed depth (so a point at that depth follows the cursor, checked by projecting it by
    hand); an orbit keeps the pivot's distance and its pixel (the camera turns as a rigid body),
    turns the heading by the yaw, raises the elevation by the pitch, and stops it at 2 and 88
    degrees."""
    src = (f"import * as N from '{(WEB_JS / 'navmath.js').as_uri()}';\n"
           """const s = Math.SQRT1_2;
    // camera 10 m south of and 10 m above the pivot (origin), looking at it; z is up
    const pose = { position: [0, -10, 10], direction: [0, s, -s], up: [0, s, s] };
    const orbit = (yaw, pitch) => N.orbitedPose(pose, [0, 0, 0], [0, 0, 1], yaw, pitch);
    console.log(JSON.stringify({
      mpp: N.metresPerPixel(10, Math.PI / 2, 500),
      pan: N.pannedPosition([0, 0, 0], [1, 0, 0], [0, 0, 1], 30, -20, 0.04),
      turn: orbit(Math.PI / 2, 0),
      raise: orbit(0, 10 * Math.PI / 180),
      low: orbit(0, -80 * Math.PI / 180),
      high: orbit(0, 80 * Math.PI / 180),
    }));""")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["mpp"] == pytest.approx(2 * 10 / 500)
    # a point 10 m ahead (camera at origin looking along +y, right +x, up +z) at pixel offset 0;
    # after dragging 30 px right and 20 px up it must appear 30 px right, 20 px up: the camera
    # moved 1.2 m left and 0.8 m down
    assert got["pan"] == pytest.approx([-1.2, 0, -0.8])
    for key in ("turn", "raise", "low", "high"):
        q = got[key]
        pos, d = np.asarray(q["position"]), np.asarray(q["direction"])
        assert np.linalg.norm(pos) == pytest.approx(np.sqrt(200))  # the pivot's distance kept
        assert np.cross(d, -pos / np.linalg.norm(pos)) == pytest.approx(np.zeros(3), abs=1e-12)  # still at it
        assert np.dot(d, q["up"]) == pytest.approx(0, abs=1e-12)
    assert got["turn"]["position"] == pytest.approx([10, 0, 10])  # a quarter turn anticlockwise
    elev = {k: np.degrees(np.arcsin(got[k]["position"][2] / np.sqrt(200))) for k in ("raise", "low", "high")}
    assert elev["raise"] == pytest.approx(55)
    assert elev["low"] == pytest.approx(2)
    assert elev["high"] == pytest.approx(88)


def test_heading_is_the_azimuth_of_the_view_in_the_local_frame():
    """web/js/navmath.js headingOf (the north arrow's angle): the direction's azimuth clockwise
    from north in the local east-north-up frame at the camera (pyproj's geodetic latitude and
    longitude of the position give the frame), the up vector's when looking straight down."""
    import pyproj

    geod = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    cases = []
    for lon, lat, h, az, el in [(0.12, 52.2, 60, 30, -40), (-122.4, 37.8, 10, 250, -5),
                                (151.2, -33.9, 500, 179, 20), (10, 0, 0, 90, -60)]:
        pos = np.array(geod.transform(lon, lat, h))
        lam, phi = np.radians(lon), np.radians(lat)
        east = np.array([-np.sin(lam), np.cos(lam), 0])
        north = np.array([-np.sin(phi) * np.cos(lam), -np.sin(phi) * np.sin(lam), np.cos(phi)])
        up = np.array([np.cos(phi) * np.cos(lam), np.cos(phi) * np.sin(lam), np.sin(phi)])
        a, e = np.radians(az), np.radians(el)
        d = np.cos(e) * (np.sin(a) * east + np.cos(a) * north) + np.sin(e) * up
        cam_up = np.cross(np.cross(d, up), d)
        cases.append((pos.tolist(), d.tolist(), (cam_up / np.linalg.norm(cam_up)).tolist(), az))
    # straight down, the top of the image towards azimuth 300
    a = np.radians(300)
    cases.append((pos.tolist(), (-up).tolist(), (np.sin(a) * east + np.cos(a) * north).tolist(), 300))
    src = (f"import * as N from '{(WEB_JS / 'navmath.js').as_uri()}';\n"
           f"const cases = {json.dumps([c[:3] for c in cases])};\n"
           "console.log(JSON.stringify(cases.map(([p, d, u]) => N.headingOf(p, d, u))));")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    got = np.degrees(json.loads(out.stdout))
    # (the frame's up is the ellipsoid's normal scaled through the camera, as Cesium's: at 500 m
    # above the ellipsoid it leans 1e-6 degrees from the geodetic normal pyproj's latitude gives)
    assert got == pytest.approx([c[3] for c in cases], abs=1e-5)
