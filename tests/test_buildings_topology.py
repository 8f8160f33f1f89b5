"""Topology from point ids: flat + pitched parts, vertical steps, regularisation, and clear
errors for overlapping, vertical, holed or broken roofs."""

from __future__ import annotations

import numpy as np
import pytest
from buildings_helpers import GABLE, GABLE_ROOFS, GABLE_VOLUME, GROUND, measured, true_grid
from cityjson_helpers import validate_city_json
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis_profiles import examples

from gsgeo.buildings.cityjson import city_json
from gsgeo.buildings.model import build_building, footprint_en
from gsgeo.buildings.solidcheck import solid_problems
from gsgeo.buildings.spec import parse_building
from gsgeo.errors import GeometryError, GsgeoError, InputError

BNG = "https://www.opengis.net/def/crs/EPSG/0/27700"


def build(roofs, truth, sigma=0.02, seed=1, **extra):
    spec = parse_building({"id": "B", "roofs": roofs, "ground": GROUND, **extra})
    return build_building(spec, measured(truth, sigma, np.random.default_rng(seed)))


def named_rings(model, kind):
    return [[model.vertex_ids[i] for i in s.ring] for s in model.surfaces if s.kind == kind]


def assert_valid(model):
    v = model.vertices - model.vertices.mean(axis=0)
    assert solid_problems(v, [s.ring for s in model.surfaces]) == []
    validate_city_json(city_json([model], BNG))


def test_a_flat_part_at_the_eaves_beside_the_pitched_part():
    truth = {**GABLE, "A1": (0, -4, 6), "A2": (12, -4, 6)}
    model = build(GABLE_ROOFS + [["A1", "A2", "E2", "E1"]], truth)
    assert abs(model.measures["volume"] - (GABLE_VOLUME + 12 * 4 * 6)) < 0.02 * GABLE_VOLUME
    assert model.measures["roof_type"] == "complex"
    walls = named_rings(model, "WallSurface")
    # the east wall runs A2 - E2 - R2 - E3 in one plane: one polygon, not three
    east = [w for w in walls if "R2" in w]
    assert len(east) == 1 and {"A2", "E2", "R2", "E3"} <= set(east[0])
    assert len(walls) == 4
    assert_valid(model)


def test_a_vertical_step_between_a_lower_flat_roof_and_the_pitched_eaves():
    truth = {**GABLE, "F1": (0, -4, 3), "F2": (12, -4, 3), "F3": (12, 0, 3), "F4": (0, 0, 3)}
    model = build(GABLE_ROOFS + [["F1", "F2", "F3", "F4"]], truth,
                  walls=[["F4", "F3", "E2", "E1"]])
    assert abs(model.measures["volume"] - (GABLE_VOLUME + 12 * 4 * 3)) < 0.02 * GABLE_VOLUME
    walls = named_rings(model, "WallSurface")
    # the given step wall, and the east wall with its step F3 -> E2 as ONE polygon
    assert ["F4", "F3", "E2", "E1"] in walls
    east = [w for w in walls if "R2" in w]
    assert len(east) == 1 and {"F2", "F3", "E2", "R2", "E3"} <= set(east[0])
    assert len(walls) == 5
    # the step is exactly vertical: F3 under E2, F4 under E1
    v = dict(zip(model.vertex_ids, model.vertices, strict=True))
    assert np.allclose(v["F3"][:2], v["E2"][:2], atol=1e-9)
    assert np.allclose(v["F4"][:2], v["E1"][:2], atol=1e-9)
    for pid, xyz in true_grid(truth).items():
        assert np.linalg.norm(v[pid] - xyz) < 0.05, pid
    # the flat roof's eaves do not count as the house's eaves
    assert abs(model.measures["eaves_height"] - (GROUND + 6)) < 0.03
    assert_valid(model)


