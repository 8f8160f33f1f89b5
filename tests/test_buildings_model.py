"""LoD2 models from measured roof points: gable, hip, flat + pitched, refusals, topology."""

from __future__ import annotations

import numpy as np
import orjson
import pytest
from buildings_helpers import (
    GABLE,
    GABLE_ROOFS,
    GABLE_VOLUME,
    GROUND,
    HIP,
    HIP_ROOFS,
    HIP_VOLUME,
    measured,
    true_grid,
)

from gsgeo.buildings.model import build_building
from gsgeo.buildings.solidcheck import solid_problems
from gsgeo.buildings.spec import parse_building
from gsgeo.errors import GeometryError, InputError
from gsgeo.solve.intersection import intersect
from gsgeo.solve.simulate import aim_with_noise


def spec(roofs, ground=GROUND, **extra):
    return parse_building({"id": "B1", "roofs": roofs, "ground": ground, **extra})


def roof_vertex(model, pid):
    return model.vertices[model.vertex_ids.index(pid)]


def kinds(model):
    return [s.kind for s in model.surfaces]


def test_a_noisy_gable_house_gives_the_true_solid():
    rng = np.random.default_rng(7)
    model = build_building(spec(GABLE_ROOFS), measured(GABLE, 0.02, rng))
    assert abs(model.measures["volume"] - GABLE_VOLUME) < 0.02 * GABLE_VOLUME
    truth = true_grid(GABLE)
    for pid, xyz in truth.items():
        assert np.linalg.norm(roof_vertex(model, pid) - xyz) < 0.05, pid
    assert kinds(model).count("RoofSurface") == 2
    assert kinds(model).count("GroundSurface") == 1
    walls = [s for s in model.surfaces if s.kind == "WallSurface"]
    assert sorted(len(s.ring) for s in walls) == [4, 4, 5, 5]  # gable walls are pentagons
    gables = [s for s in walls if len(s.ring) == 5]
    for s in gables:
        names = {model.vertex_ids[i] for i in s.ring}
        assert names & {"R1", "R2"}
    assert solid_problems(model.vertices - model.vertices.mean(axis=0),
                          [s.ring for s in model.surfaces]) == []
    assert model.measures["roof_type"] == "gable"
    assert abs(model.measures["eaves_height"] - (GROUND + 6)) < 0.03
    assert abs(model.measures["ridge_height"] - (GROUND + 9)) < 0.03
    assert abs(model.measures["measured_height"] - 9) < 0.03
    assert abs(model.measures["footprint_area"] - 96) < 0.02 * 96
    for s in model.measures["roof_slopes"]:
        assert abs(s["slope_deg"] - np.degrees(np.arctan2(3, 4))) < 1.0
    doc = model.to_dict()
    assert orjson.loads(orjson.dumps(doc)) == doc  # plain JSON types, nothing numpy


def rays_to(rng, target, n=5, ifov=5e-4, sigma_px=1.0):
    """A point measured as the operator does: n noisy rays from cameras 20-60 m away, 20-70
    degrees up, intersected by gsgeo's solver (point and covariance in the grid frame)."""
    az = rng.uniform(0, 2 * np.pi, n)
    el = np.radians(rng.uniform(20, 70, n))
    r = rng.uniform(20, 60, n)
    offsets = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=1)
    origins = target + offsets * r[:, None]
    directions = aim_with_noise(rng, -offsets, ifov, sigma_px)
    res = intersect(origins, directions, ifov=ifov, sigma_px=sigma_px)
    return res.point, res.covariance


def test_a_gable_house_measured_by_noisy_rays():
    rng = np.random.default_rng(1)
    truth = true_grid(GABLE)
    pts = {k: rays_to(rng, v) for k, v in truth.items()}
    model = build_building(spec(GABLE_ROOFS), pts)
    assert abs(model.measures["volume"] - GABLE_VOLUME) < 0.02 * GABLE_VOLUME
    for pid, xyz in truth.items():
        assert np.linalg.norm(roof_vertex(model, pid) - xyz) < 0.05, pid
    assert kinds(model).count("RoofSurface") == 2 and kinds(model).count("GroundSurface") == 1
    assert model.warnings == []
    assert model.adjustment["p"] > 0.001


def test_every_adjusted_face_is_planar_and_shared_ids_are_one_vertex():
    rng = np.random.default_rng(3)
    model = build_building(spec(GABLE_ROOFS), measured(GABLE, 0.03, rng))
    # one vertex per id: the ridge ends R1, R2 are on both roof faces and a gable wall
    assert len(set(model.vertex_ids)) == len(model.vertex_ids)
    index = {p: k for k, p in enumerate(model.vertex_ids)}
    for ring in GABLE_ROOFS:
        uses = [s for s in model.surfaces if s.kind == "RoofSurface"
                and set(s.ring) == {index[p] for p in ring}]
        assert len(uses) == 1
    for kind, xyz in model.surface_rings():
        c = xyz - xyz.mean(axis=0)
        assert np.linalg.svd(c)[1][-1] < 1e-6, kind
    faces = model.adjustment["faces"]
    assert [f["points"] for f in faces] == GABLE_ROOFS
    assert all(f["dof"] == 1 and 0 <= f["p"] <= 1 and f["rms"] < 0.1 for f in faces)
    assert set(model.adjustment["corrections"]) == set(GABLE)


def test_a_roof_naming_an_unknown_point_is_refused_naming_it():
    rng = np.random.default_rng(1)
    pts = measured(GABLE, 0.02, rng)
    del pts["R2"]
    with pytest.raises(InputError) as err:
        build_building(spec(GABLE_ROOFS), pts)
    assert err.value.field == "roofs"
    assert "'R2'" in err.value.problem and "unknown point" in err.value.problem


