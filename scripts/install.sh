#!/usr/bin/env bash
# Install gsgeo into a virtual environment (.venv, reused when present) on a Debian 12 machine
# with python3 (>= 3.11) and, where missing, installs python3-venv and Node.js's npm through apt.
#   bash scripts/install.sh          the package, its run-time dependencies and the web client
#   bash scripts/install.sh --test   the same plus the test tools and Debian's chromium, proj-data,
#                                    QGIS, PostgreSQL 15, PostGIS and nginx
# Afterwards: `.venv/bin/gsgeo ...`, or `. .venv/bin/activate` once and then `gsgeo ...`.
set -euo pipefail
cd "$(dirname "$0")/.."

test_deps=0
case "${1:-}" in
    "") ;;
    --test) test_deps=1 ;;
    *) echo "usage: bash scripts/install.sh [--test]" >&2; exit 2 ;;
esac

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
apt_updated=0
apt_install() {
    local pkgs=()
    for a in "$@"; do [[ "$a" == -* ]] || pkgs+=("$a"); done
    echo "installing Debian's ${pkgs[*]} through apt" >&2
    if [ "$apt_updated" = 0 ]; then as_root apt-get update -qq; apt_updated=1; fi
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null
}

# The interpreter: python3 (Debian 12 has no `python`), at least 3.11.
PYTHON=${PYTHON:-python3}
if ! command -v "$PYTHON" >/dev/null 2>&1; then
    apt_install python3
fi
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
    echo "gsgeo needs Python >= 3.11; $PYTHON is $("$PYTHON" -V 2>&1)" >&2
    exit 2
fi

# A virtual environment: Debian's interpreter is externally managed (PEP 668) and refuses pip.
if ! .venv/bin/python -c 'import sys' >/dev/null 2>&1; then
    # Debian splits venv's pip bootstrap (ensurepip) into python3-venv.
    if ! "$PYTHON" -c 'import ensurepip, venv' >/dev/null 2>&1; then
        apt_install python3-venv
    fi
    rm -rf .venv
    "$PYTHON" -m venv .venv
fi
PIP=(.venv/bin/python -m pip install --quiet --disable-pip-version-check)

if [ "$test_deps" = 1 ]; then
    "${PIP[@]}" -e '.[test]'
    # The official CityJSON 2.0 schema the tests validate against (tests/cityjson_helpers.py),
    # read out of the official validator's wheel on PyPI by scripts/cityjson_schema.py.
    .venv/bin/python scripts/cityjson_schema.py .venv/share/cityjson-schemas/2.0
    missing=()
    command -v chromium >/dev/null 2>&1 || missing+=(chromium)
    # egm96_15.gtx, the one geoid Debian ships, for the vertical-datum tests.
    [ -f /usr/share/proj/egm96_15.gtx ] || missing+=(proj-data)
    # PostgreSQL 15 and PostGIS for the store tests' throw-away cluster (tests/pgcluster.py).
    [ -x /usr/lib/postgresql/15/bin/initdb ] || missing+=(postgresql-15)
    [ -f /usr/share/postgresql/15/extension/postgis.control ] || missing+=(postgresql-15-postgis-3)
    # nginx as the static host of scene tiles (tests/e2e/test_static_scenes.py).
    [ -x /usr/sbin/nginx ] || missing+=(nginx-light)
    # Mesa's llvmpipe through EGL: the software renderer the browser tests draw with
    # (tests/e2e/workplace.py: about twice as fast as Chromium's SwiftShader here).
    for pkg in libegl1 libegl-mesa0 libgl1-mesa-dri; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "ok installed" || missing+=("$pkg")
    done
    if [ "${#missing[@]}" -gt 0 ]; then apt_install "${missing[@]}"; fi
    # Debian's QGIS Python and its providers (OAPIF) for the QGIS plugin's headless test;
    # where apt has no QGIS, that test skips and says why.
    qgis=()
    for pkg in python3-qgis qgis-providers; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "ok installed" || qgis+=("$pkg")
    done
    if [ "${#qgis[@]}" -gt 0 ]; then
        apt_install --no-install-recommends "${qgis[@]}" \
            || echo "could not install ${qgis[*]}: tests/test_qgis_plugin.py will skip" >&2
    fi
else
    "${PIP[@]}" -e .
fi

# WeasyPrint (the PDF of `gsgeo report`) lays text out with Debian's Pango libraries.
pango=()
for lib in libpango-1.0-0 libpangoft2-1.0-0; do
    dpkg-query -W -f='${Status}' "$lib" 2>/dev/null | grep -q "ok installed" || pango+=("$lib")
done
if [ "${#pango[@]}" -gt 0 ]; then apt_install "${pango[@]}"; fi

# The CesiumJS client: cesium is pinned in web/package-lock.json; nothing is fetched at run time.
if [ -f web/package.json ]; then
    command -v npm >/dev/null 2>&1 || apt_install npm
    (cd web && npm ci --no-audit --no-fund --loglevel=error)
fi
