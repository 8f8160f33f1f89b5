"""Validation of CityJSON documents against the official CityJSON 2.0 JSON schema.

The schema is not in the repository: `bash scripts/install.sh --test` installs it into
.venv/share/cityjson-schemas/2.0 (scripts/cityjson_schema.py reads it out of the official
validator's wheel on PyPI). Nothing is downloaded here.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any

import jsonschema
import pytest

SCHEMA = Path(__file__).resolve().parents[1] / ".venv" / "share" / "cityjson-schemas" / "2.0" / \
    "cityjson.schema.json"


@functools.lru_cache(maxsize=1)
def validator() -> jsonschema.Draft7Validator:
    if not SCHEMA.is_file():
        pytest.fail(f"the official CityJSON 2.0 schema is not installed at {SCHEMA}: run "
                    "`bash scripts/install.sh --test`")
    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    assert schema["title"] == "CityJSON v2.0.0"
    return jsonschema.Draft7Validator(schema, format_checker=jsonschema.FormatChecker())


def validate_city_json(doc: Any) -> None:
    """Fail (listing every error) unless ``doc`` is valid against the CityJSON 2.0 schema."""
    errors = sorted(validator().iter_errors(doc), key=lambda e: list(e.absolute_path))
    assert not errors, "\n".join(f"{list(e.absolute_path)}: {e.message}" for e in errors[:20])
