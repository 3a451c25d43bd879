"""The layering of the packages: imports only point down, ``sorofem`` <- ``soroshapes`` <- ``sorocontrol`` <-
``soro`` (the application layer, with the demos as its package data ``soro.demos``).

* ``sorofem`` (the ground floor) imports nothing from the three packages above it;
* ``soroshapes`` and ``sorocontrol`` use only the foundation modules of ``sorofem`` (:data:`FOUNDATION`);
* no package imports another package's private modules (``_name``) beyond the foundation helpers, except the
  few named in :data:`PRIVATE_ALLOWED` with the reason;
* no import cycle inside a package;
* the package list of ``pyproject.toml`` holds every package folder (a package left out would be missing from
  a wheel).

The walk is static (every ``import`` statement of every module, those inside functions included: they run
late, when the function is first called) and, for the function-level imports, also at run time: a workload
that reaches them runs with ``builtins.__import__`` watched, and every import statement executed is checked
against the same rules (a name built at run time, e.g. ``importlib.import_module(f"...")``, escapes the static
walk).
"""
import ast
import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The packages from the bottom up; the demos are the application's (package data soro.demos).
LAYERS = ("sorofem", "soroshapes", "sorocontrol", "soro")
#: What soroshapes and sorocontrol may import of sorofem: the documented foundation (sorofem/__init__.py),
#: with its submodules (``sorofem.sdf.properties``). ``sorofem._numba`` is numba's cache helper of every
#: compiled kernel, ``sorofem._lazy`` the lazy attributes of the package ``__init__``s: pure Python, no DOLFINx.
FOUNDATION = ("sorofem", "sorofem.errors", "sorofem.units", "sorofem.io", "sorofem.sdf", "sorofem.snapshots",
              "sorofem.materials", "sorofem._numba", "sorofem._lazy")
#: Private modules of a lower package that an upper module may import, with the reason.
PRIVATE_ALLOWED = {
    # soro doctor reports the DOLFINx support range and compiles a form quietly: the compatibility seam's checks
    ("soro.doctor", "sorofem._dolfinx"): "support_status() of the compatibility seam",
    ("soro.doctor", "sorofem._jit"): "silence_compiler_logs() for the form-JIT check",
    # the sweep's side-by-side groups compile the same forms: a longer FFCx wait, through the seam
    ("soro.sweep.runner", "sorofem._dolfinx"): "set_jit_timeout() for groups compiling side by side",
}


def _modules():
    """name -> path of every module of the four packages and of the demos (as ``soro.demos.NAME``)."""
    mods = {}
    for pkg in LAYERS:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            mods[name.removesuffix(".__init__")] = path
    for path in sorted((ROOT / "demos").rglob("*.py")):
        name = ".".join(("soro", "demos", *path.relative_to(ROOT / "demos").with_suffix("").parts))
        mods[name.removesuffix(".__init__")] = path
    return mods


MODULES = _modules()


def _known(name):
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name


def imports_of(module, source=None):
    """(line, imported module, inside a function) of every import statement of ``module`` naming one of the
    four packages; relative imports resolved, ``from pkg import sub`` taken as ``pkg.sub``."""
    path = MODULES[module]
    tree = ast.parse(source if source is not None else path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []

    def visit(node, nested):
        for child in ast.iter_child_nodes(node):
            inner = nested or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            names = []
            if isinstance(child, ast.Import):
                names = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")[:len(package.split(".")) - (child.level - 1)]
                    mod = ".".join(base + ([child.module] if child.module else []))
                else:
                    mod = child.module or ""
                names = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in MODULES else mod for a in child.names]
            for name in names:
                if name.split(".")[0] in LAYERS:
                    found.append((child.lineno, _known(name) or name, inner))
            visit(child, inner)
    visit(tree, False)
    return found


def _layer(module):
    return LAYERS.index(module.split(".")[0])


def _private(module):
    return any(part.startswith("_") for part in module.split("."))


def violation(importer, imported):
    """Why ``importer`` may not import ``imported`` (None when it may)."""
    a, b = importer.split(".")[0], imported.split(".")[0]
    if a == b:
        return None
    if _layer(imported) > _layer(importer):
        return f"{a} is below {b}: imports point down ({' <- '.join(LAYERS)})"
    if a in ("soroshapes", "sorocontrol") and b == "sorofem" and \
            not any(imported == f or imported.startswith(f + ".") for f in FOUNDATION if f != "sorofem") \
            and imported != "sorofem":
        return f"{a} uses only sorofem's foundation modules ({', '.join(FOUNDATION[1:])})"
    if _private(imported) and imported not in FOUNDATION and (importer, imported) not in PRIVATE_ALLOWED:
        return f"{imported} is private to {b}"
    return None


def check(modules=MODULES):
    problems = []
    for module in modules:
        for line, imported, inner in imports_of(module):
            why = violation(module, imported)
            if why:
                where = "inside a function" if inner else "at load time"
                problems.append(f"{MODULES[module].relative_to(ROOT)}:{line}: imports {imported} {where}: {why}")
    return problems


