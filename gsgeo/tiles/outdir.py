"""Which OUTDIR `gsgeo tiles` may write or replace, and the marker that makes a tileset ours.

Replacing OUTDIR deletes everything in it, so a directory is replaced only when it is empty
or is a tileset gsgeo wrote and holds nothing else: the marker file :data:`MARKER`, written
into every tileset, plus ``tileset.json`` and ``tiles/*.glb``. Tilesets of gsgeo versions
before the marker are recognised by their ``tileset.json`` (``asset.generator`` "gsgeo tiles"
with gsgeo's ``extras``). Never replaced, whatever the flags: a filesystem root or mount point,
the home or current directory or a folder holding one of them, and a folder holding the input.
Paths are compared after resolving symbolic links.
"""

from __future__ import annotations

import json
import os
import re
import stat
import time
from pathlib import Path

from gsgeo import __version__
from gsgeo.errors import InputError
from gsgeo.tiles.georefhistory import FIT_DIR

#: The file that marks a tileset directory as written by gsgeo.
MARKER = ".gsgeo-tileset"
_TOOL = "gsgeo tiles"
#: A larger tileset.json is not read to recognise an older gsgeo tileset.
_MAX_JSON = 256 << 20


def write_marker(folder: Path) -> None:
    """Write :data:`MARKER` (JSON: tool, version, created in UTC ISO 8601) into ``folder``."""
    doc = {"tool": _TOOL, "version": __version__,
           "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    (folder / MARKER).write_text(json.dumps(doc) + "\n", encoding="utf-8")


def _has_marker(folder: Path) -> bool:
    try:
        if (folder / MARKER).stat().st_size > 4096:
            return False
        doc = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("tool") == _TOOL


def _written_by_old_gsgeo(folder: Path) -> bool:
    try:
        if (folder / "tileset.json").stat().st_size > _MAX_JSON:
            return False
        doc = json.loads((folder / "tileset.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(doc, dict) and isinstance(doc.get("asset"), dict) and \
        doc["asset"].get("generator") == _TOOL and isinstance(doc.get("extras"), dict) and \
        "gsgeo" in doc["extras"]


def foreign_entries(folder: Path) -> list[str]:
    """Entries of ``folder`` that a tileset written by gsgeo does not have (relative paths;
    symbolic links always count as foreign)."""
    odd = []
    with os.scandir(folder) as it:
        for e in it:
            if e.name in (MARKER, "tileset.json") and e.is_file(follow_symlinks=False):
                continue
            if e.name == FIT_DIR and e.is_dir(follow_symlinks=False):
                # the georeference versions' side files (gsgeo.tiles.georefhistory)
                with os.scandir(e.path) as fits:
                    odd += [f"{FIT_DIR}/{f.name}" for f in fits
                            if not (re.fullmatch(r"v\d+\.json", f.name) and f.is_file(follow_symlinks=False))]
                continue
            if e.name == "tiles" and e.is_dir(follow_symlinks=False):
                with os.scandir(e.path) as tiles:
                    odd += [f"tiles/{t.name}" for t in tiles
                            if not (t.name.endswith(".glb") and t.is_file(follow_symlinks=False))]
                continue
            odd.append(e.name)
    return sorted(odd)


def _within(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def check_output(input_path: str | os.PathLike, outdir: str | os.PathLike,
                 overwrite: bool) -> Path:
    """Check that ``outdir`` may receive (or, with ``overwrite``, replace) a tileset built
    from ``input_path``; returns it with symbolic links resolved. Raises InputError naming
    the reason otherwise. Touches nothing."""
    given = Path(outdir)
    if "\0" in str(given) or "\0" in str(input_path):
        raise InputError("a path holds a NUL character")
    try:
        out = given.resolve()
        inp = Path(input_path)
        inputs = {inp.resolve(), inp.parent.resolve() / inp.name}
        protected = {Path.cwd().resolve(): "the current directory"}
    except (OSError, RuntimeError) as exc:   # RuntimeError: a symlink loop (Python < 3.13)
        raise InputError(f"{given}: cannot resolve the path ({exc})") from None
    try:
        protected[Path.home().resolve()] = "the home directory"
    except (OSError, RuntimeError, KeyError):   # no home directory
        pass
    if out == out.parent or os.path.ismount(out):
        raise InputError(f"-o {given}: is a filesystem root or mount point; "
                         "choose a new folder inside it")
    for place, what in protected.items():
        if _within(place, out):
            raise InputError(f"-o {given}: is or holds {what}; choose a new folder")
    for p in inputs:
        if _within(p, out):
            raise InputError(f"-o {given}: holds the input {input_path}; replacing it would "
                             "delete the input, choose another folder")
    try:
        st = os.lstat(out)
    except FileNotFoundError:
        return out
    except OSError as exc:      # a parent is a file, a name too long, ...
        raise InputError(f"-o {given}: {exc.strerror}") from None
    if not stat.S_ISDIR(st.st_mode):
        raise InputError(f"{given} exists and is not a directory")
    try:
        empty = not any(out.iterdir())
        if empty:
            return out
        if not (_has_marker(out) or _written_by_old_gsgeo(out)):
            raise InputError(f"{given} exists, is not empty and is not a tileset written by "
                             f"gsgeo tiles (no {MARKER}); --overwrite replaces only those: "
                             "choose another folder")
        if not overwrite:
            raise InputError(f"{given} exists and is not empty; pass --overwrite to replace it")
        odd = foreign_entries(out)
    except OSError as exc:
        raise InputError(f"{given}: cannot read ({exc.strerror})") from None
    if odd:
        shown = ", ".join(odd[:5]) + (f" and {len(odd) - 5} more" if len(odd) > 5 else "")
        raise InputError(f"{given} holds files that are not part of a gsgeo tileset ({shown}); "
                         "--overwrite would delete them: move them away first")
    return out
