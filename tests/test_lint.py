"""The code base passes ruff with the project's configuration (pyproject.toml)."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest
from conftest import REPO


def test_ruff_is_clean():
    if shutil.which("ruff") is None:
        try:
            import ruff  # noqa: F401
        except ImportError:
            pytest.skip("ruff is not installed")
    run = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "."],
                         cwd=REPO, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr


def test_the_repository_stands_alone():
    """No tracked file sends its reader to a design file outside the repository."""
    files = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True).stdout.split()
    if not files:
        pytest.skip("not a git checkout")
    offenders = []
    for name in files:
        path = REPO / name
        if name == "tests/test_lint.py" or not path.is_file() or path.suffix not in {
                ".py", ".js", ".md", ".html", ".css", ".sh", ".toml", ".json"}:
            continue
        text = path.read_text(encoding="utf-8", errors="replace")
        if "DESIGN.md" in text:
            offenders.append(name)
    assert offenders == []
