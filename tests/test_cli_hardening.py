"""Bad input at the command line and the other edges: one message, exit code 2, no traceback.

Each test here failed on the code before the hardening: deep or huge-number session files,
ranges of sigma_px / ifov / origins / directions, control characters in ids, the polygon
count in messages, `crs search` without a match and `-o` checked only after solving.
"""

from __future__ import annotations

import copy
import json
import os
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest
from conftest import REPO
from servertools import london_rays

from gsgeo import cli
from gsgeo.cli import main
from gsgeo.errors import InputError
from gsgeo.measure.features import polygon_measures
from gsgeo.service import Projects, open_store
from gsgeo.service.checkpoints import read_check_points
from gsgeo.service.validate import item_id
from gsgeo.session import parse_session
from gsgeo.solve import intersect, intersect_batch

EXAMPLE = REPO / "examples" / "session.json"


def example() -> dict:
    return json.loads(EXAMPLE.read_text())


def write(tmp_path, doc, name="s.json"):
    p = tmp_path / name
    if isinstance(doc, bytes):
        p.write_bytes(doc)
    else:
        p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p


def solve(capsys, *argv) -> tuple[int, str, str]:
    code = main(["solve", *map(str, argv)])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def one_error(err: str, *words: str) -> None:
    """stderr is one error line holding every word (and no traceback)."""
    lines = [ln for ln in err.splitlines() if "warning:" not in ln]
    assert len(lines) == 1, err
    assert lines[0].startswith("gsgeo ") and ": error: " in lines[0], err
    assert "Traceback" not in err
    for w in words:
        assert w in lines[0], (w, err)


# 1. parse bounds and the top-level guard ---------------------------------------------------
@pytest.mark.parametrize(("text", "words"), [
    ("[" * 100_000 + "]" * 100_000, ["nested more than 1024 levels"]),
    ('{"points": [], "sigma_px": ' + "9" * 5000 + "}", ["number too large", "line 1, column"]),
    ('{"points": [{"id": "A", "rays": [{"origin": [1e400, 0, 0]}]}]}', ["number too large"]),
    ('{"points": [], "sigma_px": NaN}', ["not valid JSON"]),
    ('{"points": [{"id": "\\ud800"}]}', ["not valid JSON", "surrogate"]),
])
def test_deep_or_huge_json_is_one_message(tmp_path, capsys, text, words):
    p = write(tmp_path, text)
    code, out, err = solve(capsys, p)
    assert code == 2
    one_error(err, str(p), *words)


def test_integer_too_large_for_a_float_names_the_field():
    doc = example()  # a decoded document (the store's import) may hold any Python int
    doc["points"][0]["rays"][0]["origin"][0] = 10 ** 400
    with pytest.raises(InputError, match=r"points\[0\].rays\[0\].origin\[0\]: .*too large"):
        parse_session(doc)


def test_non_utf8_and_oversized_files(tmp_path, capsys, monkeypatch):
    code, _, err = solve(capsys, write(tmp_path, b'{"points": [{"id": "\xff"}]}'))
    assert code == 2
    one_error(err, "UTF-8")
    monkeypatch.setattr("gsgeo.session.MAX_SESSION_BYTES", 100)
    code, _, err = solve(capsys, write(tmp_path, json.dumps(example()), "big.json"))
    assert code == 2
    one_error(err, "big.json", "larger than")


def test_a_byte_order_mark_is_accepted(tmp_path, capsys):
    p = write(tmp_path, b"\xef\xbb\xbf" + EXAMPLE.read_bytes())
    assert solve(capsys, p)[0] == 0


