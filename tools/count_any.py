"""Share of function parameters annotated ``Any`` in jwarp/ (issue "Finish the house": "22% of
parameters are typed Any").

    python tools/count_any.py [--facade] [--list]

Counts the parameters (``self``/``cls`` excluded) of every ``def`` in jwarp/*.py: annotated,
annotated exactly ``Any`` (or ``typing.Any``), unannotated. ``--facade``: only the functions and
classes' ``__init__`` that ``jwarp.__all__`` names (found where they are defined) and their
public methods. ``--list``: print each ``Any`` parameter.
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _is_any(node: ast.expr | None) -> bool:
    if node is None:
        return False
    if isinstance(node, ast.Constant) and node.value == "Any":
        return True
    return (isinstance(node, ast.Name) and node.id == "Any") or (
        isinstance(node, ast.Attribute) and node.attr == "Any")


def _params(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> list[ast.arg]:
    a = fn.args
    args = [*a.posonlyargs, *a.args, *a.kwonlyargs]
    args += [x for x in (a.vararg, a.kwarg) if x is not None]
    return [x for x in args if x.arg not in ("self", "cls")]


def _functions(tree: ast.AST, names: set[str] | None):
    """(qualified name, function) of the module's functions and methods; ``names``: only those
    top-level names (a class: its ``__init__`` and public methods)."""
    for node in getattr(tree, "body", []):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if names is None or node.name in names:
                yield node.name, node
        elif isinstance(node, ast.ClassDef) and (names is None or node.name in names):
            for sub in node.body:
                if isinstance(sub, (ast.FunctionDef, ast.AsyncFunctionDef)) and (
                        names is None or sub.name == "__init__" or not sub.name.startswith("_")):
                    yield f"{node.name}.{sub.name}", sub


def count(facade: bool = False) -> tuple[int, int, int, list[str]]:
    """(parameters, annotated, annotated Any, where) over jwarp/ or the facade."""
    files: dict[Path, set[str] | None] = {}
    if facade:
        sys.path.insert(0, str(ROOT))
        import inspect

        import jwarp

        for name in jwarp.__all__:
            obj = getattr(jwarp, name)
            try:   # the file that defines it (a package may only re-export it)
                path = Path(inspect.getsourcefile(obj) or "")
            except TypeError:   # not defined in Python source (e.g. an instance)
                continue
            if ROOT / "jwarp" in path.parents:
                files.setdefault(path, set()).add(getattr(obj, "__name__", name))  # type: ignore[union-attr]
    else:
        files = {p: None for p in sorted((ROOT / "jwarp").rglob("*.py"))}
    n = annotated = anys = 0
    where = []
    for path, names in files.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for qual, fn in _functions(tree, names):
            for p in _params(fn):
                n += 1
                annotated += p.annotation is not None
                if _is_any(p.annotation):
                    anys += 1
                    where.append(f"{path.relative_to(ROOT)}:{fn.lineno} {qual}({p.arg})")
    return n, annotated, anys, where


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--facade", action="store_true")
    ap.add_argument("--list", action="store_true")
    args = ap.parse_args()
    n, annotated, anys, where = count(args.facade)
    if args.list:
        print("\n".join(where))
    print(f"{'facade' if args.facade else 'jwarp/'}: {n} parameters, {annotated} annotated, "
          f"{anys} Any ({100 * anys / max(n, 1):.1f} % of all, "
          f"{100 * anys / max(annotated, 1):.1f} % of the annotated)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
