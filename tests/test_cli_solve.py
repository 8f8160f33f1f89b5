"""`gsgeo solve`: the example session, JSON output, and clear errors with exit code 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO

from gsgeo.cli import main
from gsgeo.session import load_session

EXAMPLE = REPO / "examples" / "session.json"


def _write(tmp_path, doc, name="s.json"):
    p = tmp_path / name
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p


def _ray(o, d, **extra):
    return {"origin": list(o), "direction": list(d), **extra}


def _good_point(pid="P1"):
    return {"id": pid, "rays": [_ray([-10, 0, 0], [1, 0, 0]), _ray([0, -10, 0.02], [0, 1, 0])]}


def test_example_session_solves(capsys):
    assert main(["solve", str(EXAMPLE)]) == 0
    out = capsys.readouterr().out
    for pid in ("P1", "P2", "P3"):
        assert pid in out


def test_json_output_and_sigma_px_override(tmp_path, capsys):
    assert main(["solve", str(EXAMPLE), "--json"]) == 0
    doc1 = json.loads(capsys.readouterr().out)
    assert main(["solve", str(EXAMPLE), "--json", "--sigma-px", "2"]) == 0
    doc2 = json.loads(capsys.readouterr().out)
    assert [p["id"] if "id" in p else p["point_id"] for p in doc1["points"]] == ["P1", "P2", "P3"]
    # the angular model's a-priori covariance scales with sigma_px^2, sigma0 with 1 / sigma_px
    s1 = np.array([p["sigma0"] for p in doc1["points"]])
    s2 = np.array([p["sigma0"] for p in doc2["points"]])
    np.testing.assert_allclose(s2, s1 / 2, rtol=1e-9)


def test_unsolvable_point_is_reported_and_others_solved(tmp_path, capsys):
    parallel = {"id": "BAD", "rays": [_ray([0, 0, 0], [0, 1, 0]), _ray([1, 0, 0], [0, 1, 0])]}
    p = _write(tmp_path, {"points": [_good_point(), parallel]})
    assert main(["solve", str(p)]) == 2
    cap = capsys.readouterr()
    assert "P1" in cap.out
    assert "parallel" in cap.out
    assert "BAD" in cap.err


@pytest.mark.parametrize(
    ("doc", "words"),
    [
        ("{not json", "not valid JSON"),
        ("[]", "JSON object"),
        ({"points": "x"}, "points: expected a list"),
        ({"points": []}, "no points"),
        ({"points": [{"rays": []}]}, "points[0]: missing 'id'"),
        ({"points": [{"id": "A", "rays": [{"origin": [1, 2]}]}]}, "points[0].rays[0]: missing 'direction'"),
        ({"points": [{"id": "A", "rays": [_ray([1, 2], [1, 0, 0])]}]}, "points[0].rays[0].origin"),
        ({"points": [{"id": "A", "rays": [_ray([1, 2, "x"], [1, 0, 0])]}]}, "origin[2]: expected a number"),
        ({"points": [{"id": "A", "rays": [_ray([1, 2, 3], [0, 0, 0])]}]}, "zero vector"),
        ({"points": [{"id": "A", "rays": [_ray([1, 2, 3], [1, 0, 0], ifov=-1)]}]}, "ifov"),
        ({"points": [{"id": "A", "rays": [_ray([1, 2, 3], [1, 0, 0], model_matrix=[1] * 16)]}]},
         "model_matrix"),
        ({"points": [_good_point("A"), _good_point("A")]}, "duplicate point id"),
        ({"points": [_good_point()], "sigma_px": -1}, "sigma_px"),
    ],
)
def test_malformed_session_exit_2(tmp_path, capsys, doc, words):
    p = _write(tmp_path, doc)
    assert main(["solve", str(p)]) == 2
    err = capsys.readouterr().err
    assert words in err
    assert "Traceback" not in err


def test_missing_file_and_mixed_ifov(tmp_path, capsys):
    assert main(["solve", str(tmp_path / "nope.json")]) == 2
    assert "no such file" in capsys.readouterr().err
    mixed = {"id": "M", "rays": [_ray([-10, 0, 0], [1, 0, 0], ifov=1e-3), _ray([0, -10, 0], [0, 1, 0])]}
    assert main(["solve", str(_write(tmp_path, {"points": [mixed]}))]) == 2
    assert "no ifov" in capsys.readouterr().out


def test_command_line_never_prints_a_traceback(tmp_path):
    p = _write(tmp_path, {"points": [{"id": "A", "rays": [_ray([1, 2, 3], [1, 0])]}]})
    run = subprocess.run([sys.executable, "-m", "gsgeo", "solve", str(p)],
                         capture_output=True, text=True, cwd=REPO)
    assert run.returncode == 2
    assert "direction: expected a list of 3 numbers" in run.stderr
    assert "Traceback" not in run.stderr


def test_example_session_parses_with_pixel_metadata():
    s = load_session(EXAMPLE)
    assert len(s.points) == 3 and all(len(p.rays) == 5 for p in s.points)
    assert all(r.ifov is not None and r.viewport == (1920.0, 1080.0) for p in s.points for r in p.rays)
