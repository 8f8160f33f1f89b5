"""The ``--store URL`` option of the commands that read projects: the store ``gsgeo serve
--store`` uses (a PostgreSQL URL, or the environment's GSGEO_STORE), else the SQLite file of
``--data``."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from gsgeo.errors import InputError


def add_store_argument(p: argparse.ArgumentParser) -> None:
    """Add ``--store URL`` to a command's parser."""
    p.add_argument("--store", default=None, metavar="URL",
                   help="a PostgreSQL store (postgresql://USER[:PASS]@HOST:PORT/DB), as for "
                        "gsgeo serve --store; default: GSGEO_STORE, else the SQLite file of --data")


def store_url(args: argparse.Namespace) -> str | None:
    """The store URL the command was given (--store, else GSGEO_STORE); None: SQLite."""
    from gsgeo.store import STORE_ENV

    url = args.store if args.store is not None else os.environ.get(STORE_ENV)
    return url.strip() if url is not None and url.strip() else None


def require_sqlite_store(data: Path) -> None:
    """InputError naming ``data`` when it holds no SQLite project store."""
    from gsgeo.store import DB_NAME

    if not (data / DB_NAME).is_file():
        raise InputError(f"--data {data}: no project store ({DB_NAME}) there; gsgeo serve or "
                         "gsgeo demo creates one (or give --store URL)")