def test_deep_session_in_a_subprocess_gives_no_traceback(tmp_path):
    p = write(tmp_path, '{"points": ' + "[" * 50_000 + "]" * 50_000 + "}")
    run = subprocess.run([sys.executable, "-m", "gsgeo", "solve", str(p)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    one_error(run.stderr, "nested more than 1024 levels")


@pytest.mark.parametrize(("exc", "words"), [
    (PermissionError(13, "Permission denied", "/data/out.gpkg"), ["/data/out.gpkg: Permission denied"]),
    (OSError(30, "Read-only file system", "/ro/a", None, "/ro/b"), ["/ro/a -> /ro/b: Read-only file system"]),
    (RecursionError("maximum recursion depth exceeded"), ["nested too deeply"]),
    (MemoryError(), ["out of memory"]),
    (ValueError("element vertex -5 is negative\nsecond line"), ["element vertex -5 is negative second line"]),
])
def test_guard_turns_os_recursion_memory_value_errors_into_exit_2(monkeypatch, capsys, exc, words):
    def boom(args):
        raise exc

    monkeypatch.delenv("GSGEO_DEBUG", raising=False)
    monkeypatch.setattr("gsgeo.commands.crs.run_search", boom)
    assert main(["crs", "search", "x"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gsgeo crs: error: ")
    one_error(err, *words)


def test_unexpected_errors_are_one_line_with_a_debug_hint(monkeypatch, capsys):
    def boom(args):
        raise KeyError("surprise")

    monkeypatch.setattr("gsgeo.commands.crs.run_search", boom)
    monkeypatch.delenv("GSGEO_DEBUG", raising=False)
    assert main(["crs", "search", "x"]) == cli.EXIT_INTERNAL == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "internal error: KeyError" in err
    assert "GSGEO_DEBUG=1" in err
    monkeypatch.setenv("GSGEO_DEBUG", "1")
    with pytest.raises(KeyError):
        main(["crs", "search", "x"])


# 2. ranges of sigma_px and ifov, defined once ------------------------------------------------
@pytest.mark.parametrize("value", [1e-320, 0.001, 500, 0])
def test_sigma_px_out_of_range_in_session_and_flag(tmp_path, capsys, value):
    doc = example()
    doc["sigma_px"] = value
    code, out, err = solve(capsys, write(tmp_path, doc))
    assert code == 2 and out == ""
    one_error(err, "sigma_px: must be between 0.01 and 100 pixels")
    assert "behind the camera" not in err
    code, out, err = solve(capsys, EXAMPLE, "--sigma-px", value)
    assert code == 2 and out == ""
    one_error(err, "--sigma-px: must be between")


@pytest.mark.parametrize("value", [1e-320, 1e-9, 0.5])
def test_ifov_out_of_range_names_the_ray(tmp_path, capsys, value):
    doc = example()
    doc["points"][1]["rays"][2]["ifov"] = value
    code, _, err = solve(capsys, write(tmp_path, doc))
    assert code == 2
    one_error(err, "points[1].rays[2].ifov: must be between 1e-07 and 0.1 radians per pixel")


def test_solver_refuses_tiny_sigma_px_and_ifov_instead_of_a_false_geometry_error():
    o = np.array([[0.0, -10, 0], [10, 0, 0], [0, 0, 10]])
    d = np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, -1]])
    with pytest.raises(InputError, match="sigma_px: must be between"):
        intersect(o, d, ifov=1e-3, sigma_px=1e-320)
    # below the edges' 0.01 px the library still solves (simulations of noise-free aims)
    assert np.allclose(intersect(o, d, ifov=1e-3, sigma_px=1e-9).point, 0.0, atol=1e-9)
    with pytest.raises(InputError, match="ifov must be between"):
        intersect(o, d, ifov=1e-320)
    with pytest.raises(InputError, match="ifov must be between"):
        intersect_batch(o[None], d[None], ifov=1e-320)


def test_store_settings_use_the_same_range(tmp_path):
    store = open_store(tmp_path)
    try:
        svc = Projects(store, tmp_path)
        for bad in (1e-320, 101.0):
            with pytest.raises(InputError, match="sigma_px: must be between 0.01 and 100"):
                svc.create_project(name="A", crs="EPSG:32630", sigma_px=bad)
        p = svc.create_project(name="A", crs="EPSG:32630", sigma_px=100.0)
        with pytest.raises(InputError, match="sigma_px: must be between"):
            svc.update_project(p.id, {"sigma_px": 1e-320})
        with pytest.raises(InputError, match=r"rays\[0\].ifov: must be between"):
            svc.add_point(p.id, {"id": "A", "rays": london_rays(3, ifov=1e-320)})
        assert svc.list_points(p.id) == []
    finally:
        store.close()


def test_api_uses_the_same_range_and_id_rule(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from fastapi.testclient import TestClient
    from gsgeo.server.app import ServerConfig, create_app

    app = create_app(ServerConfig(data_dir=tmp_path, allowed_hosts={"testserver"}))
    with TestClient(app) as client:
        for body, field in (({"rays": london_rays(2, ifov=1e-3), "sigma_px": 1e-320}, "sigma_px"),
                            ({"rays": london_rays(2, ifov=1e-3), "sigma_px": 500}, "sigma_px"),
                            ({"rays": london_rays(2, ifov=0.5)}, "ifov"),
                            ({"rays": london_rays(2, ifov=1e-320)}, "ifov")):
            r = client.post("/api/intersect", json=body)
            assert r.status_code == 422, r.text
            assert field in r.json()["message"]
        r = client.post("/api/intersect", json={"rays": london_rays(3, ifov=1e-3), "sigma_px": 100})
        assert r.status_code == 200, r.text
        # ids with control characters: a 4xx naming the character, nothing stored
        pid = client.post("/api/projects", json={"name": "A", "crs": "EPSG:32630"}).json()["id"]
        for bad in ("\x85nel", "nel\u2028"):
            r = client.post(f"/api/projects/{pid}/points", json={"id": bad, "rays": london_rays(3)})
            assert r.status_code == 422 and "U+" in r.json()["message"], r.text
        assert client.get(f"/api/projects/{pid}/points").json()["points"] == []


# 3. the real problem of huge or tiny numbers -------------------------------------------------
@pytest.mark.parametrize(("field", "value", "words"), [
    ("direction", [1e300, 1e300, 1e300], "direction: too large to normalise"),
    ("direction", [1e-200, 0, 1e-200], "direction: too small to normalise"),
    ("direction", [0, 0, 0], "direction: is a zero vector"),
    ("origin", [1e308, 1e308, 1e308], "origin: out of range: 1.73e+308 m from the Earth's centre"),
    ("origin", [2e9, 0, 0], "origin: out of range"),
])
@pytest.mark.parametrize("crs", ["EPSG:27700", None])
def test_huge_and_tiny_vectors_name_the_real_problem(tmp_path, capsys, field, value, words, crs):
    doc = example()
    doc["crs"] = crs
    doc["points"][0]["rays"][1][field] = value
    code, _, err = solve(capsys, write(tmp_path, doc))
    assert code == 2
    one_error(err, f"points[0].rays[1].{words}")
    for wrong in ("zero-length", "NaN or infinite", "behind the camera"):
        assert wrong not in err or "zero" in words


def test_solver_names_the_real_problem_of_huge_and_tiny_vectors():
    o = np.array([[0.0, -10, 0], [10, 0, 0], [0, 0, 10]])
    d = np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, -1]])
    big_d, small_d, far_o = d.copy(), d.copy(), o.copy()
    big_d[1] *= 1e300
    small_d[1] *= 1e-200
    far_o[2] = 1e308
    with pytest.raises(InputError, match=r"ray\(s\) 2 have a direction too large to normalise"):
        intersect(o, big_d)
    with pytest.raises(InputError, match=r"ray\(s\) 2 have a direction too small to normalise"):
        intersect(o, small_d)
    with pytest.raises(InputError, match=r"ray\(s\) 3: origin out of range"):
        intersect(far_o, d)
    with pytest.raises(InputError, match="point 0 has a ray with a direction too large"):
        intersect_batch(o[None], big_d[None])
    with pytest.raises(InputError, match="point 0 has a ray whose origin is out of range"):
        intersect_batch(far_o[None], d[None])
    # just inside the ranges the solver still works
    assert np.all(np.isfinite(intersect(o, d * 1e99).point))


