"""Synthetic buildings for the tests of gsgeo.buildings: true corners, noisy measurements."""

from __future__ import annotations

import numpy as np

#: Where the test buildings stand (British National Grid, metres) and the ground height.
OFFSET = np.array([545400.0, 258100.0, 0.0])
GROUND = 10.0

#: Gable house 12 m x 8 m, eaves at 6 m, ridge 3 m higher (along E, at N = 4): 720 m³.
GABLE = {"E1": (0, 0, 6), "E2": (12, 0, 6), "R2": (12, 4, 9), "R1": (0, 4, 9),
         "E3": (12, 8, 6), "E4": (0, 8, 6)}
GABLE_ROOFS = [["E1", "E2", "R2", "R1"], ["E3", "E4", "R1", "R2"]]
GABLE_VOLUME = 12 * 8 * 6 + 0.5 * 8 * 3 * 12

#: Hip roof over 12 m x 8 m, eaves at 6 m, ridge 3 m higher from E = 4 to E = 8: volume
#: 576 + 3 * (8 * 12 / 3 + 8 * 4 / 6) ... computed by HIP_VOLUME.
HIP = {"E1": (0, 0, 6), "E2": (12, 0, 6), "E3": (12, 8, 6), "E4": (0, 8, 6),
       "R1": (4, 4, 9), "R2": (8, 4, 9)}
HIP_ROOFS = [["E1", "E2", "R2", "R1"], ["E2", "E3", "R2"], ["E3", "E4", "R1", "R2"],
             ["E4", "E1", "R1"]]
# Prism under the eaves + the roof: a central prism (4 m long, triangle 8 x 3) and a
# pyramid-like end of 4 m on each side (two half-cones of a triangle: volume base*h/3).
HIP_VOLUME = 12 * 8 * 6 + 0.5 * 8 * 3 * 4 + 2 * (8 * 4 * 3 / 3)


def measured(truth: dict[str, tuple[float, float, float]], sigma: float | dict[str, float],
             rng: np.random.Generator, ground: float = GROUND,
             ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Points id -> (E, N, H grid with noise, covariance m²): true corners + N(0, sigma²)."""
    out = {}
    for k, v in truth.items():
        s = sigma[k] if isinstance(sigma, dict) else sigma
        xyz = np.asarray(v, dtype=float) + OFFSET + np.array([0.0, 0.0, ground])
        out[k] = (xyz + rng.normal(0.0, s, 3), np.eye(3) * s * s)
    return out


def true_grid(truth: dict[str, tuple[float, float, float]], ground: float = GROUND
              ) -> dict[str, np.ndarray]:
    """The true corners in grid coordinates."""
    return {k: np.asarray(v, dtype=float) + OFFSET + np.array([0.0, 0.0, ground])
            for k, v in truth.items()}
