"""Numbers on the command line and in the files it reads are ASCII decimals: Python's int()
and float() also take Unicode digits, underscores, blanks, 'nan' and 'inf', which no edge of
gsgeo takes (exit code 2 naming the argument; a file's line and column)."""

from __future__ import annotations

import pytest

from gsgeo.cli import build_parser
from gsgeo.errors import InputError
from gsgeo.service.checkpoints import read_check_points
from gsgeo.tiles.georef import Georeference


def run(capsys, *argv: str) -> tuple[int, str]:
    """The parser's verdict on ``argv`` (parsing only: nothing is run)."""
    with pytest.raises(SystemExit) as exc:
        build_parser(argv[0]).parse_args(list(argv))
    return int(exc.value.code or 0), capsys.readouterr().err


@pytest.mark.parametrize("argv", [
    ["crs", "search", "wgs", "--limit", "\u0661\u0660"],
    ["crs", "search", "wgs", "--limit", "1_0"],
    ["crs", "search", "wgs", "--limit", " 10"],
    ["serve", "--port", "8_000"],
    ["serve", "--workers", "\u0662"],
    ["solve", "x.json", "--sigma-px", "nan"],
    ["solve", "x.json", "--sigma-px", "1_0"],
    ["solve", "x.json", "--sigma-px", "\u0661"],
    ["tiles", "in.ply", "-o", "out", "--origin", "51,0,0", "--heading", "inf"],
    ["tiles", "in.ply", "-o", "out", "--max-splats", "1_000"],
])
def test_liberal_numbers_are_refused_naming_the_argument(capsys, argv):
    code, err = run(capsys, *argv)
    assert code == 2, err
    flag = argv[-2]
    assert flag in err and "Traceback" not in err, err


@pytest.mark.parametrize("text", ["5\u0661,0,0", "5_1,0,0", "51,0,nan", "51,0,inf", "51,0,0x1"])
def test_an_origin_with_liberal_numbers_is_refused(text):
    with pytest.raises(InputError, match="origin"):
        Georeference.from_options(origin=text)


@pytest.mark.parametrize("cell", ["1_000", "\u0661\u0660", "inf", "0x10", "1e999"])
def test_check_point_csv_numbers_are_strict(cell):
    data = f"id,x,y,z\nC1,{cell},180000,5\n".encode()
    with pytest.raises(InputError, match="line 2"):
        read_check_points(data, "csv", "c.csv")


@pytest.mark.parametrize("argv", [
    ["report", "p\udcff", "-o", "x.pdf"],            # a non-UTF-8 byte, as Python decodes argv
    ["georef", "--project", "p\udcff"],
    ["users", "add", "n\udcff", "--role", "viewer"],
    ["users", "remove", "n\udcff"],
    ["crs", "search", "w\udcff"],
])
def test_text_arguments_that_are_not_text_are_refused(capsys, argv):
    code, err = run(capsys, *argv)
    assert code == 2 and "U+DCFF" in err, err