def test_imports_point_down_and_use_only_the_foundation():
    problems = check()
    assert not problems, "layering violations:\n" + "\n".join(problems)


def test_the_walk_finds_an_upward_import_at_load_time_and_in_a_function():
    """The check itself: a module of sorofem that imports soroshapes (inside a function), of soroshapes that
    imports sorofem.fem (the FEM layer, not foundation) and of sorocontrol that imports soro, each fail."""
    cases = {"sorofem.snapshots": "\ndef _f():\n    from soroshapes import Shapes\n",
             "soroshapes.dvs": "\nfrom sorofem.fem import Fem\n",
             "sorocontrol.board": "\ndef _g():\n    import soro.play\n"}
    for module, extra in cases.items():
        found = [(imp, inner) for _, imp, inner in imports_of(module, MODULES[module].read_text() + extra)
                 if violation(module, imp)]
        assert len(found) == 1, (module, found)
    assert violation("sorofem.snapshots", "soroshapes.shapes").startswith("sorofem is below soroshapes")
    assert violation("soroshapes.dvs", "sorofem.fem").startswith("soroshapes uses only sorofem's foundation")
    assert violation("soro.cli", "soroshapes._beam") == "soroshapes._beam is private to soroshapes"
    assert violation("soro.cli", "sorofem.fem") is None and violation("soroshapes.shapes", "sorofem.sdf.core") is None


def _cycles(package):
    """The import cycles among the modules of ``package`` (strongly connected components of more than one)."""
    mods = [m for m in MODULES if m.split(".")[0] == package and not m.startswith("soro.demos")]
    edges = {m: {imp for _, imp, _ in imports_of(m) if imp in mods and imp != m} for m in mods}
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
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
                out.append(sorted(comp))
    for m in mods:
        if m not in index:
            visit(m)
    return out


@pytest.mark.parametrize("package", ["sorofem", "soroshapes", "sorocontrol", "soro"])
def test_no_import_cycle_inside_a_package(package):
    assert _cycles(package) == [], f"import cycles in {package}"


def test_sdf_base_class_imports_none_of_its_primitives():
    """The base class registers its primitives, operations and compiler instead of importing them."""
    assert _cycles("sorofem") == []
    imported = {imp for _, imp, _ in imports_of("sorofem.sdf.core")}
    assert not imported & {"sorofem.sdf.primitives2d", "sorofem.sdf.primitives3d", "sorofem.sdf._codegen"}
    from sorofem import sdf
    from sorofem.sdf import core
    assert isinstance(sdf.Circle(1.0).extrude(0.5), sdf.Extrude) and isinstance(sdf.Circle(1.0).revolve(), sdf.Revolve)
    assert {"circle", "sphere", "line"} <= core._PRIMITIVE_OPS and sdf.is_csg(sdf.Circle(1.0) - sdf.Rectangle(1, 1))
    assert sdf.is_csg(sdf.Circle(1.0).offset(0.1)) is False


def test_pyproject_lists_every_package():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(cfg["packages"])
    folders = {".".join(p.parent.relative_to(ROOT).parts) for pkg in LAYERS for p in (ROOT / pkg).rglob("__init__.py")}
    assert folders - listed == set(), "add these packages to [tool.setuptools] packages in pyproject.toml"
    assert listed - folders == {"soro.demos"} and cfg["package-dir"] == {"soro.demos": "demos"}


#: Process entry points outside the application layer that may exit: the board service's own command lines
#: (``python -m sorocontrol.server`` and the unit's stop hook ``python -m sorocontrol.vent``, run by systemd on
#: the board, hardware/soro-board.service): their ``main``/``__main__`` and the argument helpers of ``main``.
EXIT_ALLOWED = {("sorocontrol.server", "main"), ("sorocontrol.server", "_read_secret"),
                ("sorocontrol.server", "_import_plant"), ("sorocontrol.server", "_receive_plant"),
                ("sorocontrol.server", "<module>"), ("sorocontrol.vent", "<module>")}


def exits(module, source=None):
    """(function, line) of every ``raise SystemExit`` / ``sys.exit(...)`` / ``exit(...)`` in ``module``."""
    tree = ast.parse(source if source is not None else MODULES[module].read_text())
    found = []

    def visit(node, func):
        for child in ast.iter_child_nodes(node):
            name = child.name if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) else func
            hit = (isinstance(child, ast.Raise) and child.exc is not None and "SystemExit" in ast.unparse(child.exc)) \
                or (isinstance(child, ast.Call) and ast.unparse(child.func) in ("sys.exit", "exit", "os._exit"))
            if hit:
                found.append((func, child.lineno))
            visit(child, name)
    visit(tree, "<module>")
    return found


def test_only_the_cli_turns_errors_into_exit_codes():
    """Library code raises SoroErrors; exit codes are the CLI's (soro/), besides the board service's entry points."""
    problems = [f"{MODULES[m].relative_to(ROOT)}:{line} exits in {func}()" for m in MODULES
                if m.split(".")[0] != "soro" for func, line in exits(m) if (m, func) not in EXIT_ALLOWED]
    assert not problems, "raise a SoroError subclass instead (the CLI turns it into the exit status):\n" + \
        "\n".join(problems)
    assert exits("sorofem.io", "def f():\n    raise SystemExit('no')\n") == [("f", 2)]


