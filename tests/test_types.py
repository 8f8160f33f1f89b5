"""mypy checks the whole of gsgeo/ (py.typed ships) with the [tool.mypy] settings of
pyproject.toml: every function annotated (disallow_untyped_defs), bodies checked
(check_untyped_defs), no error anywhere."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_gsgeo_type_checks(tmp_path: Path) -> None:
    pytest.importorskip("mypy")
    run = subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", str(tmp_path / "mypy-cache")],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "Success: no issues found" in run.stdout, run.stdout


def test_every_function_must_be_annotated(tmp_path: Path) -> None:
    """The settings really require annotations: an unannotated function is an error."""
    pytest.importorskip("mypy")
    probe = tmp_path / "probe.py"
    probe.write_text("def f(x):\n    return x\n")
    run = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"),
         "--cache-dir", str(tmp_path / "mypy-cache"), str(probe)],
        cwd=tmp_path, capture_output=True, text=True, timeout=300,
    )
    assert run.returncode == 1 and "missing a type annotation" in run.stdout, run.stdout + run.stderr
