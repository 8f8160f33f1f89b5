"""The `gsgeo` command. Each subcommand lives in its own module under gsgeo.commands.

Errors. Every command answers bad input with one line ``gsgeo COMMAND: error: MESSAGE`` on
stderr and exit code 2, never a traceback. The commands check what they can name precisely
(a session's JSON path, a CRS, an output file) and raise GsgeoError; as a guard behind those
checks, `main` also turns

- OSError into the path and the system's reason (``/x/out: Permission denied``),
- RecursionError, MemoryError and ValueError into their message,

with exit code 2 as well. Anything else is a bug of gsgeo: one line ``gsgeo COMMAND: internal
error: TYPE: MESSAGE`` with a hint and exit code 1. Set the environment variable
``GSGEO_DEBUG=1`` to get the full Python traceback of any error instead (developers).
Ctrl-C exits with 130; a closed output pipe (``gsgeo solve ... | head``) with 0.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
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
    "report": "gsgeo.commands.report",
    "georef": "gsgeo.commands.georef",
    "users": "gsgeo.commands.users",
}

EXIT_USAGE = 2
EXIT_INTERNAL = 1


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


def os_error_text(exc: OSError) -> str:
    """``PATH: reason`` of an OSError (both paths of a rename), or its text without a path."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    if exc.filename is None:
        return reason
    paths = os.fsdecode(exc.filename)
    if exc.filename2 is not None:
        paths += f" -> {os.fsdecode(exc.filename2)}"
    return f"{paths}: {reason}"


def _debug() -> bool:
    return os.environ.get("GSGEO_DEBUG", "") not in ("", "0")


def main(argv: list[str] | None = None) -> int:
    """Run one `gsgeo` command; returns the exit code (errors: see the module docstring)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv and argv[0] in COMMANDS else None)
    args = parser.parse_args(argv)
    prefix = f"gsgeo {args.command}:"
    try:
        return int(args.run(args) or 0)
    except GsgeoError as exc:
        if _debug():
            raise
        print(f"{prefix} error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("gsgeo: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (`gsgeo solve ... --json | head`): not an error of ours.
        # Point stdout at devnull so the interpreter's final flush does not complain.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (OSError, RecursionError, MemoryError, ValueError) as exc:
        if _debug():
            raise
        if isinstance(exc, OSError):
            text = os_error_text(exc)
        elif isinstance(exc, RecursionError):
            text = "the input is nested too deeply to process"
        elif isinstance(exc, MemoryError):
            text = "out of memory: the input is too large"
        else:
            text = str(exc) or type(exc).__name__
        print(f"{prefix} error: {one_line(text)}", file=sys.stderr)
        return EXIT_USAGE
    except Exception as exc:
        if _debug():
            raise
        print(f"{prefix} internal error: {type(exc).__name__}: {one_line(str(exc))} "
              "(a bug in gsgeo; run again with GSGEO_DEBUG=1 for the traceback and report it)",
              file=sys.stderr)
        return EXIT_INTERNAL


#: Characters that would break a message's line or hide in it: control characters (C0, C1),
#: line and paragraph separators, unpaired surrogates. Shown escaped (\x85), never dropped.
_UNPRINTABLE = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff]")


def one_line(text: str, limit: int = 2000) -> str:
    """A message as one printable line of at most ``limit`` characters: line breaks and tabs
    become spaces, other control characters their escapes (user text echoed in a message,
    e.g. an unknown CRS, must not split the line or vanish from it)."""
    flat = re.sub(r"[\r\n\t]+", " ", text)
    flat = _UNPRINTABLE.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), flat)
    return flat if len(flat) <= limit else flat[:limit - 3] + "..."


if __name__ == "__main__":
    sys.exit(main())
