"""Shared fixtures: paths to ../shared data, deterministic random generators."""

from __future__ import annotations

from pathlib import Path

import hypothesis_profiles  # noqa: F401  (loads the Hypothesis profile: GSGEO_HYPOTHESIS=ci|long)
import numpy as np
import pytest

# the browser tests' session fixtures: one Chromium, one demo and one box scene with their servers
from tests.e2e.shared import box_data, box_server, browser, demo_data, demo_server  # noqa: E402, F401

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
SHARED_DATA = SHARED / "data"
WHITE_SCULPTURE = SHARED_DATA / "white-sculpture"


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture
def white_sculpture() -> Path:
    """The real 3DGS tileset of ../shared/data; the test is skipped where it is absent."""
    if not (WHITE_SCULPTURE / "tileset.json").is_file():
        pytest.skip("../shared/data/white-sculpture is not present beside this checkout")
    return WHITE_SCULPTURE


@pytest.fixture(scope="session")
def white_sculpture_rebuilt(tmp_path_factory):
    """The real tileset read, written as a PLY and rebuilt by `gsgeo tiles`, once per session
    (tests.tiles_real.rebuild_ply_and_tiles): (the rebuilt tileset's folder, its Summary)."""
    if not (WHITE_SCULPTURE / "tileset.json").is_file():
        pytest.skip("../shared/data/white-sculpture is not present beside this checkout")
    from tests.tiles_real import rebuild_ply_and_tiles

    work = tmp_path_factory.mktemp("white-sculpture-rebuilt")
    return work / "ours", rebuild_ply_and_tiles(WHITE_SCULPTURE, work, work / "ours")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Groups for pytest-xdist's ``--dist loadgroup`` (pyproject.toml's addopts): the browser
    tests all on one worker (they share one Chromium, one demo and one box scene, and two
    SwiftShader renderers at once would only slow each other), every other module whole on
    one worker (its module fixtures, servers and demo builds among them, made once)."""
    for item in items:
        browser = item.get_closest_marker("e2e") is not None and "e2e" in item.path.parts
        item.add_marker(pytest.mark.xdist_group("browser" if browser else item.path.stem))
