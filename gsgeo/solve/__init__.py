"""Multi-ray least-squares intersection in any Cartesian frame (pure numpy, no CRS)."""

from gsgeo.solve.intersection import (
    PARALLEL_LIMIT_DEG,
    WEAK_GEOMETRY_DEG,
    BatchResult,
    IntersectionResult,
    intersect,
    intersect_batch,
    intersection_angles,
)
from gsgeo.solve.stats import SCALE_95_1D, SCALE_95_2D, SCALE_95_3D

__all__ = [
    "PARALLEL_LIMIT_DEG",
    "SCALE_95_1D",
    "SCALE_95_2D",
    "SCALE_95_3D",
    "WEAK_GEOMETRY_DEG",
    "BatchResult",
    "IntersectionResult",
    "intersect",
    "intersect_batch",
    "intersection_angles",
]
