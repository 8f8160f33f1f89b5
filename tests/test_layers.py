"""The layers of gsgeo hold in every import, function-level ones included (docs/architecture.md,
"Layers"): solve <- crs <- measure <- (export, georef, report, tiles, store) <- service <-
(server, commands).

Every module of gsgeo/ and tests/ is read with ast; an import names a module (``import a.b``,
``from a import b`` -> a.b when that is a module, else a). Each test lists its offenders.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
WEB_STACK = ("fastapi", "starlette", "pydantic", "uvicorn")


def module_name(path: Path) -> str:
    rel = path.relative_to(REPO).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def load(folder: str) -> dict[str, tuple[Path, ast.Module]]:
    return {module_name(p): (p, ast.parse(p.read_text(encoding="utf-8"), str(p)))
            for p in sorted((REPO / folder).rglob("*.py"))}


GSGEO = load("gsgeo")


def absolute(mod: str, node: ast.ImportFrom, is_package: bool) -> str:
    """The module an ImportFrom names, relative imports resolved."""
    if not node.level:
        return node.module or ""
    base = mod.split(".")
    base = base if is_package else base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join([*base, *([node.module] if node.module else [])])


def imports(mod: str, path: Path, tree: ast.Module) -> list[tuple[str, int]]:
    """(module, line) of every import of a module, anywhere in it."""
    out = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            out += [(a.name, n.lineno) for a in n.names]
        elif isinstance(n, ast.ImportFrom):
            src = absolute(mod, n, path.name == "__init__.py")
            for a in n.names:
                sub = f"{src}.{a.name}"
                out.append((sub if sub in GSGEO else src, n.lineno))
    return out


def layer(mod: str) -> str:
    parts = mod.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 else mod


def offenders(source: str, forbidden: tuple[str, ...], allowed: tuple[str, ...] = ()) -> list[str]:
    out = []
    for mod, (path, tree) in GSGEO.items():
        if not (mod == source or mod.startswith(source + ".")):
            continue
        for imp, line in imports(mod, path, tree):
            if imp.startswith(allowed):
                continue
            if any(imp == f or imp.startswith(f + ".") for f in forbidden):
                out.append(f"{path.relative_to(REPO)}:{line} imports {imp}")
    return out


LAYERS = ("gsgeo.solve", "gsgeo.crs", "gsgeo.measure", "gsgeo.session", "gsgeo.export",
          "gsgeo.buildings",
          "gsgeo.georef", "gsgeo.report", "gsgeo.tiles", "gsgeo.aim", "gsgeo.store", "gsgeo.service",
          "gsgeo.server", "gsgeo.commands", "gsgeo.demo", "gsgeo.cli")


def test_solve_imports_no_other_layer():
    others = tuple(x for x in LAYERS if x != "gsgeo.solve")
    assert offenders("gsgeo.solve", others) == []


def test_crs_imports_nothing_above_it():
    assert offenders("gsgeo.crs", ("gsgeo.session", "gsgeo.store", "gsgeo.export", "gsgeo.tiles",
                                   "gsgeo.server", "gsgeo.demo", "gsgeo.commands",
                                   "gsgeo.measure", "gsgeo.service", "gsgeo.cli")) == []


def test_measure_imports_nothing_above_it():
    assert offenders("gsgeo.measure", ("gsgeo.session", "gsgeo.store", "gsgeo.export",
                                       "gsgeo.server", "gsgeo.service", "gsgeo.commands",
                                       "gsgeo.cli")) == []


def test_georef_imports_nothing_above_it():
    """gsgeo.georef sits beside export: it uses solve, crs and measure, never the service."""
    assert offenders("gsgeo.georef", ("gsgeo.session", "gsgeo.store", "gsgeo.export",
                                      "gsgeo.tiles", "gsgeo.server", "gsgeo.service",
                                      "gsgeo.commands", "gsgeo.demo", "gsgeo.cli")) == []


def test_report_renders_data_and_sits_below_the_service():
    """gsgeo.report renders the plain data gsgeo.service.reporting gathers, beside export."""
    assert offenders("gsgeo.report", ("gsgeo.service", "gsgeo.server", "gsgeo.commands",
                                      "gsgeo.cli", "gsgeo.store", "gsgeo.session",
                                      "gsgeo.export", "gsgeo.tiles", "gsgeo.demo",
                                      "gsgeo.georef")) == []


def test_buildings_sit_beside_export_and_use_only_the_maths_below():
    """gsgeo.buildings (LoD2 models, CityJSON) uses solve, crs and measure, never what is above."""
    assert offenders("gsgeo.buildings", ("gsgeo.session", "gsgeo.store", "gsgeo.export",
                                         "gsgeo.tiles", "gsgeo.server", "gsgeo.service",
                                         "gsgeo.commands", "gsgeo.demo", "gsgeo.cli",
                                         "gsgeo.georef", "gsgeo.report")) == []


def test_aim_sits_beside_tiles_and_uses_only_what_is_below():
    """gsgeo.aim (depth hints, views, matching) reads splats through gsgeo.tiles, never above."""
    assert offenders("gsgeo.aim", ("gsgeo.session", "gsgeo.store", "gsgeo.export",
                                   "gsgeo.server", "gsgeo.service", "gsgeo.commands",
                                   "gsgeo.demo", "gsgeo.cli", "gsgeo.georef", "gsgeo.report",
                                   "gsgeo.buildings")) == []


def test_the_server_reaches_the_store_only_through_the_service():
    assert offenders("gsgeo.server", ("gsgeo.store",)) == []


def test_store_is_persistence_only():
    assert offenders("gsgeo.store", ("gsgeo.export", "gsgeo.measure", "gsgeo.service",
                                     "gsgeo.server", "gsgeo.commands", "gsgeo.session",
                                     "gsgeo.cli")) == []


def test_only_server_and_commands_import_the_web_stack():
    out = [f"{path.relative_to(REPO)}:{line} imports {imp}"
           for mod, (path, tree) in GSGEO.items()
           if layer(mod) not in ("gsgeo.server", "gsgeo.commands")
           for imp, line in imports(mod, path, tree) if imp.split(".")[0] in WEB_STACK]
    assert out == []


def test_demo_does_not_run_the_command_line():
    assert offenders("gsgeo.demo", ("gsgeo.commands", "gsgeo.cli")) == []


def test_no_import_cycle_between_modules():
    """Tarjan's strongly connected components of the module graph: each is one module."""
    graph = {m: sorted({i for i, _ in imports(m, *GSGEO[m]) if i in GSGEO and i != m})
             for m in GSGEO}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    cycles: list[list[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in graph:
        if v not in index:
            strong(v)
    assert cycles == []


def private_uses(folder: str) -> list[str]:
    """`from x import _y`, `import x._y` and `x._y` where x is another gsgeo module."""
    modules = load(folder) if folder != "gsgeo" else GSGEO
    out = []
    for mod, (path, tree) in modules.items():
        aliases: dict[str, str] = {}
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom):
                src = absolute(mod, n, path.name == "__init__.py")
                for a in n.names:
                    if a.name.startswith("_") and not a.name.startswith("__") and src != mod:
                        out.append(f"{path.relative_to(REPO)}:{n.lineno} from {src} import {a.name}")
                    if f"{src}.{a.name}" in GSGEO:
                        aliases[a.asname or a.name] = f"{src}.{a.name}"
            elif isinstance(n, ast.Import):
                for a in n.names:
                    if any(p.startswith("_") and not p.startswith("__") for p in a.name.split(".")):
                        out.append(f"{path.relative_to(REPO)}:{n.lineno} import {a.name}")
                    if a.name.startswith("gsgeo"):
                        aliases[a.asname or a.name] = a.name
        for n in ast.walk(tree):
            if isinstance(n, ast.Attribute) and n.attr.startswith("_") \
                    and not n.attr.startswith("__"):
                target = ast.unparse(n.value)
                if target in aliases and aliases[target] != mod:
                    out.append(f"{path.relative_to(REPO)}:{n.lineno} {target}.{n.attr}")
    return out


def test_no_private_name_is_used_across_modules():
    assert private_uses("gsgeo") == []


#: Private names tests may reach into: none (tests use the public API).
KNOWN_PRIVATE_IN_TESTS: set[str] = set()


def test_tests_use_no_new_private_name_of_gsgeo():
    found = {f"{o.split(':')[0]}: {o.split(' ', 1)[1]}" for o in private_uses("tests")}
    assert found - KNOWN_PRIVATE_IN_TESTS == set()