def test_model_matrix_moving_a_ray_out_of_range_is_named(tmp_path, capsys):
    doc = example()
    mm = [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 1e300, 0, 0, 1.0]
    for ray in doc["points"][0]["rays"]:
        ray["model_matrix"] = mm
    code, out, err = solve(capsys, write(tmp_path, doc))
    assert code == 2
    assert "P1" in out and "georeferenced origin" in out and "out of range" in out
    assert "Traceback" not in err


# 4. polygon counts --------------------------------------------------------------------------
@pytest.mark.parametrize(("ids", "words"), [
    (["P1", "P2", "P1"], "got 2 (of 3 given)"),
    (["P1", "P2"], "got 2"),
])
def test_polygon_error_counts_the_ids_given(tmp_path, capsys, ids, words):
    doc = example()
    doc["polygons"] = [{"id": "A1", "points": ids}]
    code, out, err = solve(capsys, write(tmp_path, doc), "-o", tmp_path / "o.gpkg")
    assert code == 2
    one_error(err, "polygon 'A1'", f"at least 3 distinct points, {words}")
    assert not (tmp_path / "o.gpkg").exists()


def test_polygon_measures_counts_points_given_before_the_closing_one():
    same = np.zeros((3, 3))
    with pytest.raises(InputError, match=r"got 1 \(of 3 given\)"):
        polygon_measures(same, None, ["A", "B", "C"])