# ------------------------------------------------------------------------------------------------ at run time
_WATCH = r'''
import builtins, importlib, json, sys
LAYERS = ("sorofem", "soroshapes", "sorocontrol", "soro")
seen = set()
real_import, real_import_module = builtins.__import__, importlib.import_module

def record(importer, full, fromlist=()):
    if importer == "sorofem._lazy":      # a package's lazy attribute: its own submodule
        return
    if importer.split(".")[0] in LAYERS and full.split(".")[0] in LAYERS:
        for sub in (fromlist or ()):
            seen.add((importer, f"{full}.{sub}"))
        seen.add((importer, full))

def watched(name, globals=None, locals=None, fromlist=(), level=0):
    # the importer is the caller's module (also for a bare __import__("...") call without globals)
    importer = sys._getframe(1).f_globals.get("__name__", "")
    full = name
    if level:
        package = (globals or {}).get("__package__") or importer
        base = package.split(".")[:len(package.split(".")) - (level - 1)]
        full = ".".join(base + ([name] if name else []))
    record(importer, full, fromlist)
    return real_import(name, globals, locals, fromlist, level)

def watched_import_module(name, package=None):
    importer = sys._getframe(1).f_globals.get("__name__", "")
    record(importer, importlib.util.resolve_name(name, package) if name.startswith(".") else name)
    return real_import_module(name, package)

builtins.__import__, importlib.import_module = watched, watched_import_module
try:
    exec(compile(open(sys.argv[1]).read(), sys.argv[1], "exec"), {"__name__": "__workload__"})
finally:
    builtins.__import__, importlib.import_module = real_import, real_import_module
    print("SEEN " + json.dumps(sorted(seen)))
'''

# The workload: what reaches the function-level imports of the libraries (sdf operations, compiled kernels,
# properties and export; the robots' designs, part STL and chamber check; snapshots written and read; a small
# FEM solve with its mesh; a beam's statics and strain recovery).
_WORKLOAD = r'''
import tempfile
from pathlib import Path

import numpy as np

from sorofem import materials, robots, sdf
from sorofem.units import mm

tmp = Path(tempfile.mkdtemp())
shape = sdf.Rectangle(20 * mm, 10 * mm).rotate(30, deg=True) - sdf.Circle(3 * mm)
pts = np.random.default_rng(0).uniform(-0.02, 0.02, (200_000, 2))
shape(pts); shape.gradient(pts[:100]); shape.section_properties(); shape.to_png(tmp / "s.png")
solid = shape.extrude(5 * mm) | sdf.Circle(2 * mm).revolve(offset=10 * mm)
solid.mass_properties(); solid.to_stl(tmp / "s.stl", resolution=1 * mm)
d = robots.design("bending_actuator")
robots.export_part(d.parts[0], tmp / "a.stl", resolution=2 * mm); robots.chamber_check(d.parts[0])

from sorofem.fem import Fem
from sorofem.mesh import Mesh
msh = Mesh.from_sdf(sdf.Rectangle(40 * mm, 6 * mm).translate((20 * mm, 0.0)), size=3 * mm)
fem = Fem(msh, material=materials.NeoHookean(E=1e5, nu=0.4))
fem.add_support("left").add_gravity()
traj = fem.solve(steps=2)
traj.save(tmp / "bar.h5")

from sorofem.snapshots import Snapshots
snap = Snapshots(tmp / "bar.h5")

from soroshapes import Basis, Shapes
from soroshapes.dvs import Backbone, recover_strains
shp = Shapes(Basis.chebyshev(2), dofs=(0, 2, 2, 0, 0, 0), length=0.04, section=sdf.Circle(3 * mm),
             material=materials.NeoHookean(E=1e5, nu=0.4)).add_gravity()
shp.statics()
recover_strains(tmp / "bar.h5", Backbone.line([0.0, 0.0], [40 * mm, 0.0]), samples=11)
'''


@pytest.mark.slow
def test_imports_made_at_run_time_point_down(tmp_path, subprocess_env):
    workload = tmp_path / "workload.py"
    workload.write_text(_WORKLOAD)
    res = subprocess.run([sys.executable, "-c", _WATCH, str(workload)], capture_output=True, text=True,
                         env=subprocess_env, timeout=900, cwd=tmp_path)
    line = next((ln for ln in res.stdout.splitlines() if ln.startswith("SEEN ")), None)
    assert res.returncode == 0 and line, res.stdout[-2000:] + res.stderr[-4000:]
    seen = [(a, _known(b) or b) for a, b in json.loads(line[5:])]
    libraries = {a for a, _ in seen if a.split(".")[0] != "soro"}
    assert {"sorofem.sdf.core", "sorofem.fem.problem", "soroshapes.dvs"} <= libraries   # it reached them
    problems = [f"{a} imports {b} at run time: {violation(a, b)}" for a, b in seen if violation(a, b)]
    assert not problems, "\n".join(problems)
