"""Aiming aids of a scene for the viewer: depth hint along a ray, suggested views, and the
match of a clicked feature in another rendered view (gsgeo.aim). Positions are in rendered
ECEF (metres), as the viewer's rays carry them; each ray's modelMatrix maps to the tileset.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gsgeo.aim.depth import depth_hint
from gsgeo.aim.splatindex import scene_index
from gsgeo.errors import InputError
from gsgeo.measure import Rays
from gsgeo.store import NotFoundError


def tileset_of(scene_dir: Path) -> Path:
    """The tileset.json of a scene folder; NotFoundError when it has none."""
    ts = Path(scene_dir) / "tileset.json"
    if not ts.is_file():
        raise NotFoundError(f"scene {Path(scene_dir).name!r} has no tileset.json")
    return ts


def depth_on_ray(scene_dir: Path, rays: Rays) -> dict[str, Any]:
    """The depth hint of the first of ``rays`` in the scene (gsgeo.aim.depth.depth_hint), as
    the JSON of POST /api/scenes/{scene}/depth."""
    if len(rays) < 1:
        raise InputError("one ray is needed", field="ray")
    ifov = None if rays.ifov is None else float(rays.ifov[0])
    index = scene_index(tileset_of(scene_dir))
    hint = depth_hint(index, rays.origins[0], rays.directions[0],
                      ifov if ifov == ifov else None, rays.model_matrix(0))
    return hint.to_json()
