"""ENU frames and the modelMatrix: round trips, rotation consistency, hand-computed geometry."""

from __future__ import annotations

import numpy as np
import pytest
from crs_helpers import rotation

from gsgeo.crs.frames import EnuFrame, ecef_to_geodetic, enu_rotation, geodetic_to_ecef
from gsgeo.crs.modelmatrix import (
    column_major,
    invert_affine,
    is_similarity,
    matrix4,
    rendered_to_georeferenced,
)
from gsgeo.errors import InputError

ORIGINS = [(-83.02341, 40.01609, 0.0), (-1.5, 52.5, 80.0), (151.2, -33.8, 30.0),
           (179.9, 0.1, -20.0), (10.0, 89.5, 2000.0)]


@pytest.mark.parametrize(("lon", "lat", "h"), ORIGINS)
@pytest.mark.parametrize("source", ["EPSG:4978", "EPSG:4936"])
def test_round_trip_within_10_km(lon, lat, h, source, rng):
    f = EnuFrame.from_geodetic(lon, lat, h, source)
    enu = np.column_stack([rng.uniform(-1e4, 1e4, 2000), rng.uniform(-1e4, 1e4, 2000),
                           rng.uniform(-500, 3000, 2000)])
    ecef = f.to_ecef(enu)
    assert np.abs(f.to_enu(ecef) - enu).max() < 1e-6
    assert np.abs(f.to_ecef(f.to_enu(ecef)) - ecef).max() < 1e-6
    # hand-computed: ENU = R (X - X0), R from the origin's latitude and longitude
    np.testing.assert_allclose(enu, (ecef - f.origin_ecef) @ f.rotation.T, atol=1e-6)


@pytest.mark.parametrize(("lon", "lat", "h"), ORIGINS)
def test_direction_rotation_consistent_with_point_conversion(lon, lat, h, rng):
    f = EnuFrame.from_geodetic(lon, lat, h)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    base = f.origin_ecef + rng.uniform(-5000, 5000, (500, 3))
    s = 1000.0
    via_points = (f.to_enu(base + s * d) - f.to_enu(base)) / s
    assert np.abs(via_points - f.directions_to_enu(d)).max() < 1e-9
    assert np.abs(f.directions_to_ecef(f.directions_to_enu(d)) - d).max() < 1e-12


@pytest.mark.parametrize(("lon", "lat", "h"), ORIGINS)
def test_axes_are_east_north_and_the_ellipsoid_normal(lon, lat, h):
    r = enu_rotation(lon, lat)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(r) == pytest.approx(1.0)
    p = geodetic_to_ecef(lon, lat, h)
    up = geodetic_to_ecef(lon, lat, h + 1.0) - p  # the ellipsoid normal, independently
    north = geodetic_to_ecef(lon, lat + 1e-5, h) - geodetic_to_ecef(lon, lat - 1e-5, h)
    east = geodetic_to_ecef(lon + 1e-5, lat, h) - geodetic_to_ecef(lon - 1e-5, lat, h)
    np.testing.assert_allclose(r[2], up / np.linalg.norm(up), atol=1e-9)
    np.testing.assert_allclose(r[1], north / np.linalg.norm(north), atol=1e-9)
    if abs(lat) < 89:
        np.testing.assert_allclose(r[0], east / np.linalg.norm(east), atol=1e-9)


def test_origin_and_covariance_round_trip(rng):
    f = EnuFrame.from_geodetic(-1.5, 52.5, 80.0)
    lon, lat, h = ecef_to_geodetic(f.origin_ecef)
    assert (float(lon), float(lat), float(h)) == pytest.approx((-1.5, 52.5, 80.0), abs=1e-9)
    np.testing.assert_allclose(f.to_enu(f.origin_ecef), 0.0, atol=1e-8)
    a = rng.normal(size=(3, 3))
    c = a @ a.T
    np.testing.assert_allclose(f.covariance_to_enu(f.covariance_to_ecef(c)), c, atol=1e-12)
    # the variance along the up axis is the ECEF covariance projected on the normal
    ce = f.covariance_to_ecef(c)
    assert f.rotation[2] @ ce @ f.rotation[2] == pytest.approx(c[2, 2])


def test_bad_origin():
    with pytest.raises(InputError, match="geocentre"):
        EnuFrame([0.0, 1.0, 2.0])
    with pytest.raises(InputError, match="finite"):
        EnuFrame([np.nan, 0, 6.4e6])


def test_model_matrix_is_column_major_and_inverts_rays(rng):
    m16 = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 10, 20, 30, 1]  # translation (10, 20, 30)
    m = matrix4(m16)
    assert m[:3, 3].tolist() == [10, 20, 30]
    assert column_major(m) == [float(v) for v in m16]
    lin = 1.002 * rotation([1, 2, 3], 0.3)
    m = np.eye(4)
    m[:3, :3] = lin
    m[:3, 3] = [5.0, -7.0, 2.0]
    assert is_similarity(m)
    np.testing.assert_allclose(invert_affine(m) @ m, np.eye(4), atol=1e-12)
    target = np.array([6.4e6, 1e5, 2e5])
    o = target + rng.normal(0, 30, (4, 3))
    d = (target - o) / np.linalg.norm(target - o, axis=1, keepdims=True)
    o_r = o @ lin.T + m[:3, 3]
    d_r = d @ lin.T * 7.0  # rendered directions need not be unit length
    go, gd, similar = rendered_to_georeferenced(o_r, d_r, [column_major(m)] * 4)
    assert similar
    np.testing.assert_allclose(go, o, atol=1e-6)
    np.testing.assert_allclose(gd, d, atol=1e-12)
    shear = m.copy()
    shear[0, 1] += 0.1
    assert not rendered_to_georeferenced(o_r, d_r, [shear] * 4)[2]
    with pytest.raises(InputError, match="singular"):
        invert_affine(np.diag([1.0, 1.0, 0.0, 1.0]))
