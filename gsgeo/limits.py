"""Ranges and id rules every input edge shares: the session JSON, the command line, the store
and the HTTP API check them with the same numbers (the API models import these constants).

Imports nothing of gsgeo but its errors, so every layer can use it.
"""

from __future__ import annotations

import math
import re
from typing import Any

from gsgeo.errors import InputError

#: A-priori aiming precision, pixels: from a hundredth of a pixel (finer than any aim) to 100.
SIGMA_PX_MIN = 0.01
SIGMA_PX_MAX = 100.0
#: The solver itself (a library function, also used by simulations with near noise-free aims)
#: takes sigma_px down to this: its weights 1 / (sigma_px · ifov · range)² stay finite.
SOLVER_SIGMA_PX_MIN = 1e-12
#: Angular size of a pixel, radians per pixel: from 1e-7 (a telescope) to 0.1 (5.7 degrees).
IFOV_MIN = 1e-7
IFOV_MAX = 0.1
#: Largest distance of a ray origin (camera centre) from the Earth's centre, metres (rendered
#: or georeferenced ECEF); 150 times the Earth's radius, beyond the Moon.
MAX_ORIGIN_M = 1e9
#: Direction vectors must have a length in this range, so that every layer (numpy, PROJ, the
#: viewer's JavaScript) can normalise them without overflow or underflow; a unit vector is usual.
DIRECTION_MIN = 1e-100
DIRECTION_MAX = 1e100

#: Integers given where text is expected (ids, codes) are used as text up to this size;
#: str() of a huge integer is slow or refused by Python.
MAX_INT_BITS = 256

#: Control characters (Unicode Cc: C0, DEL and C1 such as U+0085), line and paragraph
#: separators, and unpaired surrogates: never part of an id. str.strip() would silently
#: remove some of them (U+0085, U+2028), so they are refused before any stripping.
_BAD_ID_CHAR = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff]")


def _finite(value: Any, field: str, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"expected a number of {unit}", field=field)
    try:
        v = float(value)
    except OverflowError:
        raise InputError(f"expected a finite number of {unit}, got an integer too large for "
                         "a float", field=field) from None
    if not math.isfinite(v):
        raise InputError(f"expected a finite number of {unit}", field=field)
    return v


def sigma_px(value: Any, field: str = "sigma_px", minimum: float = SIGMA_PX_MIN) -> float:
    """The aiming precision in pixels, checked to lie in [minimum, SIGMA_PX_MAX]; ``minimum``
    is SIGMA_PX_MIN at every user-facing edge and SOLVER_SIGMA_PX_MIN in the solver.
    ``field``: the JSON path an InputError names."""
    v = _finite(value, field, "pixels")
    if not minimum <= v <= SIGMA_PX_MAX:
        raise InputError(f"must be between {minimum:g} and {SIGMA_PX_MAX:g} pixels, got {v:g}",
                         field=field)
    return v


def ifov(value: Any, field: str = "ifov") -> float:
    """The angular size of a pixel in radians, checked to lie in [IFOV_MIN, IFOV_MAX]."""
    v = _finite(value, field, "radians per pixel")
    if not IFOV_MIN <= v <= IFOV_MAX:
        raise InputError(f"must be between {IFOV_MIN:g} and {IFOV_MAX:g} radians per pixel, "
                         f"got {v:g}", field=field)
    return v


def vector_length(v: Any) -> float:
    """Euclidean length of a vector of floats without overflow or underflow (math.hypot scales)."""
    return math.hypot(*(float(x) for x in v))


def origin_problem(origin: Any) -> str | None:
    """Why a camera centre (ECEF, metres) is unusable, or None: beyond MAX_ORIGIN_M."""
    r = vector_length(origin)
    if not r <= MAX_ORIGIN_M:
        return (f"out of range: {r:.3g} m from the Earth's centre (more than "
                f"{MAX_ORIGIN_M:g} m)")
    return None


def direction_problem(direction: Any) -> str | None:
    """Why a direction vector is unusable, or None: zero, or too small or large to normalise."""
    r = vector_length(direction)
    if r == 0:
        return "is a zero vector"
    if r < DIRECTION_MIN:
        return (f"too small to normalise (length {r:.3g}; give a length between "
                f"{DIRECTION_MIN:g} and {DIRECTION_MAX:g}, e.g. a unit vector)")
    if not r <= DIRECTION_MAX:
        return (f"too large to normalise (length {r:.3g}; give a length between "
                f"{DIRECTION_MIN:g} and {DIRECTION_MAX:g}, e.g. a unit vector)")
    return None


