"""`gsgeo users add|list|remove`: the accounts of a store (users, roles, API tokens).

``add NAME --role ROLE`` prints the new user's token once (the store keeps only its hash);
``list`` shows name, role and when each was made; ``remove NAME`` deletes one (their token
stops working at once). The store is the one ``gsgeo serve`` uses: ``--store URL`` (or
GSGEO_STORE), else the SQLite file of ``--data``.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from gsgeo.commands.argtypes import text as text_arg
from gsgeo.errors import InputError
from gsgeo.store.accountrecords import ROLES


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "users",
        help="add, list or remove the users of the API (roles and tokens)",
        description="Manage the users of a store: each has a role (admin: everything; "
                    "surveyor: measures and edits; viewer: reads only) and an API token, "
                    "printed once by 'add' (only its hash is stored).",
    )
    acts = p.add_subparsers(dest="action", metavar="ACTION")
    acts.required = True
    add = acts.add_parser("add", help="make a user and print their token (once)")
    add.add_argument("name", type=text_arg, help="user name (letters, digits, '.', '_', '-')")
    add.add_argument("--role", required=True, choices=ROLES, help="what the user may do")
    acts.add_parser("list", help="list the users (name, role, created)")
    rm = acts.add_parser("remove", help="delete a user (their token stops working)")
    rm.add_argument("name", type=text_arg, help="user name")
    for a in (add, acts.choices["list"], rm):
        a.add_argument("--data", default="gsgeo-data", metavar="DIR",
                       help="data directory with the project store (default: ./gsgeo-data, "
                            "as for gsgeo serve)")
        a.add_argument("--store", default=None, metavar="URL",
                       help="a PostgreSQL store (postgresql://USER[:PASS]@HOST:PORT/DB); "
                            "default: GSGEO_STORE, else the SQLite file of --data")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from gsgeo.service import accounts
    from gsgeo.store import DB_NAME, STORE_ENV, open_store

    url = args.store if args.store is not None else os.environ.get(STORE_ENV)
    data = Path(args.data)
    if not (url or "").strip() and args.action != "add" and not (data / DB_NAME).is_file():
        raise InputError(f"no project store in '{data}' (give --data DIR or --store URL)",
                         field="data")
    store = open_store(data, url)
    try:
        if args.action == "add":
            token = accounts.add_user(store, args.name, args.role)
            print(f"user '{args.name}' ({args.role}) added; their API token (shown only "
                  f"now, keep it safe):\n{token}")
        elif args.action == "list":
            for u in accounts.list_users(store):
                print(f"{u.name}\t{u.role}\t{u.created_at}")
        else:
            accounts.remove_user(store, args.name)
            print(f"user '{args.name}' removed")
    finally:
        store.close()
    return 0