def test_store_polygon_error_counts_the_ids_given(tmp_path):
    store = open_store(tmp_path)
    try:
        svc = Projects(store, tmp_path)
        p = svc.create_project(name="A", crs="EPSG:32630")
        with pytest.raises(InputError, match=r"got 2 \(3 given, the last closing the ring\)"):
            svc.add_feature(p.id, "polygon", {"id": "F", "points": ["X", "Y", "X"]})
    finally:
        store.close()


# 5. control characters in ids ---------------------------------------------------------------
BAD_IDS = ["\x85nel", "nel\x85", "a\u2028b", "a\u2029", "\x00", "a\tb", "\x9f", "\x7f"]


@pytest.mark.parametrize("bad", BAD_IDS)
def test_ids_with_control_characters_are_refused_everywhere(tmp_path, capsys, bad):
    code = f"U+{ord(next(c for c in bad if c not in 'nelab')):04X}"
    for where, edit in (("points[0].id", lambda d: d["points"][0].__setitem__("id", bad)),
                        ("lines[0].id", lambda d: d["lines"][0].__setitem__("id", bad)),
                        ("polygons[0].points[1]", lambda d: d["polygons"][0]["points"].__setitem__(1, bad))):
        doc = example()
        edit(doc)
        rc, out, err = solve(capsys, write(tmp_path, doc))
        assert rc == 2 and out == ""
        one_error(err, f"{where}: contains {code}")
    with pytest.raises(InputError, match=re.escape(f"id: contains {code}")):
        item_id(bad, "id")
    with pytest.raises(InputError, match=re.escape(code)):
        read_check_points(f"id,x,y,z\n{bad},1,2,3\n".encode(), "csv")


def test_store_never_strips_a_control_character_into_another_id(tmp_path):
    store = open_store(tmp_path)
    try:
        svc = Projects(store, tmp_path)
        p = svc.create_project(name="A", crs="EPSG:32630")
        with pytest.raises(InputError, match="U\\+0085"):
            svc.add_point(p.id, {"id": "\x85nel", "rays": london_rays(3)})
        doc = {"points": [{"id": "nel\u2028", "rays": london_rays(3)}]}
        with pytest.raises(InputError, match="U\\+2028"):
            svc.import_session(p.id, doc)
        assert svc.list_points(p.id) == []
        assert item_id("  nel ", "id") == "nel"  # ordinary blanks are still trimmed
    finally:
        store.close()


