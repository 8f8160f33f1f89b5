#!/usr/bin/env bash
# Install gsgeo and everything it needs on a fresh Debian machine with Python >= 3.11 and Node.js.
#   bash scripts/install.sh          the package, its run-time dependencies and the web client
#   bash scripts/install.sh --test   the same plus the test tools and Debian's chromium
set -euo pipefail
cd "$(dirname "$0")/.."

test_deps=0
[ "${1:-}" = "--test" ] && test_deps=1

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

if [ "$test_deps" = 1 ]; then
    python -m pip install --quiet --disable-pip-version-check -e '.[test]'
    if ! command -v chromium >/dev/null 2>&1; then
        echo "installing Debian's chromium for the browser tests" >&2
        as_root apt-get update -qq
        as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
    fi
else
    python -m pip install --quiet --disable-pip-version-check -e .
fi

# The CesiumJS client: cesium is pinned in web/package-lock.json; nothing is fetched at run time.
if [ -f web/package.json ]; then
    (cd web && npm ci --no-audit --no-fund --loglevel=error)
fi
