"""The architecture contract (:mod:`vision_calib.layers`), read from every module's imports (``ast``; imports
inside functions included): imports go down the floors, siblings on a floor are independent, no import
circle (across packages or inside one), no import of another module's private names, and ``identify`` /
``kinematics`` reach no cv2 / torch / OpenGL.

The checkers take a plain import graph, so the tests below also feed them made-up graphs with one
violation each and expect it named.
"""

from __future__ import annotations

import ast
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from vision_calib.layers import EXCEPTIONS, HEAVY, LAYERS, LIGHT

PKG = "vision_calib"
ROOT = Path(__file__).resolve().parents[1] / PKG


@dataclass(frozen=True)
class Import:
    """One import statement's target: ``src`` module imports ``dst`` (a module of the package, or the top
    name of a third-party module), binding ``name`` from it (None: the module itself); ``line``: where."""

    src: str
    dst: str
    name: str | None
    line: int


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def read_imports(root: Path = ROOT) -> tuple[set[str], list[Import]]:
    """(modules of the package, every import statement of every module), lazy imports included."""
    paths = {module_name(p, root): p for p in sorted(root.rglob("*.py"))}
    out = []
    for mod, path in paths.items():
        is_pkg = path.name == "__init__.py"
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        imported_modules = {}  # local name -> package module bound by "import x" / "from p import mod"
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.split(".")[0] == PKG:
                        out.append(Import(mod, a.name, None, node.lineno))
                        if a.asname:
                            imported_modules[a.asname] = a.name
                    else:
                        out.append(Import(mod, a.name.split(".")[0], None, node.lineno))
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = mod.split(".")[: None if is_pkg else -1]
                    base = base[: len(base) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target.split(".")[0] != PKG:
                    if target != "__future__":
                        out.append(Import(mod, target.split(".")[0], None, node.lineno))
                    continue
                for a in node.names:
                    sub = f"{target}.{a.name}"
                    if sub in paths:
                        out.append(Import(mod, sub, None, node.lineno))
                        imported_modules[a.asname or a.name] = sub
                    else:
                        out.append(Import(mod, target, a.name, node.lineno))
        for node in ast.walk(tree):  # module._private through a module bound by an import
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in imported_modules and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                out.append(Import(mod, imported_modules[node.value.id], node.attr, node.lineno))
    return set(paths), out


def floor_of(mod: str) -> str:
    """The floor name of a package module: its top-level subpackage or module ("" for the package itself)."""
    parts = mod.split(".")
    return parts[1] if len(parts) > 1 else ""


def layer_violations(imports: list[Import], layers=LAYERS) -> list[str]:
    """Imports that run up the floors or sideways to a sibling, as "src -> dst (line L)", plus modules on no floor."""
    rank = {name: i for i, floor in enumerate(layers) for name in floor}
    bad = []
    for imp in imports:
        if not imp.dst.startswith(PKG):
            continue
        a, b = floor_of(imp.src), floor_of(imp.dst)
        for end in (a, b):
            if end and end not in rank:
                bad.append(f"{end}: on no floor of vision_calib.layers.LAYERS")
        if not a or not b or a == b or a not in rank or b not in rank:
            continue
        if rank[b] < rank[a]:
            bad.append(f"{imp.src} -> {imp.dst} (line {imp.line}): {b} is above {a}")
        elif rank[b] == rank[a]:
            bad.append(f"{imp.src} -> {imp.dst} (line {imp.line}): {a} and {b} are siblings on one floor")
    return sorted(set(bad))


def import_cycles(imports: list[Import]) -> list[list[str]]:
    """Strongly connected components (> 1 module, or a module importing itself) of the module graph."""
    graph: dict[str, set[str]] = {}
    for imp in imports:
        if imp.dst.startswith(PKG):
            graph.setdefault(imp.src, set()).add(imp.dst)
            graph.setdefault(imp.dst, set())
    index, low, stack, on, comps = {}, {}, [], set(), []
    counter = [0]

    def visit(v):  # Tarjan (the graph is small: recursion depth <= number of modules)
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
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
            if len(comp) > 1 or v in graph[v]:
                comps.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(comps)


def private_imports(imports: list[Import]) -> list[str]:
    """Imports of a private (_name) object of another module. A private *submodule* may be imported from its
    own package."""
    bad = []
    for imp in imports:
        if not imp.dst.startswith(PKG) or imp.src == imp.dst:
            continue
        last = imp.name if imp.name is not None else imp.dst.rsplit(".", 1)[-1]
        if not last.startswith("_") or last.startswith("__"):
            continue
        if imp.name is None and imp.dst.rsplit(".", 1)[0] == imp.src.rsplit(".", 1)[0]:
            continue  # a private submodule of the importer's own package
        if imp.name is None and imp.dst.rsplit(".", 1)[0] == imp.src:
            continue  # a package's __init__ importing its own private submodule
        bad.append(f"{imp.src} -> {imp.dst}.{imp.name} (line {imp.line})" if imp.name else
                   f"{imp.src} -> {imp.dst} (line {imp.line})")
    return sorted(set(bad))


def heavy_imports(imports: list[Import], light=LIGHT, heavy=HEAVY, exceptions=()) -> list[str]:
    """Heavy third-party imports reached from a module of the ``light`` floors, with the path that reaches them
    (``exceptions``: (module, heavy module) pairs left out)."""
    graph: dict[str, list[Import]] = {}
    for imp in imports:
        if (imp.src, imp.dst) not in exceptions:
            graph.setdefault(imp.src, []).append(imp)
    bad = []
    for start in sorted(graph):
        if floor_of(start) not in light:
            continue
        seen, todo = {start: [start]}, [start]
        while todo:
            v = todo.pop()
            for imp in graph.get(v, ()):
                if imp.dst in heavy:
                    bad.append(f"{' -> '.join(seen[v])} imports {imp.dst} (line {imp.line})")
                elif imp.dst.startswith(PKG) and imp.dst not in seen:
                    seen[imp.dst] = seen[v] + [imp.dst]
                    todo.append(imp.dst)
    return sorted(set(bad))


MODULES, IMPORTS = read_imports()


# ---------------------------------------------------------------- the package keeps the contract
def test_every_package_module_is_on_a_floor():
    floors = {n for f in LAYERS for n in f}
    assert len(floors) == sum(len(f) for f in LAYERS), "a name is on two floors"
    missing = sorted({floor_of(m) for m in MODULES} - floors - {""})
    assert not missing, f"modules on no floor of vision_calib.layers.LAYERS: {missing}"


def test_rooms_hold_one_job_each():
    """``io`` reads and writes data files only; the report (report.json and its schema, summary, HTML, plots,
    overlays, the hand-eye block) is a room of its own, above the stages it reports on and below the pipelines that
    write it; the controller exports and the reading of a result folder are ``deploy``'s."""
    rank = {name: i for i, floor in enumerate(LAYERS) for name in floor}
    assert rank["experiment"] < rank["report"] < min(rank[s] for s in ("io", "measure", "identify", "rig"))
    assert rank["deploy"] < rank["io"]
    room = {m: floor_of(m) for m in MODULES}
    for mod in ("build", "summary", "write", "text", "html", "plots", "overlay", "handeye"):
        assert room.get(f"{PKG}.report.{mod}") == "report", mod
    assert room.get(f"{PKG}.deploy.export") == "deploy"
    assert (ROOT / "report" / "schema.json").is_file()
    io_files = sorted(p.name for p in (ROOT / "io").iterdir())
    bad = [n for n in io_files if any(w in n for w in ("report", "plot", "overlay", "controller", "schema"))]
    assert not bad, f"vision_calib/io/ holds report or controller-export files: {bad}"


def test_imports_go_down_the_floors():
    bad = layer_violations(IMPORTS)
    assert not bad, "imports against vision_calib.layers.LAYERS:\n" + "\n".join(bad)


def test_no_import_circle():
    cycles = import_cycles(IMPORTS)
    assert not cycles, "import circles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_no_private_name_imported_from_another_module():
    bad = private_imports(IMPORTS)
    assert not bad, "private names imported from another module:\n" + "\n".join(bad)


def private_names_used_by(path: Path) -> list[str]:
    """Private (_name) objects or submodules of the package that a module outside it (a test) imports, or reaches
    as ``module._name`` through a package module it imported, as "name (line L)". A private function the same file
    replaces to plant a fault (``monkeypatch.setattr(module, "_name", ...)``) may be read there (the original it
    wraps). Test-local helpers (names from other test modules) are not the package's and are not looked at."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    private = lambda name: name.startswith("_") and not name.startswith("__")  # noqa: E731
    bad, modules = [], {}  # modules: local name -> package module bound by an import
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == PKG:
                    modules[a.asname or a.name.split(".")[0]] = a.name if a.asname else PKG
                    if any(map(private, a.name.split("."))):
                        bad.append(f"{a.name} (line {node.lineno})")
        elif isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").split(".")[0] == PKG:
            if any(map(private, node.module.split("."))):
                bad.append(f"{node.module} (line {node.lineno})")
            for a in node.names:
                if private(a.name):
                    bad.append(f"{node.module}.{a.name} (line {node.lineno})")
                modules[a.asname or a.name] = f"{node.module}.{a.name}"
    planted = {(n.args[0].id, n.args[1].value) for n in ast.walk(tree)
               if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "setattr"
               and isinstance(n.func.value, ast.Name) and n.func.value.id == "monkeypatch" and len(n.args) >= 2
               and isinstance(n.args[0], ast.Name) and isinstance(n.args[1], ast.Constant)}
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules
                and private(node.attr) and (node.value.id, node.attr) not in planted):
            bad.append(f"{modules[node.value.id]}.{node.attr} (line {node.lineno})")
    return sorted(set(bad))


def test_tests_use_no_private_name_of_the_package():
    """The tests exercise the package through its public names, as a user would (a helper a test needs is public
    and documented)."""
    tests = Path(__file__).resolve().parent
    bad = [f"{p.relative_to(tests.parent)}: {b}" for p in sorted(tests.rglob("*.py")) for b in private_names_used_by(p)]
    assert not bad, "tests import private names of vision_calib:\n" + "\n".join(bad)


def test_identify_and_kinematics_reach_no_cv2_torch_opengl():
    bad = heavy_imports(IMPORTS, exceptions=EXCEPTIONS)
    assert not bad, "\n".join(bad)


def test_every_listed_exception_is_still_needed():
    """vision_calib.layers.EXCEPTIONS only shrinks: an entry whose import is gone must be deleted."""
    present = {(imp.src, imp.dst) for imp in IMPORTS}
    stale = [pair for pair in EXCEPTIONS if pair not in present]
    assert not stale, f"remove from vision_calib.layers.EXCEPTIONS (no longer imported): {stale}"


def test_identify_and_kinematics_import_light_at_run_time(tmp_path):
    """The same at run time: importing every identify/kinematics module loads none of the heavy modules."""
    import subprocess

    mods = sorted(m for m in MODULES if floor_of(m) in LIGHT)
    code = ("import importlib, sys\n"
            f"for m in {mods!r}: importlib.import_module(m)\n"
            f"print(sorted(h for h in {HEAVY!r} if h in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=ROOT.parent)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


# ---------------------------------------------------------------- the checkers catch a violation
def _fake(*edges) -> list[Import]:
    return [Import(f"{PKG}.{a}", f"{PKG}.{b}" if b not in HEAVY else b, name, 1) for a, b, name in edges]


GOOD = [("cli", "study.run", None), ("study.run", "experiment.steps", None), ("experiment.steps", "report.build", None),
        ("report.build", "measure.pose", None), ("measure.pose", "rig.base", None), ("rig.base", "identify.lse", None),
        ("identify.lse", "kinematics.serial", None), ("kinematics.serial", "config", None),
        ("config", "frames", None), ("frames", "errors", None)]


def test_checkers_pass_a_graph_that_goes_down():
    imports = _fake(*GOOD)
    assert layer_violations(imports) == []
    assert import_cycles(imports) == []
    assert private_imports(imports) == []
    assert heavy_imports(imports) == []


def test_a_back_arrow_is_named():
    bad = layer_violations(_fake(*GOOD, ("measure.detect", "io.atomic", "jsonable")))
    assert bad == ["vision_calib.measure.detect -> vision_calib.io.atomic (line 1): io is above measure"]


def test_a_sibling_arrow_is_named():
    bad = layer_violations(_fake(*GOOD, ("render.coverage", "sensor.cpu", None)))
    assert bad == ["vision_calib.render.coverage -> vision_calib.sensor.cpu (line 1): render and sensor are siblings "
                   "on one floor"]


def test_a_module_on_no_floor_is_named():
    assert layer_violations(_fake(("newpkg.x", "frames", None))) == ["newpkg: on no floor of vision_calib.layers.LAYERS"]


def test_a_circle_inside_a_package_is_named():
    cycles = import_cycles(_fake(*GOOD, ("study.plots", "study.tables", None), ("study.tables", "study.plots", "_value")))
    assert cycles == [[f"{PKG}.study.plots", f"{PKG}.study.tables"]]


def test_a_circle_through_a_lazy_import_is_found_in_source(tmp_path):
    """read_imports sees an import inside a function, and the private name it takes."""
    pkg = tmp_path / PKG / "measure"
    pkg.mkdir(parents=True)
    (tmp_path / PKG / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "detect.py").write_text("def f():\n    from .seeded import refine\n    return refine\n")
    (pkg / "seeded.py").write_text("from .detect import _subpix\n\ndef refine():\n    pass\n")
    mods, imports = read_imports(tmp_path / PKG)
    assert mods == {PKG, f"{PKG}.measure", f"{PKG}.measure.detect", f"{PKG}.measure.seeded"}
    assert import_cycles(imports) == [[f"{PKG}.measure.detect", f"{PKG}.measure.seeded"]]
    assert private_imports(imports) == [f"{PKG}.measure.seeded -> {PKG}.measure.detect._subpix (line 1)"]


def test_a_private_attribute_through_a_module_is_named(tmp_path):
    pkg = tmp_path / PKG / "io"
    pkg.mkdir(parents=True)
    (tmp_path / PKG / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "rosi.py").write_text("def _target():\n    pass\n")
    (pkg / "visp.py").write_text("from . import rosi\n\nrosi._target()\n")
    _, imports = read_imports(tmp_path / PKG)
    assert private_imports(imports) == [f"{PKG}.io.visp -> {PKG}.io.rosi._target (line 3)"]


def test_a_heavy_import_reached_from_identify_is_named():
    bad = heavy_imports(_fake(*GOOD, ("identify.handeye_problem", "measure.reprojection", None),
                              ("measure.reprojection", "cv2", None)))
    assert bad == [f"{PKG}.identify.handeye_problem -> {PKG}.measure.reprojection imports cv2 (line 1)"]


def test_a_private_name_used_by_a_test_is_named(tmp_path):
    f = tmp_path / "test_x.py"
    f.write_text("from vision_calib.measure.intrinsics import PARAM_NAMES, _jac\n"
                 "from vision_calib.targets.kinds import _grid\n"
                 "import vision_calib.measure.seeded as seeded\n"
                 "from vision_calib.experiment import image_chain\n"
                 "from helpers import _local\n"
                 "seeded._Refiner(image_chain.worker_pid, image_chain._W, _local)\n"
                 "def test_fault(monkeypatch):\n"
                 "    real = seeded._from_seed\n"
                 "    monkeypatch.setattr(seeded, '_from_seed', lambda *a: None or real(*a))\n")
    assert private_names_used_by(f) == [f"{PKG}.experiment.image_chain._W (line 6)",
                                        f"{PKG}.measure.intrinsics._jac (line 1)",
                                        f"{PKG}.measure.seeded._Refiner (line 6)",
                                        f"{PKG}.targets.kinds._grid (line 2)"]


@pytest.mark.parametrize("floor", [n for f in LAYERS for n in f])
def test_floor_names_are_modules_of_the_package(floor):
    assert (ROOT / floor).is_dir() or (ROOT / f"{floor}.py").is_file(), f"{floor}: no such module in {ROOT}"
