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


#: Modules that took 12 s or more of one worker in a whole run (worker-seconds, fresh clone,
#: 2026-11-28, db3c3ba), slowest first. They are handed out first so that the run does not end
#: on one worker with a long module while the other waits (the run was 42 s longer than half
#: its worker-seconds). A module not listed keeps its place after them; the list needs no
#: precision, only the order of the large ones.
SLOW_MODULES = (
    "test_server_api_postgres.py", "test_types.py", "test_server_live.py", "test_report.py",
    "test_report_hardening.py", "test_ogc_api.py", "test_buildings_api.py",
    "test_concurrency.py", "test_accounts.py", "test_server_api.py", "test_tiles_real.py",
    "test_crs_layout.py", "test_qgis_plugin.py", "test_server_hardening.py",
    "test_demo_local.py", "test_serve_postgres.py", "test_cli_fuzz.py",
    "test_buildings_calibration.py", "test_server_files.py",
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The browser tests (tests/e2e/) first: the worker that takes them starts with them
    (the longest part, about 560 s), the other one with the other modules. Then the
    SLOW_MODULES, slowest first, then the rest. The order within a module is kept. The
    scheduler hands modules out in this order (pytest_xdist_make_scheduler).

    Both workers run at the same priority. With the other worker at nice 19 (kept from the
    SwiftShader days, when the browser beside a busy worker took 2-4 times its time) the
    browser tests were no faster under llvmpipe (578 s against 544 s beside an equal worker)
    and the run took 802 s instead of 715-730 s (2026-11-28)."""
    slow = {name: rank for rank, name in enumerate(SLOW_MODULES)}

    def rank(item: pytest.Item) -> tuple[int, int]:
        if "e2e" in item.path.parts:
            return (0, 0)
        return (1, slow.get(item.path.name, len(slow)))

    items.sort(key=rank)


@pytest.hookimpl(trylast=True)  # after the module's own fixtures (its pages) are gone
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None) -> None:
    """After the last browser test of this process, Chromium and Playwright are stopped
    (tests/e2e/shared.py: stop_browser): the modules after them on the same worker call
    asyncio.run(), which Playwright's running loop refuses."""
    if "e2e" in item.path.parts and (nextitem is None or "e2e" not in nextitem.path.parts):
        from tests.e2e.shared import stop_browser

        stop_browser()


def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object:
    """pytest-xdist's scheduler for the suite (pyproject.toml's addopts: two workers): every
    test module whole on one worker (its module fixtures, servers and demo builds among them,
    made once), and the browser tests (tests/e2e/) all together on one worker: they share one
    Chromium, one demo and one box scene (tests/e2e/shared.py). Split in two groups on the
    two workers they took 1 480 worker-seconds instead of about 600 alone (two SwiftShaders
    on two cores, the renderer then), and the run was no shorter. They are collected first
    (pytest_collection_modifyitems), so one worker starts with them.
    (xdist's own ``--dist loadgroup`` marks do not reach it under pytest 9.2: the group is
    written into a node id that pytest no longer reads.)"""
    from xdist.scheduler import LoadScopeScheduling

    # xdist's default reorders the modules by their number of tests, which put the browser
    # tests (30 tests) behind a dozen modules and the long modules anywhere.
    config.option.loadscopereorder = False

    class ModulesWithTheBrowserTestsTogether(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return "tests/e2e/" if module.startswith("tests/e2e/") else module

    return ModulesWithTheBrowserTestsTogether(config, log)
