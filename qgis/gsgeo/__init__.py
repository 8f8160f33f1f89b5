"""gsgeo for QGIS: a project's layers from a gsgeo server, live, and the measuring view.

The plugin talks to the server over HTTP only (the JSON API under /api and OGC API - Features
under /ogc); it imports nothing from the gsgeo Python package.
"""

from __future__ import annotations

from typing import Any


def classFactory(iface: Any) -> Any:
    """QGIS's entry point: the plugin object for the running QGIS interface."""
    from .plugin import GsgeoPlugin

    return GsgeoPlugin(iface)