def id_text(value: Any, field: str | None) -> str:
    """An id (point, line, polygon, check point) as given, or InputError.

    Text or an integer; never empty or blank, never holding a control character, a line or
    paragraph separator or an unpaired surrogate (checked before any stripping).
    """
    if isinstance(value, bool) or not isinstance(value, (str, int)) or (
            isinstance(value, int) and value.bit_length() > MAX_INT_BITS):
        raise InputError("expected text", field=field)
    v = str(value)
    bad = _BAD_ID_CHAR.search(v)
    if bad:
        raise InputError(f"contains U+{ord(bad.group()):04X} at position {bad.start() + 1} "
                         "(a control character, line or paragraph separator or unpaired "
                         "surrogate); ids must be printable text", field=field)
    if not v.strip():
        raise InputError("must not be empty", field=field)
    return v


#: What no text may hold, anywhere: a NUL character (PostgreSQL's text cannot keep it, C
#: libraries such as PROJ and GDAL stop reading at it) and unpaired surrogates (U+D800 to
#: U+DFFF: not characters, so not encodable as UTF-8; JSON escapes such as "\ud800" and
#: Python's surrogateescape can make them).
_BAD_TEXT_CHAR = re.compile("[\x00\ud800-\udfff]")
#: Where a JSON document's bytes may hold such text: an escaped NUL or surrogate, or the raw
#: UTF-8 form of a surrogate (which Python's json decodes with "surrogatepass"). A quick
#: screen only: a hit makes :func:`check_json_text` walk the document.
_BAD_JSON_TEXT = re.compile(rb"\\u(?:[dD][89a-fA-F]|0000)|\xed[\xa0-\xbf]")


def text_problem(text: str) -> str | None:
    """Why ``text`` cannot be kept or passed on as text, or None: it holds a NUL character or
    an unpaired surrogate (named with its position)."""
    bad = _BAD_TEXT_CHAR.search(text)
    if bad is None:
        return None
    c = bad.group()
    what = ("a NUL character (U+0000), which no text may hold" if c == "\x00" else
            f"an unpaired surrogate (U+{ord(c):04X}), which is not valid Unicode text")
    return f"holds {what} (at character {bad.start() + 1})"


def check_text(text: str, field: str | None) -> str:
    """``text`` when :func:`text_problem` finds nothing wrong in it, else InputError naming
    ``field``."""
    problem = text_problem(text)
    if problem is not None:
        raise InputError(problem, field=field)
    return text


def json_text_may_be_bad(data: bytes) -> bool:
    """Whether the JSON text ``data`` may decode to text :func:`text_problem` refuses (a fast
    screen of the bytes; False means it cannot)."""
    return _BAD_JSON_TEXT.search(data) is not None


def check_json_text(doc: Any, field: str | None = None) -> None:
    """InputError naming the JSON path (``points[0].code``) of the first string, or object
    key, of the decoded JSON ``doc`` that :func:`text_problem` refuses."""
    stack: list[tuple[Any, str | None]] = [(doc, field)]
    while stack:
        value, where = stack.pop()
        if isinstance(value, str):
            check_text(value, where)
        elif isinstance(value, dict):
            for key, item in reversed(value.items()):
                name = key if isinstance(key, str) else str(key)
                if text_problem(name) is not None:  # named escaped: a message must be text
                    shown = name.encode("ascii", "backslashreplace").decode()
                    check_text(name, f"{where}.{shown}" if where else shown)
                at = f"{where}.{name}" if where else name
                stack.append((item, at))
        elif isinstance(value, list):
            stack.extend((item, f"{where or ''}[{i}]") for i, item in reversed(
                list(enumerate(value))))


#: A number as text: ASCII digits, an optional sign, point and exponent. Python's float()
#: and int() also take Unicode digits ("١٠"), underscores ("1_000"), blanks, "nan" and
#: "inf"; no input edge takes those.
_NUMBER_TEXT = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_INTEGER_TEXT = re.compile(r"[0-9]+")
MAX_INTEGER_DIGITS = 4000  # Python's int() refuses more than 4300


def number_text(text: str, field: str | None) -> float:
    """A finite number written in ASCII decimal notation (``-1.5``, ``.5``, ``2e3``), or
    InputError naming ``field``."""
    if not _NUMBER_TEXT.fullmatch(text):
        raise InputError(f"{text[:40]!r} is not a number (write ASCII digits, e.g. -1.25 or "
                         "2e3)", field=field)
    v = float(text)
    if not math.isfinite(v):
        raise InputError(f"{text[:40]!r} is too large a number", field=field)
    return v


def integer_text(text: str, field: str | None) -> int:
    """A non-negative integer written with ASCII digits only, or InputError
    naming ``field``."""
    if not _INTEGER_TEXT.fullmatch(text) or len(text) > MAX_INTEGER_DIGITS:
        raise InputError(f"{text[:40]!r} is not a whole number of at most "
                         f"{MAX_INTEGER_DIGITS} ASCII digits", field=field)
    return int(text)