def test_horizontal_eaves_and_a_rectangular_footprint():
    model = build(GABLE_ROOFS, GABLE, sigma=0.03, seed=4,
                  regularise=["horizontal_eaves", "rectangular"])
    v = dict(zip(model.vertex_ids, model.vertices, strict=True))
    heights = [v[p][2] for p in ("E1", "E2", "E3", "E4")]
    assert max(heights) - min(heights) < 1e-9
    corners = [v[p][:2] for p in ("E1", "E2", "E3", "E4")]
    for k in range(4):
        a = corners[(k + 1) % 4] - corners[k]
        b = corners[(k + 2) % 4] - corners[(k + 1) % 4]
        assert abs(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b)) < 1e-9
    assert abs(model.measures["volume"] - GABLE_VOLUME) < 0.02 * GABLE_VOLUME
    assert model.adjustment["dof"] == 4 + 3 + 3  # planarity, collinearity + eaves + angles
    assert_valid(model)


def test_rectangular_on_a_skewed_footprint_is_refused_naming_the_corner():
    truth = {**GABLE, "E2": (16, 0, 6), "R2": (14, 4, 9), "E3": (12, 8, 6)}
    with pytest.raises(InputError, match="'rectangular'.*corner at point") as err:
        build(GABLE_ROOFS, truth, regularise=["rectangular"])
    assert err.value.field == "regularise"


def test_the_outline_comes_from_ids_not_from_close_coordinates():
    # Two faces whose corners coincide in space but carry different ids are not joined.
    truth = {**GABLE, "X1": (0, 4, 9), "X2": (12, 4, 9)}
    roofs = [["E1", "E2", "R2", "R1"], ["E3", "E4", "X1", "X2"]]
    with pytest.raises(GeometryError, match="2 separate parts"):
        build(roofs, truth)


@pytest.mark.parametrize("roofs, truth, needle", [
    # a roof face standing upright
    ([["E1", "E2", "R2", "R1"], ["E1", "U1", "U2", "E2"]],
     {**GABLE, "U1": (0, 0, 3), "U2": (12, 0, 3)}, "roof face 1 (E1, U1, U2, E2) is vertical"),
    # two faces on the same side of one edge: they overlap in plan
    ([["E1", "E2", "R2", "R1"], ["E1", "E2", "X2", "X1"]],
     {**GABLE, "X1": (0, 2, 7.5), "X2": (12, 2, 7.5)}, "overlap in plan"),
    # a courtyard: the faces leave a hole
    ([["O1", "O2", "I2", "I1"], ["O2", "O3", "I3", "I2"], ["O3", "O4", "I4", "I3"],
      ["O4", "O1", "I1", "I4"]],
     {"O1": (0, 0, 6), "O2": (12, 0, 6), "O3": (12, 12, 6), "O4": (0, 12, 6),
      "I1": (4, 4, 7), "I2": (8, 4, 7), "I3": (8, 8, 7), "I4": (4, 8, 7)}, "has a hole"),
    # a face whose points are not in order around it
    ([["E1", "R2", "E2", "R1"], ["E3", "E4", "R1", "R2"]], GABLE,
     "roof face 0 (E1, R2, E2, R1) crosses itself in plan"),
    # two faces touching at one point only
    ([["A1", "A2", "P", "A4"], ["P", "B2", "B3", "B4"]],
     {"A1": (0, 0, 6), "A2": (5, 0, 6), "P": (5, 5, 6), "A4": (0, 5, 6),
      "B2": (10, 5, 6), "B3": (10, 10, 6), "B4": (5, 10, 6)},
     "not one simple loop: it passes through point P twice"),
])
def test_broken_roofs_are_refused_with_a_clear_message(roofs, truth, needle):
    with pytest.raises(GeometryError, match=needle.replace("(", r"\(").replace(")", r"\)")) as err:
        build(roofs, truth)
    assert err.value.field.startswith("roofs")


def test_faces_may_be_given_either_way_round():
    turned = [list(reversed(GABLE_ROOFS[0])), GABLE_ROOFS[1]]
    a = build(GABLE_ROOFS, GABLE, seed=3)
    b = build(turned, GABLE, seed=3)
    va = dict(zip(a.vertex_ids, a.vertices, strict=True))
    vb = dict(zip(b.vertex_ids, b.vertices, strict=True))
    assert va.keys() == vb.keys()
    assert all(np.allclose(va[k], vb[k], atol=1e-9) for k in va)
    assert a.measures["volume"] == pytest.approx(b.measures["volume"], rel=1e-12)
    assert_valid(b)


