"""The demo projects: 'demo' (the demo scene, EPSG:27700, the ground truth as check points)
and 'demo-local' (the local variant, its control and check points with stated sigmas)."""

from __future__ import annotations

import os
from pathlib import Path

from gsgeo.demo import place
from gsgeo.demo.build import SCENE_NAME, DemoBuild
from gsgeo.demo.localbuild import SCENE_NAME as LOCAL_SCENE_NAME
from gsgeo.demo.localbuild import LocalBuild
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
        rows = [CheckPointRow(t.id, t.easting, t.northing, t.height, description=t.description)
                for t in truth_points()]
        # a rebuild states the same truth again: its ids are replaced by name, not refused
        n = projects.add_check_points(project.id, rows, place.CRS,
                                      source=f"gsgeo demo ground truth ({build.checkpoints_csv.name})",
                                      overwrite=[r.id for r in rows])
    finally:
        store.close()
    return project, n


LOCAL_PROJECT_ID = "demo-local"
LOCAL_PROJECT_NAME = "Demo, local frame: Parker's Piece before georeferencing"
LOCAL_DESCRIPTION = ("The demo scene as a 3DGS trainer leaves it: in an arbitrary local frame "
                     "(scaled, turned, shifted), not georeferenced (gsgeo demo --local). "
                     "Georeference it with its six control points (G2, G3, G4, R1, T3, T4): "
                     "measure each and name the point after it, then fit and apply in the "
                     "Georeference panel; the other 14 markers are check points.")


def ensure_local_project(data_dir: str | os.PathLike, build: LocalBuild) -> tuple[Project, int, int]:
    """Create the project 'demo-local' on the local scene if it is missing (an existing one
    keeps its points) and import the build's control file (role control) and check-point
    file (role check), with their stated sigmas, as a user would (updated by id).
    Returns (project, control, check)."""
    store = open_store(Path(data_dir))
    try:
        projects = Projects(store, Path(data_dir))
        try:
            project = projects.get_project(LOCAL_PROJECT_ID)
        except NotFoundError:
            project = projects.create_project(name=LOCAL_PROJECT_NAME, id=LOCAL_PROJECT_ID,
                                              description=LOCAL_DESCRIPTION,
                                              scene=LOCAL_SCENE_NAME, crs=place.CRS, sigma_px=1.0)
        truth_ids = [t.id for t in place.truth_points()]  # a rebuild replaces its own points
        counts = [projects.import_check_point_file(project.id, path.read_bytes(), path.name,
                                                   crs=place.CRS, role=role,
                                                   overwrite=truth_ids)[0]
                  for role, path in (("control", build.control_csv),
                                     ("check", build.checkpoints_csv))]
    finally:
        store.close()
    return project, counts[0], counts[1]


def remeasure_scene(data_dir: str | os.PathLike, scene: str) -> int:
    """Solve every point of every project on ``scene`` again in the scene's current frame
    (after a rebuild put the scene back where it is tiled: each point's rays are carried
    from the frame they were taken under, so the points stay on their features). Returns
    the number of points."""
    store = open_store(Path(data_dir))
    try:
        projects = Projects(store, Path(data_dir))
        n = 0
        for p in projects.list_projects():
            if p.scene == scene and projects.list_points(p.id):
                projects.remeasure_all(p.id)
                n += len(projects.list_points(p.id))
    finally:
        store.close()
    return n
