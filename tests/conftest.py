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
    """The browser tests (tests/e2e/) last: they start when the other modules are handed out,
    so that the two groups of them (pytest_xdist_make_scheduler) run beside each other rather
    than beside the CPU-heavy modules. The order within each part is kept."""
    items.sort(key=lambda item: "e2e" in item.path.parts)


#: The browser tests on the demo scene (tests/e2e/shared.py's demo build and server): one
#: group, the other browser tests (the box scene, static hosts, the real scene) another.
DEMO_BROWSER_MODULES = ("test_autoaim.py", "test_building_tool.py", "test_guide.py")


def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object:
    """pytest-xdist's scheduler for the suite (pyproject.toml's addopts: two workers): every
    test module whole on one worker (its module fixtures, servers and demo builds among them,
    made once), and the browser tests (tests/e2e/) in two groups, each whole on one worker:
    those on the demo scene (one demo build and server) and the others (one box scene). Each
    group shares one Chromium. They are collected last, so each starts when a worker is free
    of the other modules (pytest_collection_modifyitems), and the two run side by side.
    (xdist's own ``--dist loadgroup`` marks do not reach it under pytest 9.2: the group is
    written into a node id that pytest no longer reads.)"""
    from xdist.scheduler import LoadScopeScheduling

    class ModulesWithTheBrowserTestsTogether(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            if not module.startswith("tests/e2e/"):
                return module
            return "tests/e2e/ (demo)" if module.endswith(DEMO_BROWSER_MODULES) else "tests/e2e/"

    return ModulesWithTheBrowserTestsTogether(config, log)
