"""The height-system text stored with every point (vertical_datum) names the datum once:
"ellipsoidal height on WGS 84 (EPSG:4979)", with the ellipsoid only where the datum's name
does not already say it."""

from __future__ import annotations

from gsgeo.crs.grid import to_grid

LONDON_ECEF = [3980000.0, -8000.0, 4966000.0]


def test_wgs84_ellipsoidal_height_names_the_datum_once():
    g = to_grid(LONDON_ECEF, None, "EPSG:27700")
    assert g.height_type == "ellipsoidal"
    assert g.vertical_datum == "ellipsoidal height on WGS 84 (EPSG:4979)"
    assert g.vertical_datum.count("WGS 84") == 1


def test_other_ellipsoid_is_named_where_the_datum_does_not_say_it():
    g = to_grid(LONDON_ECEF, None, "EPSG:27700", source_crs="EPSG:4936")
    assert g.vertical_datum == "ellipsoidal height on ETRS89 (EPSG:4937, ellipsoid GRS 1980)"
