"""Type-annotation coverage of the package, read from the source (``ast``; nothing is imported).

Counted: every ``def`` / ``async def`` of ``vision_calib/`` (module functions, methods, nested functions).
- return: the function has a ``-> ...`` annotation (``__init__`` included: ``-> None``);
- every argument: each parameter besides a method's ``self`` / ``cls`` is annotated (``*args`` / ``**kw`` too),
  among the functions that take at least one such parameter.
"public API" is the public functions (no leading underscore, nested ones excluded) and the public methods of public
classes of the modules of ``--api`` (default: rig, identify, experiment), without their private submodules.

    python benchmarks/annotations.py                       # the table per floor, the package and the public API
    python benchmarks/annotations.py --list rig identify   # also the public-API functions still lacking one
    python benchmarks/annotations.py --root OTHER/vision_calib   # another checkout (e.g. a baseline)
"""

from __future__ import annotations

import argparse
import ast
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "vision_calib"
API = ("rig", "identify", "experiment")


@dataclass(frozen=True)
class Func:
    """One function: where (module path relative to the package, line), qualified name, whether it is part of the
    public API (public name, not nested, in a public class or at module level), return and argument annotations."""

    module: str
    line: int
    name: str
    public: bool
    has_params: bool
    returns: bool
    all_args: bool


def functions(path: Path, rel: str) -> list[Func]:
    """Every function of one source file, methods and nested functions included."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    out: list[Func] = []

    def visit(body, prefix: str, public: bool, in_class: bool, nested: bool) -> None:
        for node in body:
            if isinstance(node, ast.ClassDef):
                visit(node.body, f"{prefix}{node.name}.", public and not node.name.startswith("_"), True, nested)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                params = a.posonlyargs + a.args + a.kwonlyargs + [p for p in (a.vararg, a.kwarg) if p is not None]
                if in_class and params and params[0].arg in ("self", "cls"):
                    params = params[1:]
                own = not node.name.startswith("_") or (node.name.startswith("__") and node.name.endswith("__"))
                out.append(Func(rel, node.lineno, prefix + node.name, public and own and not nested, bool(params),
                                node.returns is not None, all(p.annotation is not None for p in params)))
                visit(node.body, f"{prefix}{node.name}.", False, False, True)
            elif isinstance(node, (ast.If, ast.Try, ast.With, ast.For, ast.While)):
                for part in ("body", "orelse", "finalbody"):
                    visit(getattr(node, part, []), prefix, public, in_class, nested)
                for h in getattr(node, "handlers", []):
                    visit(h.body, prefix, public, in_class, nested)

    visit(tree.body, "", True, False, False)
    return out


def read_package(root: Path = ROOT) -> list[Func]:
    return [f for p in sorted(root.rglob("*.py")) for f in functions(p, p.relative_to(root).as_posix())]


def floor(f: Func) -> str:
    return f.module.split("/")[0].removesuffix(".py") if "/" in f.module else "(top-level modules)"


def in_api(f: Func, api=API) -> bool:
    parts = f.module.removesuffix(".py").split("/")
    return f.public and parts[0] in api and not any(p.startswith("_") and p != "__init__" for p in parts[1:])


def row(name: str, fs: list[Func]) -> str:
    n, with_params = len(fs), [f for f in fs if f.has_params]
    ret = sum(f.returns for f in fs) / n if n else float("nan")
    args = sum(f.all_args for f in with_params) / len(with_params) if with_params else float("nan")
    return f"{name:<40} {n:>6} {100 * ret:>8.1f} % {len(with_params):>8} {100 * args:>10.1f} %"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=ROOT, help="the vision_calib package directory to read")
    ap.add_argument("--api", nargs="+", default=list(API), help="floors whose public functions are the public API")
    ap.add_argument("--list", nargs="*", metavar="FLOOR", help="list the public-API functions of these floors (all "
                    "API floors when none given) that lack a return or an argument annotation")
    args = ap.parse_args(argv)
    fs = read_package(args.root)
    print(f"annotation coverage of {args.root}")
    print(f"{'':<40} {'funcs':>6} {'return':>10} {'w/ params':>8} {'every arg':>12}")
    for name in sorted({floor(f) for f in fs}):
        print(row(name, [f for f in fs if floor(f) == name]))
    print(row("package", fs))
    api = [f for f in fs if in_api(f, args.api)]
    print(row(f"public API ({', '.join(args.api)})", api))
    if args.list is not None:
        wanted = set(args.list or args.api)
        for f in api:
            if floor(f) in wanted and (not f.returns or (f.has_params and not f.all_args)):
                what = " and ".join(w for w, bad in (("return", not f.returns),
                                                     ("arguments", f.has_params and not f.all_args)) if bad)
                print(f"  {f.module}:{f.line} {f.name}: {what}")


if __name__ == "__main__":
    main()
