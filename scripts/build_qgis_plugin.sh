#!/usr/bin/env bash
# Build the QGIS plugin zip: dist/gsgeo-qgis.zip holding the folder gsgeo/ (qgis/gsgeo in the
# repository), the layout QGIS's "Plugins > Manage and Install Plugins > Install from ZIP" takes.
#   bash scripts/build_qgis_plugin.sh [OUT.zip]
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-dist/gsgeo-qgis.zip}
mkdir -p "$(dirname "$out")"
out=$(cd "$(dirname "$out")" && pwd)/$(basename "$out")
rm -f "$out"
# Python's zipfile (no zip program needed); caches and editor leftovers stay out.
python3 - "$out" <<'PY'
import sys
import zipfile
from pathlib import Path

out = Path(sys.argv[1])
src = Path("qgis/gsgeo")
with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
    for f in sorted(src.rglob("*")):
        if f.is_file() and "__pycache__" not in f.parts and f.suffix not in (".pyc", ".pyo") \
                and not f.name.endswith("~"):
            z.write(f, Path("gsgeo") / f.relative_to(src))
PY
echo "$out"
