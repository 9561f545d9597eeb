"""Imports go one way (README, "Layout"): every module's imports, read from its syntax tree,
point to its own package or to a lower layer.

    config, geometry  <  mesh  <  fcm  <  fluid, dem, pd  <  coupling  <  simulation
                      <  verify, bench, tools, cli, preflight, __main__

``io`` (logging, CSV, XDMF, checkpoints, timing) may be imported from anywhere because it
imports nothing but ``config``. Packages of one layer do not import each other (fluid and
dem stay independent), except in the top layer of entry points. An import inside
``if __name__ == "__main__":`` is the entry point of a module run as a script (the former
command names, ``python -m fcm_fsi.config.docs``), not a dependency, and is not counted.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "fcm_fsi"

#: package (first name under fcm_fsi) → layer
LAYER = {"config": 0, "geometry": 0, "jit": 0, "mesh": 1, "fcm": 2, "fluid": 3, "dem": 3, "pd": 3, "coupling": 4, "simulation": 5,
         "verify": 6, "bench": 6, "tools": 6, "cli": 6, "preflight": 6, "api": 6, "__main__": 6, "__init__": 6}
TOP = max(LAYER.values())
#: the utility package and the only packages it may import
UTILITY, UTILITY_IMPORTS = "io", {"config"}


def package_of(module: str) -> str:
    """``fcm_fsi.dem.walls`` → ``dem``; ``fcm_fsi.cli`` → ``cli``; ``fcm_fsi`` → ``__init__``."""
    parts = module.split(".")
    assert parts[0] == "fcm_fsi", module
    return parts[1] if len(parts) > 1 else "__init__"


def violation(importer: str, imported: str) -> str | None:
    """Why ``importer`` may not import ``imported`` (module names under fcm_fsi), or None."""
    a, b = package_of(importer), package_of(imported)
    if a == b:
        return None
    for p in (a, b):
        if p != UTILITY and p not in LAYER:
            return f"package {p!r} has no layer (add it to LAYER and to the README's Layout)"
    if a == UTILITY:
        return None if b in UTILITY_IMPORTS else f"{UTILITY} imports only {sorted(UTILITY_IMPORTS)}, not {b}"
    if b == UTILITY:
        return None
    if LAYER[b] < LAYER[a] or LAYER[a] == LAYER[b] == TOP:
        return None
    if LAYER[b] == LAYER[a]:
        return f"{a} and {b} are one layer and must not import each other"
    return f"{a} (layer {LAYER[a]}) imports the higher layer {b} (layer {LAYER[b]})"


def _is_main_guard(node: ast.AST) -> bool:
    t = node.test if isinstance(node, ast.If) else None
    return (isinstance(t, ast.Compare) and isinstance(t.left, ast.Name) and t.left.id == "__name__"
            and len(t.comparators) == 1 and isinstance(t.comparators[0], ast.Constant)
            and t.comparators[0].value == "__main__")


def imports_of_source(module: str, source: str, is_package: bool = False) -> list[tuple[str, int]]:
    """(imported fcm_fsi module, line) of every import in ``source``, the module ``module``
    (``is_package``: the source is its ``__init__.py``); relative imports resolved, the names
    of ``from X import name`` taken as submodules where such a module file exists."""
    base = module.split(".") if is_package else module.split(".")[:-1]
    out: list[tuple[str, int]] = []

    def visit(node: ast.AST) -> None:
        if _is_main_guard(node):
            return
        if isinstance(node, ast.Import):
            out.extend((a.name, node.lineno) for a in node.names if a.name.split(".")[0] == "fcm_fsi")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                target = base[: len(base) - (node.level - 1)] + (node.module.split(".") if node.module else [])
            else:
                target = node.module.split(".") if node.module else []
            if target and target[0] == "fcm_fsi":
                for a in node.names:
                    sub = target + [a.name]
                    is_module = (ROOT.joinpath(*sub).with_suffix(".py").exists() or ROOT.joinpath(*sub).is_dir())
                    out.append((".".join(sub if is_module else target), node.lineno))
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(source))
    return out


def all_imports() -> list[tuple[str, str, int]]:
    """(importer, imported, line) over every module of the package."""
    rows = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        is_package = rel.name == "__init__"
        module = ".".join(rel.parent.parts if is_package else rel.parts)
        rows += [(module, imported, line) for imported, line in imports_of_source(module, path.read_text(), is_package)]
    return rows


def test_imports_go_one_way():
    rows = all_imports()
    assert len(rows) > 300                      # the parser found the package's imports
    bad = [f"{a}:{line} imports {b}: {why}" for a, b, line in rows if (why := violation(a, b))]
    assert not bad, "\n".join(bad)


# ------------------------------------------------------------------ the checker itself

@pytest.mark.parametrize("importer, imported", [
    ("fcm_fsi.fcm.domain", "fcm_fsi.fluid.navier_stokes"),      # fcm above fluid
    ("fcm_fsi.fcm.levelset", "fcm_fsi.dem.bodies"),             # fcm above dem
    ("fcm_fsi.fluid.phase_field", "fcm_fsi.dem.state"),         # fluid and dem: one layer
    ("fcm_fsi.dem.model", "fcm_fsi.fluid.solvers"),
    ("fcm_fsi.io.snapshots", "fcm_fsi.dem.output"),             # io imports only config
    ("fcm_fsi.io.checkpoint", "fcm_fsi.cli"),
    ("fcm_fsi.mesh.build", "fcm_fsi.coupling.dem_side"),        # mesh above coupling
    ("fcm_fsi.config.docs", "fcm_fsi.preflight"),               # config above the entry points
    ("fcm_fsi.config.dem", "fcm_fsi.geometry"),                 # config and geometry: one layer
    ("fcm_fsi.simulation.loop", "fcm_fsi.tools.run"),
    ("fcm_fsi.dem.model", "fcm_fsi.plugins.x"),                 # a package without a layer
])
def test_checker_finds_upward_imports(importer, imported):
    assert violation(importer, imported) is not None


@pytest.mark.parametrize("importer, imported", [
    ("fcm_fsi.fluid.phase_field", "fcm_fsi.fcm.cut"),
    ("fcm_fsi.fcm.levelset", "fcm_fsi.geometry"),
    ("fcm_fsi.dem.output", "fcm_fsi.io.csv"),
    ("fcm_fsi.io.checkpoint", "fcm_fsi.config.loader"),
    ("fcm_fsi.simulation.coupled", "fcm_fsi.dem.walls"),
    ("fcm_fsi.tools.verify", "fcm_fsi.verify.runner"),          # entry points among themselves
    ("fcm_fsi.dem.contact", "fcm_fsi.dem"),
])
def test_checker_allows_downward_imports(importer, imported):
    assert violation(importer, imported) is None


def test_checker_reads_relative_imports_and_skips_script_entry_points():
    src = ("from __future__ import annotations\n"
           "from . import L_SPRING\n"
           "from ..fluid.navier_stokes import cell_size\n"
           "import fcm_fsi.coupling.dem_side\n"
           "from .. import geometry\n"
           "def f():\n"
           "    from ..simulation import coupled\n"
           "if __name__ == '__main__':\n"
           "    from ..cli import main\n")
    got = imports_of_source("fcm_fsi.dem.walls", src)
    assert [m for m, _ in got] == ["fcm_fsi.dem", "fcm_fsi.fluid.navier_stokes", "fcm_fsi.coupling.dem_side",
                                   "fcm_fsi.geometry", "fcm_fsi.simulation.coupled"]
    bad = [m for m, _ in got if violation("fcm_fsi.dem.walls", m)]
    assert bad == ["fcm_fsi.fluid.navier_stokes", "fcm_fsi.coupling.dem_side", "fcm_fsi.simulation.coupled"]
    assert imports_of_source("fcm_fsi.dem", "from . import walls\n", is_package=True) == [("fcm_fsi.dem.walls", 1)]
