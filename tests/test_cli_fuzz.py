"""Fuzz `gsgeo solve` with malformed session files: never a traceback, exit 0 or 2, a message.

Hypothesis mutates a valid session (a value of the wrong type, huge, tiny or non-finite
numbers, huge integers, control characters in ids, missing fields, deep nesting) or its bytes
(NaN / Infinity literals, long digit strings, invalid UTF-8, truncation). Runs go in-process
through gsgeo.cli.main for speed; a few go through a subprocess to show nothing leaks past it.
"""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from conftest import REPO
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis_profiles import examples

from gsgeo.cli import main

EXAMPLE = json.loads((REPO / "examples" / "session.json").read_text())


def small_session() -> dict:
    """Two points of the example with three rays each, a line and a polygon."""
    doc = json.loads(json.dumps(EXAMPLE))
    doc["points"] = [dict(p, rays=p["rays"][:3]) for p in doc["points"][:3]]
    return doc


def deep(n: int) -> object:
    v: object = 1.0
    for _ in range(n):
        v = [v]
    return v


ODD_TEXT = st.sampled_from(["", " ", "\x85nel", "a\u2028", "\x00", "P1", "x" * 500, "\x9f", "é"])
ODD_NUMBER = st.sampled_from([0, -1, 1e-320, 5e-324, 1e-200, 1e300, 1e308, -1e308, 10**30,
                              2**64, 0.5, 1e9, 1e10, 1e-9])
LEAF = st.one_of(st.none(), st.booleans(), ODD_NUMBER, ODD_TEXT,
                 st.floats(allow_nan=False, allow_infinity=False), st.integers())
ODD_VALUE = st.one_of(
    LEAF,
    st.lists(LEAF, max_size=4),
    st.dictionaries(st.sampled_from(["id", "rays", "origin", "x"]), LEAF, max_size=3),
    st.integers(min_value=0, max_value=800).map(deep),  # deeper: the raw "deep" mutation
)


def paths(doc: object, max_depth: int = 8) -> list[tuple]:
    """Paths (tuples of keys / indices) into a JSON document, down to ``max_depth``."""
    out, todo = [], [((), doc)]
    while todo:
        prefix, value = todo.pop()
        out.append(prefix)
        if len(prefix) < max_depth:
            items = value.items() if isinstance(value, dict) else (
                enumerate(value) if isinstance(value, list) else ())
            todo += [(prefix + (k,), v) for k, v in items]
    return out


@st.composite
def mutated_session(draw) -> bytes:
    doc = small_session()
    for _ in range(draw(st.integers(1, 3))):
        all_paths = [p for p in paths(doc) if p]
        path = draw(st.sampled_from(all_paths))
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        if draw(st.booleans()) and isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent[path[-1]] = draw(ODD_VALUE)
        if not isinstance(doc, dict):
            break
    text = json.dumps(doc).encode()
    # mostly well-formed JSON, so that the mutations above reach the session's validation
    raw = draw(st.sampled_from(["none"] * 6 + ["nan", "inf", "digits", "utf8", "cut", "deep"]))
    if raw == "nan":
        text = text.replace(b"1.0", b"NaN", 1)
    elif raw == "inf":
        text = text.replace(b"1.0", b"-Infinity", 1)
    elif raw == "digits":
        text = text.replace(b"1.0", b"9" * draw(st.integers(300, 6000)), 1)
    elif raw == "utf8":
        text = text.replace(b'"P1"', b'"P\xff\xfe1"', 1)
    elif raw == "cut":
        text = text[:draw(st.integers(0, len(text)))]
    elif raw == "deep":
        n = draw(st.integers(1000, 30000))
        text = text.replace(b'"lines":', b'"lines":' + b"[" * n + b"]" * n + b", \"x\":", 1)
    return text


ARGS = st.sampled_from([[], ["--json"], ["--crs", "EPSG:27700"], ["--crs", ""],
                        ["--sigma-px", "1e-320"], ["--crs", "EPSG:27700", "-o", "OUT.csv"]])


def run_solve(data: bytes, args: list[str], folder: Path) -> tuple[int, str, str]:
    session = folder / "s.json"
    session.write_bytes(data)
    argv = ["solve", str(session)] + [str(folder / a) if a == "OUT.csv" else a for a in args]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def check_outcome(code: int, err: str) -> None:
    assert "Traceback" not in err, err
    assert "internal error" not in err, err
    assert code in (0, 2), (code, err)
    lines = [ln for ln in err.splitlines() if ln]
    assert all(ln.startswith("gsgeo solve: ") for ln in lines), err
    if code == 2:
        problems = [ln for ln in lines if ": error: " in ln or "could not be solved" in ln]
        assert len(problems) == 1, err


@settings(max_examples=examples(300), deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(data=mutated_session(), args=ARGS)
def test_malformed_sessions_get_one_message_and_exit_0_or_2(data, args):
    with tempfile.TemporaryDirectory() as tmp:
        code, _, err = run_solve(data, args, Path(tmp))
    check_outcome(code, err)


@settings(max_examples=examples(30), deadline=None)
@given(value=ODD_VALUE, key=st.sampled_from(["sigma_px", "crs", "source_crs", "points",
                                               "lines", "polygons", "vertical"]))
def test_top_level_fields_of_any_type(value, key):
    doc = small_session()
    doc[key] = value
    with tempfile.TemporaryDirectory() as tmp:
        code, _, err = run_solve(json.dumps(doc).encode(), [], Path(tmp))
    check_outcome(code, err)


def test_subprocess_runs_leak_nothing(tmp_path):
    """The same guarantee through the installed entry point, for a few nasty files."""
    doc = small_session()
    doc["points"][0]["id"] = "\x85nel"
    cases = [
        b'{"points": ' + b"[" * 40000 + b"]" * 40000 + b"}",
        json.dumps(doc).encode(),
        json.dumps(small_session()).replace("1.0", "9" * 5000, 1).encode(),
        b'{"points": [{"id": "P\xff", "rays": []}]}',
    ]
    for i, data in enumerate(cases):
        p = tmp_path / f"s{i}.json"
        p.write_bytes(data)
        run = subprocess.run([sys.executable, "-m", "gsgeo", "solve", str(p)],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 2, run.stderr
        assert "Traceback" not in run.stderr
        assert run.stderr.count("\n") == 1 and run.stderr.startswith("gsgeo solve: error: ")
        assert str(p) in run.stderr and run.stdout == ""
