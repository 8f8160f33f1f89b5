"""An empty map takes the gsgeo project's grid CRS and its layers' extent.

In the project's grid the map shows E, N as gsgeo reports them and the error ellipses turn
by exactly the grid bearing the server gives.
"""

from __future__ import annotations

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsCoordinateTransform,
    QgsProject,
    QgsRectangle,
    QgsVectorLayer,
)
from qgis.gui import QgsMapCanvas


def frame_map(canvas: QgsMapCanvas, crs: str | None, layers: list[QgsVectorLayer],
              project: QgsProject | None = None) -> None:
    """Set the QGIS project's CRS to ``crs`` (the gsgeo project's grid, when it has one QGIS
    knows) and show the valid ``layers``' extent on ``canvas``."""
    project = project or QgsProject.instance()
    grid = QgsCoordinateReferenceSystem(crs) if crs else QgsCoordinateReferenceSystem()
    if grid.isValid():
        project.setCrs(grid)
        canvas.setDestinationCrs(grid)
    target = canvas.mapSettings().destinationCrs()
    extent = QgsRectangle()
    for layer in layers:
        if not layer.isValid() or layer.extent().isEmpty():
            continue
        xf = QgsCoordinateTransform(layer.crs(), target, project)
        box = xf.transformBoundingBox(layer.extent())
        if extent.isEmpty():
            extent = box
        else:
            extent.combineExtentWith(box)
    if not extent.isEmpty():
        extent.scale(1.1)
        canvas.setExtent(extent)
        canvas.refresh()
