"""OGC API – Features at /ogc (gsgeo.server.ogc.routes), its OpenAPI definition and HTML views."""

from gsgeo.server.ogc.routes import router

__all__ = ["router"]
