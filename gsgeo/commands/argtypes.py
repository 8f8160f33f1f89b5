"""Argument types of the command line: numbers read as the other edges read them.

argparse's ``type=int`` / ``type=float`` are Python's int() and float(), which also take
Unicode digits ("١٠"), underscores ("8_000"), blanks, "nan" and "inf"; these take ASCII
decimals only (gsgeo.limits.integer_text / number_text), and argparse answers anything else
with exit code 2 naming the argument.
"""

from __future__ import annotations

import argparse

from gsgeo.errors import InputError
from gsgeo.limits import integer_text, number_text, text_problem


def integer(text: str) -> int:
    """A non-negative whole number of ASCII digits."""
    try:
        return integer_text(text, None)
    except InputError as exc:
        raise argparse.ArgumentTypeError(exc.problem) from None


def number(text: str) -> float:
    """A finite number in ASCII decimal notation (-1.5, .5, 2e3)."""
    try:
        return number_text(text, None)
    except InputError as exc:
        raise argparse.ArgumentTypeError(exc.problem) from None


def text(value: str) -> str:
    """Text a name or id may be: no NUL, no unpaired surrogate (argv bytes that are not UTF-8
    arrive as surrogates, which no store or library can encode)."""
    problem = text_problem(value)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return value
