"""The demo project: the demo scene, EPSG:27700, and the ground truth as check points."""

from __future__ import annotations

import os
from pathlib import Path

from gsgeo.demo import place
from gsgeo.demo.build import SCENE_NAME, DemoBuild
from gsgeo.service import NotFoundError, Project, Projects, open_store
from gsgeo.service.checkpoints import CheckPointRow

PROJECT_ID = "demo"
PROJECT_NAME = "Demo: Parker's Piece (synthetic scene with ground truth)"
DESCRIPTION = ("Synthetic 3DGS scene with 20 surveyed validation points (gsgeo demo). Name a "
               "measured point after its marker (G1-G4, R1 targets; B1-B6 building corners; "
               "T1-T5 pole and post tops; S1-S4 sculpture corners) to compare it with the truth.")


def ensure_project(data_dir: str | os.PathLike, build: DemoBuild) -> tuple[Project, int]:
    """Create the demo project if it is missing (an existing one keeps its points) and store
    the ground truth as its check points (updated by id). Returns (project, check points)."""
    from gsgeo.demo.place import truth_points

    store = open_store(Path(data_dir))
    try:
        projects = Projects(store, Path(data_dir))
        try:
            project = projects.get_project(PROJECT_ID)
        except NotFoundError:
            project = projects.create_project(name=PROJECT_NAME, id=PROJECT_ID,
                                              description=DESCRIPTION, scene=SCENE_NAME,
                                              crs=place.CRS, sigma_px=1.0)
        rows = [CheckPointRow(t.id, t.easting, t.northing, t.height) for t in truth_points()]
        n = projects.add_check_points(project.id, rows, place.CRS,
                                      source=f"gsgeo demo ground truth ({build.checkpoints_csv.name})")
    finally:
        store.close()
    return project, n
