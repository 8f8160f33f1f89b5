"""A gable house at Parker's Piece, Cambridge (EPSG:27700), measured by noisy rays.

The truth is set in the grid (E, N, H; H = WGS 84 ellipsoidal height, as gsgeo reports
without a vertical datum): a 12 m x 8 m footprint turned 30 degrees, eaves 6 m above the
ground, the ridge 3 m higher along the long axis: volume 12 * 8 * 6 + 12 * 8 * 3 / 2 = 720 m^3.
Its corners are taken to ECEF through gsgeo's own grid path backwards, and each is aimed at
from four cameras 25-40 m away with 0.5 px of aiming noise (ifov 1 mrad).
"""

from __future__ import annotations

import numpy as np
from georef_helpers import aim

from gsgeo.georef.control import grid_to_ecef
from gsgeo.measure import SolveSettings

CRS = "EPSG:27700"
ORIGIN = (545_400.0, 258_100.0)  # E, N of the house's first corner
GROUND = 52.0  # H of the ground, metres
EAVES = 6.0  # eaves above the ground, metres
RIDGE = 3.0  # ridge above the eaves, metres
LENGTH, WIDTH = 12.0, 8.0
TURN_DEG = 30.0
VOLUME = LENGTH * WIDTH * EAVES + LENGTH * WIDTH * RIDGE / 2  # 720 m^3

#: Roof faces of the gable house as rings of point ids (shared ridge R1-R2).
ROOFS = [["E1", "E2", "R2", "R1"], ["E3", "E4", "R1", "R2"]]


def truth() -> dict[str, np.ndarray]:
    """Point id -> true E, N, H of the roof corners."""
    local = {"E1": (0.0, 0.0, EAVES), "E2": (LENGTH, 0.0, EAVES),
             "E3": (LENGTH, WIDTH, EAVES), "E4": (0.0, WIDTH, EAVES),
             "R1": (0.0, WIDTH / 2, EAVES + RIDGE), "R2": (LENGTH, WIDTH / 2, EAVES + RIDGE)}
    t = np.radians(TURN_DEG)
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    out = {}
    for pid, (x, y, z) in local.items():
        e, n = rot @ np.array([x, y]) + np.asarray(ORIGIN)
        out[pid] = np.array([e, n, GROUND + z])
    return out


def house_points(seed: int = 7, sigma_px: float = 0.5) -> list[dict]:
    """Session-JSON points (id, rays) of the house's roof corners, noisy rays."""
    rng = np.random.default_rng(seed)
    t = truth()
    ids = list(t)
    ecef = grid_to_ecef(np.array([t[i] for i in ids]), SolveSettings(crs=CRS))
    points = []
    for pid, x in zip(ids, ecef, strict=True):
        rays = aim(rng, x, x / np.linalg.norm(x), rng.uniform(25, 40), n=4, sigma_px=sigma_px)
        points.append({"id": pid, "rays": rays})
    return points


def house_session(**building: object) -> dict:
    """A session with the house's points and the building B1 (fields overridable)."""
    b = {"id": "B1", "roofs": ROOFS, "ground": GROUND,
         "attributes": {"function": "residential"}} | building
    return {"crs": CRS, "points": house_points(), "buildings": [b]}
