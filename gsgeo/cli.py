"""The `gsgeo` command. Each subcommand lives in its own module under gsgeo.commands."""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from gsgeo import __version__
from gsgeo.errors import GsgeoError

#: Subcommand name -> module in gsgeo.commands providing ``add_parser(sub)`` and ``run(args)``.
COMMANDS = {
    "solve": "gsgeo.commands.solve",
    "tiles": "gsgeo.commands.tiles",
    "crs": "gsgeo.commands.crs",
    "serve": "gsgeo.commands.serve",
    "demo": "gsgeo.commands.demo",
}

EXIT_USAGE = 2


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The command-line parser; with ``only``, just that subcommand (the others' modules,
    some heavy to import, are then not loaded)."""
    parser = argparse.ArgumentParser(
        prog="gsgeo",
        description="Survey-grade point measurement in georeferenced 3D Gaussian Splatting scenes.",
    )
    parser.add_argument("--version", action="version", version=f"gsgeo {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, module in COMMANDS.items():
        if only is None or name == only:
            importlib.import_module(module).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv and argv[0] in COMMANDS else None)
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except GsgeoError as exc:
        print(f"gsgeo {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("gsgeo: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (`gsgeo solve ... --json | head`): not an error of ours.
        # Point stdout at devnull so the interpreter's final flush does not complain.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
