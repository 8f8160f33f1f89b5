"""gsgeo.export.wkb and gsgeo.export.arrow: WKB assembled with numpy equals shapely's; Arrow
columns hold the values (nulls, Unicode, flags) they were given."""

from __future__ import annotations

import nanoarrow as na
import numpy as np
import pytest
import shapely

from gsgeo.errors import InputError
from gsgeo.export import wkb
from gsgeo.export.arrow import column, table_stream
from gsgeo.export.tables import Table


def _split(offsets, data) -> list[bytes]:
    return [bytes(data[offsets[k]:offsets[k + 1]]) for k in range(len(offsets) - 1)]


@pytest.mark.parametrize("dims", [2, 3])
def test_wkb_equals_shapely(rng, dims):
    xyz = rng.normal(530000.0, 1000.0, (7, dims))
    seg = rng.normal(180000.0, 50.0, (7, 2, dims))
    ring = rng.normal(0.0, 1.0, (7, 37, dims)) * [1e6, -3.0, 1e-9][:dims]
    ring[:, -1] = ring[:, 0]
    iso = {"flavor": "iso", "byte_order": 1, "output_dimension": dims}
    assert _split(*wkb.points(xyz)) == list(shapely.to_wkb(shapely.points(xyz), **iso))
    assert _split(*wkb.linestrings(seg)) == list(shapely.to_wkb(shapely.linestrings(seg), **iso))
    assert _split(*wkb.polygons(ring)) == list(shapely.to_wkb(shapely.polygons(ring), **iso))
    # and shapely reads them back to the same coordinates, NaN heights included
    xyz[0, -1] = np.nan
    back = shapely.from_wkb(np.array(_split(*wkb.points(xyz)), dtype=object))
    np.testing.assert_array_equal(shapely.get_coordinates(back, include_z=dims == 3), xyz)


def test_wkb_offsets_and_from_bytes():
    off, data = wkb.linestrings(np.zeros((3, 2, 3)))
    assert off.tolist() == [0, 57, 114, 171] and data.dtype == np.uint8 and data.size == 171
    items = [b"a", b"", b"xyz"]
    off, data = wkb.from_bytes(items)
    assert off.tolist() == [0, 1, 1, 4] and _split(off, data) == items
    with pytest.raises(ValueError, match="2 or 3 dimensions"):
        wkb.points(np.zeros((2, 4)))


def _values(arr):
    return na.Array(arr).to_pylist()


def test_arrow_columns_hold_values_and_nulls():
    f = np.array([1.5, np.nan, -0.0, 1e-300, np.inf])
    got = _values(column("x", f, "float"))
    assert got[0] == 1.5 and got[1] is None and got[3] == 1e-300 and got[4] == np.inf
    assert np.copysign(1.0, got[2]) == -1.0
    assert _values(column("n", np.array([3, 0, -2]), "int")) == [3, 0, -2]
    flags = np.array([True, False, True, True, False, False, False, False, True])
    assert _values(column("b", flags, "bool")) == flags.tolist()
    text = np.array(["P1", None, "Straße, \"quoted\"\nline", "", "日本"], dtype=object)
    assert _values(column("s", text, "str")) == text.tolist()
    assert _values(column("s", np.array(["a", "b"], dtype=object), "str")) == ["a", "b"]
    assert _values(column("s", np.array([7, None], dtype=object), "str")) == ["7", None]
    assert _values(column("s", np.array([None, None], dtype=object), "str")) == [None, None]
    assert _values(column("x", np.array([np.nan, np.nan]), "float")) == [None, None]
    assert _values(column("x", np.array([]), "float")) == []
    with pytest.raises(InputError, match="column s"):
        column("s", np.array(["bad \udc80"], dtype=object), "str")


def test_arrow_table_stream():
    t = Table({"id": np.array(["a", "b"], dtype=object), "v": np.array([1.0, np.nan])},
              {"id": "str", "v": "float"})
    stream = table_stream(wkb.points(np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])), t)
    rows = na.ArrayStream(stream).read_all().to_pylist()
    assert [r["id"] for r in rows] == ["a", "b"] and rows[1]["v"] is None
    assert shapely.from_wkb(rows[1]["geom"]).equals(shapely.Point(4, 5, 6))
    with pytest.raises(ValueError, match="3 geometries for 2 rows"):
        table_stream(wkb.points(np.zeros((3, 3))), t)