def test_a_ground_above_the_eaves_is_refused():
    spec = parse_building({"id": "B", "roofs": GABLE_ROOFS, "ground": GROUND + 7})
    with pytest.raises(GeometryError, match="not below the lowest roof point") as err:
        build_building(spec, measured(GABLE, 0.01, np.random.default_rng(1)))
    assert err.value.field == "ground"


def test_footprint_is_the_outline_in_order():
    spec = parse_building({"id": "B", "roofs": GABLE_ROOFS, "ground": GROUND})
    pts = measured(GABLE, 0.0001, np.random.default_rng(1))
    fp = footprint_en(spec, pts)
    assert fp.shape == (6, 2)
    x, y = fp[:, 0], fp[:, 1]
    area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    assert abs(area - 96) < 0.01


def test_a_flat_box_and_a_shed():
    box = {"C1": (0, 0, 4), "C2": (10, 0, 4), "C3": (10, 6, 4), "C4": (0, 6, 4)}
    flat = build([["C1", "C2", "C3", "C4"]], box, seed=2)
    assert abs(flat.measures["volume"] - 240) < 0.02 * 240
    assert flat.measures["roof_type"] == "flat"
    assert abs(flat.measures["eaves_height"] - flat.measures["ridge_height"]) < 0.05
    assert len(named_rings(flat, "WallSurface")) == 4
    assert_valid(flat)
    shed_truth = {**box, "C3": (10, 6, 6), "C4": (0, 6, 6)}
    shed = build([["C1", "C2", "C3", "C4"]], shed_truth, seed=2)
    assert abs(shed.measures["volume"] - 300) < 0.02 * 300
    assert shed.measures["roof_type"] == "shed"
    assert abs(shed.measures["eaves_height"] - (GROUND + 4)) < 0.03
    assert abs(shed.measures["ridge_height"] - (GROUND + 6)) < 0.03
    assert abs(shed.measures["roof_slopes"][0]["aspect_deg"] - 180) < 1  # faces south
    assert_valid(shed)


def test_a_wall_that_is_not_vertical_is_refused():
    truth = {**GABLE, "F1": (0, -4, 3), "F2": (12, -4, 3), "F3": (12, -1, 3), "F4": (0, -1, 3)}
    with pytest.raises(GeometryError, match=r"wall 0 \(F4, F3, E2, E1\) is not vertical") as err:
        build(GABLE_ROOFS + [["F1", "F2", "F3", "F4"]], truth,
              walls=[["F4", "F3", "E2", "E1"]])
    assert err.value.field == "walls[0]"


@settings(max_examples=examples(80), deadline=None)
@given(seed=st.integers(0, 2**32 - 1), sigma=st.sampled_from([0.001, 0.02, 0.3, 2.0]),
       shuffle=st.booleans(), roll=st.integers(0, 3), extra=st.sampled_from(
           [None, ["E1", "E2", "E3"], ["R1", "R2", "E2"], ["E1", "E4", "E3", "E2"]]))
def test_any_measurement_builds_a_valid_solid_or_is_refused_clearly(seed, sigma, shuffle, roll,
                                                                    extra):
    rng = np.random.default_rng(seed)
    roofs = [list(np.roll(GABLE_ROOFS[0], roll)), list(GABLE_ROOFS[1])]
    if shuffle:
        roofs[1] = [roofs[1][k] for k in rng.permutation(4)]
    if extra:
        roofs.append(extra)
    try:
        model = build(roofs, GABLE, sigma=sigma, seed=seed)
    except GsgeoError as exc:
        assert exc.problem
        return
    v = model.vertices - model.vertices.mean(axis=0)
    assert solid_problems(v, [s.ring for s in model.surfaces], planarity_m=1e-5) == []
    validate_city_json(city_json([model], BNG))
