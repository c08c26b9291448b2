"""Kernel parameter sections match their use (issue "Finish the house", item 5).

Kernels group their parameters under comments (MuJoCo Warp's style)::

    @wp.kernel
    def k(
        # Model:
        ...
        # Data in:
        ...
        # Data out:
        ...
    ):

This test reads every ``@wp.kernel`` of ``jwarp/`` (the source, with ``ast`` and
``tokenize``) and checks, per parameter of a section:

* ``# Model:`` and ``# Data in:``: never written in the kernel body (no ``p[...] = ``,
  ``p[...] += ``, ``p.f = ``, no ``wp.atomic_*(p, ...)``); a parameter the kernel writes
  belongs under ``# Data out:`` or ``# Data in/out:`` (or ``# Scratch:``).
* ``# Data out:``: written in the body, or passed to a function (a ``@wp.func`` that
  writes it: calls are not followed).

Every kernel with parameters has sections: each parameter is under one (issue 40 item 5),
and the sections come in the order ``# Model:``, ``# Data in:``, ``# Data in/out:``,
``# Data out:`` (each optional); other section names (``# Scratch:``, ...) are accepted
anywhere, unchecked. A kernel's parameter order is its launch order (``inputs=``), so a
kernel is put in order together with every launch of it.
"""

from __future__ import annotations

import ast
import io
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
READ_ONLY = {"Model:", "Data in:"}
WRITTEN = {"Data out:"}
#: the order of the sections (a section not listed may stand anywhere)
ORDER = {"Model:": 0, "Data in:": 1, "Data in/out:": 2, "Data out:": 3}
#: kernels checked for the use of their sections, not yet for their order (none left: issue
#: 40 item 5 put the last ones, of jwarp/kernels/motion.py, in order)
NOT_YET: set[str] = set()
ATOMICS = {"atomic_add", "atomic_sub", "atomic_max", "atomic_min", "atomic_cas", "atomic_exch",
           "atomic_and", "atomic_or", "atomic_xor"}


def _is_kernel(fn: ast.FunctionDef) -> bool:
    for d in fn.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        if isinstance(target, ast.Attribute) and target.attr == "kernel":
            return True
    return False


def _sections(source: str, fn: ast.FunctionDef) -> dict[str, str]:
    """parameter name -> the section comment above it (parameters before any comment
    are left out)."""
    comments = {}  # line -> section name
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT and fn.lineno <= tok.start[0] <= fn.body[0].lineno:
            text = tok.string.lstrip("#").strip()
            if text.endswith(":") and len(text) < 30:
                comments[tok.start[0]] = text
    out = {}
    for a in fn.args.args:
        above = [line for line in comments if line < a.lineno]
        if above:
            out[a.arg] = comments[max(above)]
    return out


def _root_name(node: ast.AST) -> str | None:
    while isinstance(node, (ast.Subscript, ast.Attribute)):
        node = node.value
    return node.id if isinstance(node, ast.Name) else None


def _writes(fn: ast.FunctionDef) -> tuple[set[str], set[str]]:
    """(names written directly, names passed to a call) in the kernel body."""
    written, passed = set(), set()
    for node in ast.walk(fn):
        targets = []
        if isinstance(node, ast.Assign):
            targets = node.targets
        elif isinstance(node, (ast.AugAssign, ast.AnnAssign)):
            targets = [node.target]
        for t in targets:
            for sub in ast.walk(t):
                if isinstance(sub, (ast.Subscript, ast.Attribute)) and isinstance(sub.ctx, ast.Store):
                    name = _root_name(sub)
                    if name:
                        written.add(name)
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else (f.id if isinstance(f, ast.Name) else "")
            args = [_root_name(a) for a in node.args]
            if name in ATOMICS and args and args[0]:
                written.add(args[0])
            else:
                passed.update(a for a in args if a)
    return written, passed


def _kernels():
    for path in sorted((ROOT / "jwarp").rglob("*.py")):
        source = path.read_text()
        if "@wp.kernel" not in source:
            continue
        tree = ast.parse(source)
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef) and _is_kernel(node):
                yield path.relative_to(ROOT).as_posix(), source, node


KERNELS = list(_kernels())


def test_kernels_were_found():
    with_sections = [k for k in KERNELS if _sections(k[1], k[2])]
    assert len(KERNELS) >= 50 and len(with_sections) >= 40, (len(KERNELS), len(with_sections))


@pytest.mark.parametrize("where,source,fn", KERNELS,
                         ids=[f"{w}:{fn.name}" for w, _, fn in KERNELS])
def test_sections_match_the_use(where, source, fn):
    sections = _sections(source, fn)
    if not sections:
        return
    written, passed = _writes(fn)
    bad = [f"{p} is under '# {s}' but written" for p, s in sections.items()
           if s in READ_ONLY and p in written]
    bad += [f"{p} is under '# {s}' but neither written nor passed on" for p, s in sections.items()
            if s in WRITTEN and p not in written and p not in passed]
    assert not bad, f"{where}:{fn.lineno} kernel {fn.name}: " + "; ".join(bad)


def _order_problems(source: str, fn: ast.FunctionDef) -> list[str]:
    """Parameters under no section, and sections out of :data:`ORDER`."""
    sections = _sections(source, fn)
    bad = [f"{a.arg} is under no section" for a in fn.args.args if a.arg not in sections]
    last = ("", -1)
    for a in fn.args.args:
        s = sections.get(a.arg)
        if s in ORDER:
            if ORDER[s] < last[1]:
                bad.append(f"'# {s}' ({a.arg}) comes after '# {last[0]}'")
            last = (s, ORDER[s])
    return bad


@pytest.mark.parametrize("where,source,fn", KERNELS,
                         ids=[f"{w}:{fn.name}" for w, _, fn in KERNELS])
def test_sections_are_complete_and_in_order(where, source, fn):
    bad = _order_problems(source, fn)
    if f"{where}:{fn.name}" in NOT_YET:
        assert bad, f"{where}: kernel {fn.name} is in order now: remove it from NOT_YET"
        pytest.skip(f"{where}: {fn.name} not yet in order (NOT_YET)")
    assert not bad, f"{where}:{fn.lineno} kernel {fn.name}: " + "; ".join(bad)


def test_the_order_check_finds_misplaced_and_missing_sections():
    src = ("import warp as wp\n@wp.kernel\ndef k(\n    n: int,\n    # Data in:\n"
           "    a: wp.array(dtype=float),\n    # Scratch:\n    s: wp.array(dtype=float),\n"
           "    # Model:\n    m: wp.array(dtype=float),\n    # Data out:\n"
           "    b: wp.array(dtype=float),\n):\n    pass\n")
    fn = ast.parse(src).body[1]
    assert _order_problems(src, fn) == ["n is under no section",
                                        "'# Model:' (m) comes after '# Data in:'"]


def test_the_check_finds_a_written_input():
    src = ("import warp as wp\n@wp.kernel\ndef k(\n    # Data in:\n    a: wp.array(dtype=float),\n"
           "    # Data out:\n    b: wp.array(dtype=float),\n):\n    i = wp.tid()\n    a[i] = 1.0\n")
    fn = ast.parse(src).body[1]
    sections = _sections(src, fn)
    assert sections == {"a": "Data in:", "b": "Data out:"}
    written, passed = _writes(fn)
    assert "a" in written and "b" not in written and "b" not in passed
