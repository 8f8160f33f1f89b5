"""The map tool "open the measuring view here": the gsgeo web viewer on the project's scene,
looking at the clicked place.

The viewer takes ``?scene=NAME&project=ID&lon=DEG&lat=DEG`` (WGS 84 degrees) and the token
in the fragment (``#token=``, never sent to the server in the URL's query or logs).
"""

from __future__ import annotations

import urllib.parse
from collections.abc import Callable

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsCoordinateTransform,
    QgsPointXY,
    QgsProject,
)
from qgis.gui import QgsMapCanvas, QgsMapToolEmitPoint
from qgis.PyQt.QtCore import Qt

from .client import Connection

WGS84 = QgsCoordinateReferenceSystem("EPSG:4326")


def viewer_url(connection: Connection, scene: str | None, pid: str, lon: float,
               lat: float) -> str:
    """The viewer's URL on ``scene`` (the project's own when None) looking at lon, lat."""
    q = {"project": pid, "lon": f"{lon:.8f}", "lat": f"{lat:.8f}"}
    if scene:
        q = {"scene": scene, **q}
    url = f"{connection.base}/?{urllib.parse.urlencode(q)}"
    if connection.token.strip():
        url += "#token=" + urllib.parse.quote(connection.token.strip(), safe="")
    return url


def to_wgs84(point: QgsPointXY, crs: QgsCoordinateReferenceSystem) -> QgsPointXY:
    """``point`` from ``crs`` (the map's) to longitude, latitude in degrees."""
    xf = QgsCoordinateTransform(crs, WGS84, QgsProject.instance())
    return xf.transform(point)


class OpenViewerTool(QgsMapToolEmitPoint):
    """A left click calls ``on_place(lon, lat)`` with the clicked place in degrees."""

    def __init__(self, canvas: QgsMapCanvas, on_place: Callable[[float, float], object]) -> None:
        super().__init__(canvas)
        self.on_place = on_place
        self.canvasClicked.connect(self.clicked)

    def clicked(self, point: QgsPointXY, button: Qt.MouseButton) -> None:
        if button != Qt.MouseButton.LeftButton:
            return
        p = to_wgs84(point, self.canvas().mapSettings().destinationCrs())
        self.on_place(p.x(), p.y())
