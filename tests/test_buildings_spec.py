"""The building JSON form: parsed, written back, and every problem named."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis_profiles import examples

from gsgeo.buildings.spec import Ground, building_to_json, parse_building, point_ids
from gsgeo.errors import InputError

DOC = {"id": "B1", "roofs": [["E1", "E2", "R2", "R1"], ["E3", "E4", "R1", "R2"]],
       "ground": 10.0, "attributes": {"function": "residential"},
       "regularise": ["horizontal_eaves"]}


@pytest.mark.parametrize("ground, expected", [
    (10.0, Ground(height=10.0)),
    ("G7", Ground(point_id="G7")),
    ({"dtm": "dtm.tif"}, Ground(dtm="dtm.tif")),
    ({"height": 9.5, "sigma": 0.05}, Ground(height=9.5, sigma=0.05)),
    ({"point": "G1", "sigma": 0.02}, Ground(point_id="G1", sigma=0.02)),
])
def test_every_ground_form_round_trips(ground, expected):
    spec = parse_building({**DOC, "ground": ground})
    assert spec.ground == expected
    assert parse_building(building_to_json(spec)) == spec


def test_a_building_round_trips_with_its_attributes_and_walls():
    doc = {**DOC, "walls": [["E1", "E2", "R2"]]}
    spec = parse_building(doc)
    assert spec.roofs[1] == ("E3", "E4", "R1", "R2")
    assert spec.regularise == ("horizontal_eaves",)
    assert building_to_json(spec) == doc
    assert point_ids(parse_building({**DOC, "ground": "G7"})) == [
        "E1", "E2", "R2", "R1", "E3", "E4", "G7"]


def test_every_problem_is_named_at_once():
    doc = {"id": "", "roofs": [["A", "B"], ["A", "B", "A", "C"], "x"], "ground": {"height": 1, "dtm": "d"},
           "regularise": ["square"], "colour": 1}
    with pytest.raises(InputError) as err:
        parse_building(doc, "buildings[3]")
    text = str(err.value)
    for needle in ("buildings[3].colour: unknown key", "buildings[3].id: must not be empty",
                   "buildings[3].roofs[0]: a face needs at least 3 point ids",
                   "buildings[3].roofs[1]: point 'A' appears more than once",
                   "buildings[3].roofs[2]: expected a list of point ids",
                   "give exactly one of 'height', 'point', 'dtm'",
                   "buildings[3].regularise[0]: unknown regularisation 'square'"):
        assert needle in text, needle
    assert err.value.field == "buildings[3]"


@pytest.mark.parametrize("doc, field, needle", [
    ([1], "building", "expected an object"),
    ({"id": "B", "ground": 1}, "building.roofs", "missing"),
    ({"id": "B", "roofs": [], "ground": 1}, "building.roofs", "at least 1 roof faces"),
    ({"id": "B", "roofs": [["a", "b", "c", "a"]], "ground": 1}, "building.roofs[0]",
     "repeats its first point"),
    ({"id": "B", "roofs": [["a", "b", "c"]]}, "building.ground", "missing"),
    ({"id": "B", "roofs": [["a", "b", "c"]], "ground": True}, "building.ground",
     "expected a height"),
    ({"id": "B", "roofs": [["a", "b", "c"]], "ground": {"height": 1, "sigma": -1}},
     "building.ground.sigma", "must be between 0 and 1000 m"),
    ({"id": "B", "roofs": [["a", "b", "c"]], "ground": {"height": 1, "sigma": 1e300}},
     "building.ground.sigma", "must be between 0 and 1000 m"),
    ({"id": "B", "roofs": [["a", "b", "c"]], "ground": 1, "attributes": {"volume": 3}},
     "building.attributes.volume", "computed by gsgeo"),
    ({"id": "B", "roofs": [["a", "b", "c"]], "ground": 1, "walls": [["a", "b", "x"]]},
     "building.walls[0]", "point 'x' is on no roof face"),
    ({"id": "B", "roofs": [["a", "b", "c"]], "ground": 1,
      "regularise": ["rectangular", "rectangular"]}, "building.regularise[1]", "given twice"),
])
def test_one_problem_names_its_field(doc, field, needle):
    with pytest.raises(InputError) as err:
        parse_building(doc)
    assert err.value.field == field
    assert needle in err.value.problem


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10, 10) | st.floats(allow_nan=True)
    | st.text(max_size=4),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                 max_size=4),
    max_leaves=12)
ids = st.sampled_from(["E1", "E2", "E3", "E4", "R1", "R2", "", " ", 3, None])


@settings(max_examples=examples(150), deadline=None)
@given(doc=st.fixed_dictionaries(
    {}, optional={"id": ids, "roofs": st.lists(st.lists(ids, max_size=5), max_size=3) | json_values,
                  "ground": json_values | st.floats(), "walls": json_values,
                  "attributes": json_values, "regularise": json_values, "extra": json_values}))
def test_any_document_parses_or_is_refused_with_an_input_error(doc):
    try:
        spec = parse_building(doc)
    except InputError as exc:
        assert exc.problem and exc.field
        return
    assert parse_building(building_to_json(spec)) == spec


def test_an_api_body_parsed_at_the_root_names_fields_without_a_prefix():
    with pytest.raises(InputError) as err:
        parse_building({"id": "B", "roofs": [["a", "b", "c"], ["a", "b", ""]], "ground": 1}, "")
    assert err.value.field == "roofs[1][2]"
    with pytest.raises(InputError) as err:
        parse_building({"roofs": [["a", "b"]], "ground": 1}, "")
    assert err.value.field is None and "id: missing" in err.value.problem
    assert "roofs[0]: a face needs at least 3 point ids" in err.value.problem
