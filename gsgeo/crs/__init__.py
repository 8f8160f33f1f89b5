"""gsgeo.crs: frames (ECEF <-> ENU), grid output with covariance and vertical datums.
Knows PROJ, never HTTP; the measurement pipeline that uses it is gsgeo.measure.

PROJ never uses the network from gsgeo: every CRS is parsed by gsgeo.crs.resolve.parse_crs
and every transformer built by gsgeo.crs.transformers, and both call
gsgeo.crs.resolve.network_off() first (tests/test_crs_ellipsoid.py checks this).
Importing the package alone loads no PROJ, so gsgeo.crs.ellipsoid (numpy only) is cheap.
"""

from importlib import import_module
from typing import Any

# Names are loaded on first use (PEP 562): importing one submodule, e.g. gsgeo.crs.frames for
# `gsgeo tiles`, then does not load PROJ and everything grid output needs.
_WHERE = {
    "EnuFrame": "frames", "ecef_to_geodetic": "frames", "enu_rotation": "frames",
    "geodetic_to_ecef": "frames",
    "GridPoint": "grid", "GridPoints": "grid", "analytic_jacobian": "grid", "to_grid": "grid",
    "to_grid_many": "grid",
    "network_off": "resolve", "grid_crs": "resolve", "parse_crs": "resolve",
    "source_crs": "resolve",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        value = getattr(import_module(f"gsgeo.crs.{_WHERE[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'gsgeo.crs' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(_WHERE))


__all__ = [
    "EnuFrame",
    "GridPoint",
    "GridPoints",
    "analytic_jacobian",
    "ecef_to_geodetic",
    "enu_rotation",
    "geodetic_to_ecef",
    "grid_crs",
    "network_off",
    "parse_crs",
    "source_crs",
    "to_grid",
    "to_grid_many",
]
