"""The typed core of gsgeo.measure: Rays (validated once, written back as session-JSON rays)
and SolveSettings."""

from __future__ import annotations

import numpy as np
import pytest
from servertools import london_rays

from gsgeo.errors import InputError
from gsgeo.measure import Rays, SolveSettings, measure_point
from gsgeo.session import parse_point

MM = [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 10.0, 20.0, 30.0, 1.0]


def test_to_json_is_the_session_json_ray_as_given():
    rays = london_rays(3)
    rays[0] |= {"ifov": 0.001, "pixel": [10.5, 20.0], "viewport": [800.0, 600.0],
                "model_matrix": MM}
    rays[1] |= {"ifov": 0.002}
    typed = parse_point({"id": "P", "rays": rays}, "").to_rays()
    assert typed.to_json() == rays  # members only where given, in the session's order
    assert list(typed.to_json()[0]) == ["origin", "direction", "ifov", "pixel", "viewport",
                                        "model_matrix"]
    np.testing.assert_array_equal(typed.model_matrix(0)[:3, 3], [10.0, 20.0, 30.0])
    assert typed.model_matrix(1) is None


@pytest.mark.parametrize(("change", "field", "words"), [
    ({"direction": [0.0, 0.0, 0.0]}, "rays[1].direction", "zero vector"),
    ({"origin": [1e10, 0.0, 0.0]}, "rays[1].origin", "out of range"),
    ({"ifov": 1.0}, "rays[1].ifov", "radians"),
    ({"model_matrix": [1.0] * 16}, "rays[1].model_matrix", "affine"),
])
def test_rays_validate_ranges_once_and_name_the_member(change, field, words):
    rays = london_rays(2)
    rays[1] |= change
    docs = [rays[0], rays[1]]
    with pytest.raises(InputError, match=words) as e:
        Rays.from_columns([r["origin"] for r in docs], [r["direction"] for r in docs],
                          [r.get("ifov") for r in docs],
                          model_matrices=[r.get("model_matrix") for r in docs])
    assert e.value.field == field
    with pytest.raises(InputError) as e2:  # the session reader reports it from the same check
        parse_point({"id": "P", "rays": docs}, "points[4]")
    assert e2.value.field == f"points[4].{field}"


def test_ifov_on_some_rays_only_is_refused_when_measuring():
    rays = london_rays(3)
    rays[0]["ifov"] = rays[2]["ifov"] = 0.001
    typed = parse_point({"id": "P", "rays": rays}, "").to_rays()
    with pytest.raises(InputError, match="no ifov on ray") as e:
        measure_point(typed, SolveSettings(), point_id="P")
    assert e.value.field == "rays[1].ifov"


def test_rays_are_read_only():
    typed = parse_point({"id": "P", "rays": london_rays(2)}, "").to_rays()
    with pytest.raises(ValueError):
        typed.origins[0, 0] = 0.0


def test_solve_settings_parse_checks_sigma_px():
    assert SolveSettings.parse(source_crs="", sigma_px=2).source_crs == "EPSG:4978"
    with pytest.raises(InputError) as e:
        SolveSettings.parse(sigma_px=1000)
    assert e.value.field == "sigma_px"
