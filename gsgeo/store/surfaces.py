"""The surfaces of a project's built LoD2 buildings, as a store that serves GIS keeps them.

A building is stored as given (its session-JSON form); its model is derived from the points.
A store whose database GIS clients read directly (PostgreSQL + PostGIS) also keeps the
model's surfaces, rewritten by the service in the transaction of every change that can move
them, so that a GIS layer can show buildings without running gsgeo's adjustment.
"""

from __future__ import annotations

from dataclasses import dataclass

from gsgeo.jsontypes import JSONObject


@dataclass
class BuildingSurface:
    """One surface of a building's LoD2 solid.

    ``values``: its columns (gsgeo.pointschema.BUILDING_TYPES; None where unknown);
    ``ring``: its open ring of (E, N, H) vertices in the project's grid CRS (CRS units),
    outward-facing as in the GeoPackage and CityJSON exports."""

    building_id: str
    surface_index: int
    values: JSONObject
    ring: list[tuple[float, float, float]]

    def wkt(self) -> str:
        """The surface as a closed ``POLYGON Z`` (exact: shortest round-trip decimals)."""
        pts = [*self.ring, self.ring[0]]
        return "POLYGON Z ((" + ", ".join(f"{x!r} {y!r} {z!r}" for x, y, z in pts) + "))"
