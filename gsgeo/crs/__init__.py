"""gsgeo.crs: frames (ECEF <-> ENU), grid output with covariance,
vertical datums and the measurement pipeline. Knows PROJ, never HTTP.

PROJ never uses the network from gsgeo: every module that uses pyproj imports
gsgeo.crs.resolve, which sets PROJ_NETWORK=OFF on import (tests/test_crs_ellipsoid.py checks
this).
Importing the package alone loads no PROJ, so gsgeo.crs.ellipsoid (numpy only) is cheap.
"""

from importlib import import_module

# Names are loaded on first use (PEP 562): importing one submodule, e.g. gsgeo.crs.frames for
# `gsgeo tiles`, then does not load the measurement pipeline and everything it needs.
_WHERE = {
    "EnuFrame": "frames", "ecef_to_geodetic": "frames", "enu_rotation": "frames",
    "geodetic_to_ecef": "frames",
    "GridPoint": "grid", "GridPoints": "grid", "analytic_jacobian": "grid", "to_grid": "grid",
    "to_grid_many": "grid",
    "Measurement": "pipeline", "MeasurementFailure": "pipeline", "measure_point": "pipeline",
    "measure_session": "pipeline",
    "disable_network": "resolve", "grid_crs": "resolve", "parse_crs": "resolve",
    "source_crs": "resolve",
}


def __getattr__(name: str):
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
    "Measurement",
    "MeasurementFailure",
    "analytic_jacobian",
    "disable_network",
    "ecef_to_geodetic",
    "enu_rotation",
    "geodetic_to_ecef",
    "grid_crs",
    "measure_point",
    "measure_session",
    "parse_crs",
    "source_crs",
    "to_grid",
    "to_grid_many",
]