# 6. crs search without a match -----------------------------------------------------------
def test_crs_search_without_a_match_is_exit_0_with_a_message(capsys):
    assert main(["crs", "search", "zzzz"]) == 0
    cap = capsys.readouterr()
    assert "CRS matches 'zzzz'" in cap.err and cap.out == ""
    assert main(["crs", "search", "zzzz", "--json"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out) == [] and "CRS matches 'zzzz'" in cap.err


# 7. outputs are checked before solving --------------------------------------------------
def _unwritable_dir(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if not os.access(ro, os.W_OK):
        return ro
    if os.path.isdir("/proc/self") and not os.access("/proc/self", os.W_OK):
        return "/proc/self"  # root writes anywhere else
    pytest.skip("no directory this user cannot write to")


@pytest.mark.parametrize(("out", "words"), [
    ("o.txt", "cannot tell the export format"),
    ("missing/o.gpkg", "does not exist"),
    ("adir", "cannot tell the export format"),
    ("unwritable", "is not writable"),
])
def test_bad_output_is_reported_before_solving(tmp_path, capsys, monkeypatch, out, words):
    (tmp_path / "adir").mkdir()
    target = (f"{_unwritable_dir(tmp_path)}/o.gpkg" if out == "unwritable" else tmp_path / out)

    def no_solving(*a, **k):
        raise AssertionError("solved before checking the output")

    monkeypatch.setattr("gsgeo.commands.solve.measure_session", no_solving)
    code, stdout, err = solve(capsys, EXAMPLE, "-o", target)
    assert code == 2 and stdout == ""
    one_error(err, words)


def test_output_directory_given_with_a_format_is_refused_before_solving(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("gsgeo.commands.solve.measure_session", None)  # would fail if called
    code, stdout, err = solve(capsys, EXAMPLE, "-o", tmp_path, "--export-format", "csv")
    assert code == 2 and stdout == ""
    one_error(err, "it is a directory")


def test_good_output_still_written(tmp_path, capsys):
    doc = copy.deepcopy(example())
    code, out, err = solve(capsys, write(tmp_path, doc), "-o", tmp_path / "o.csv")
    assert code == 0 and "P1" in out
    assert (tmp_path / "o.csv").read_text().startswith("point_id,")


def test_missing_geoid_is_one_message_before_solving(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("gsgeo.commands.solve.measure_session", None)  # would fail if called
    for geoid, words in ((tmp_path / "none.tif", "no such file"), (tmp_path, "is a directory")):
        code, stdout, err = solve(capsys, EXAMPLE, "--crs", "EPSG:27700", "--geoid", geoid)
        assert code == 2 and stdout == ""
        one_error(err, f"--geoid {geoid}: {words}")


@pytest.mark.parametrize(("edit", "words"), [
    (lambda d: d["points"][0].__setitem__("id", 10 ** 5000), r"points\[0\].id: expected text"),
    (lambda d: d["points"][0].__setitem__("rays", 10 ** 5000), r"points\[0\].rays: .*integer"),
    (lambda d: d["points"][0].__setitem__("code", 10 ** 5000), r"points\[0\].code: expected text"),
    (lambda d: d.__setitem__("crs", 10 ** 5000), "crs: expected text"),
])
def test_huge_integers_in_a_decoded_document_are_input_errors(edit, words):
    """Python refuses str() of an integer over 4300 digits (ValueError): never reached."""
    doc = example()
    edit(doc)
    with pytest.raises(InputError, match=words):
        parse_session(doc)
    with pytest.raises(InputError, match="expected text"):
        item_id(10 ** 5000, "id")