def test_a_non_planar_face_is_refused_naming_face_and_worst_point():
    rng = np.random.default_rng(2)
    pts = measured(GABLE, 0.01, rng)
    xyz, cov = pts["E2"]
    pts["E2"] = (xyz + np.array([0.0, 0.0, 0.4]), cov)  # 40 cm above the south face's plane
    with pytest.raises(GeometryError) as err:
        build_building(spec(GABLE_ROOFS), pts)
    msg = str(err.value)
    assert "roof face 0 (E1, E2, R2, R1) is not planar" in msg
    assert "worst: point" in msg
    assert err.value.field == "roofs[0]"


def test_the_worst_point_is_the_one_that_is_off():
    truth = {**GABLE, "M": (6, 0, 6)}  # a fifth point of the south face, mid-eave
    roofs = [["E1", "M", "E2", "R2", "R1"], ["E3", "E4", "R1", "R2"]]
    rng = np.random.default_rng(5)
    pts = measured(truth, 0.01, rng)
    xyz, cov = pts["M"]
    pts["M"] = (xyz + np.array([0.0, 0.0, -0.5]), cov)
    with pytest.raises(GeometryError, match=r"worst: point M is"):
        build_building(spec(roofs), pts)


def test_a_hip_roof():
    rng = np.random.default_rng(11)
    model = build_building(spec(HIP_ROOFS), measured(HIP, 0.015, rng))
    assert abs(model.measures["volume"] - HIP_VOLUME) < 0.02 * HIP_VOLUME
    for pid, xyz in true_grid(HIP).items():
        assert np.linalg.norm(roof_vertex(model, pid) - xyz) < 0.05, pid
    assert kinds(model).count("RoofSurface") == 4
    walls = [s for s in model.surfaces if s.kind == "WallSurface"]
    assert sorted(len(s.ring) for s in walls) == [4, 4, 4, 4]
    assert model.measures["roof_type"] == "hip"
    assert abs(model.measures["ridge_height"] - (GROUND + 9)) < 0.03


def test_points_without_covariance_get_a_default_sigma_and_a_warning():
    rng = np.random.default_rng(4)
    pts = {k: (v[0], None) for k, v in measured(GABLE, 0.01, rng).items()}
    model = build_building(spec(GABLE_ROOFS), pts)
    assert any("without a covariance" in w and "0.05 m" in w for w in model.warnings)


def test_a_crs_in_feet_gives_metric_volume_and_heights_in_feet():
    ft = 0.3048006096012192  # US survey foot
    rng = np.random.default_rng(6)
    pts = {k: (xyz / ft, cov) for k, (xyz, cov) in measured(GABLE, 0.01, rng).items()}
    spec_ft = parse_building({"id": "B1", "roofs": GABLE_ROOFS, "ground": GROUND / ft})
    model = build_building(spec_ft, pts, unit_m=ft, vertical_unit_m=ft)
    assert abs(model.measures["volume"] - GABLE_VOLUME) < 0.01 * GABLE_VOLUME  # m³
    assert abs(model.measures["footprint_area"] - 96) < 0.01 * 96  # m²
    assert abs(model.measures["measured_height"] - 9 / ft) < 0.05 / ft  # CRS units (feet)
    assert abs(model.measures["sigma_ridge_height"] * ft - 0.01 / np.sqrt(2)) < 0.005
    for s in model.measures["roof_slopes"]:
        assert abs(s["slope_deg"] - np.degrees(np.arctan2(3, 4))) < 1.0


@pytest.mark.parametrize("change, needle", [
    (lambda xyz, cov: (xyz * 1e150, cov), "lies outside any grid"),
    (lambda xyz, cov: (xyz, np.array([[1, 2, 0], [2, 1, 0], [0, 0, 1.0]]) * 1e-4),
     "not positive semi-definite"),
    (lambda xyz, cov: (xyz, cov * 1e210), "is no measurement"),
    (lambda xyz, cov: (xyz, np.full((3, 3), np.nan)), "not finite"),
    (lambda xyz, cov: (np.array([xyz[0], xyz[1], np.nan]), cov), "has no height"),
    (lambda xyz, cov: ([1.0, 2.0], cov), "no usable coordinates"),
])
def test_unusable_points_are_refused_naming_them(change, needle):
    pts = measured(GABLE, 0.01, np.random.default_rng(1))
    pts["R1"] = change(*pts["R1"])
    with pytest.raises(InputError, match=needle) as err:
        build_building(spec(GABLE_ROOFS), pts)
    assert "'R1'" in err.value.problem or "'E1'" in err.value.problem
    assert err.value.field == "roofs"


def test_a_building_kilometres_wide_is_refused():
    pts = measured(GABLE, 0.01, np.random.default_rng(1))
    xyz, cov = pts["E2"]
    pts["E2"] = (xyz + np.array([30000.0, 0, 0]), cov)
    with pytest.raises(InputError, match="a building is at most"):
        build_building(spec(GABLE_ROOFS), pts)


def test_an_absurd_ground_is_refused_as_input():
    pts = measured(GABLE, 0.01, np.random.default_rng(1))
    with pytest.raises(InputError, match="sigma must be between") as err:
        build_building(spec(GABLE_ROOFS), pts, ground_height=GROUND, ground_sigma=1e300)
    assert err.value.field == "ground"
    with pytest.raises(InputError, match="not a finite number") as err:
        build_building(spec(GABLE_ROOFS), pts, ground_height=1e300)
