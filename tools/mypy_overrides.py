"""Regenerate the per-module mypy error codes of pyproject.toml.

    python tools/mypy_overrides.py           # rewrite the section between the markers
    python tools/mypy_overrides.py --check   # exit 1 when the section is not what mypy needs

The section between ``# --- begin: per-module error codes`` and ``# --- end: per-module error
codes`` lists, for each module, the error codes mypy still reports there (off in that module
only). This script runs mypy on jwarp/ without the section, counts the errors per module and
code, and writes the section again: after a fix a code (or a module) drops out, after a move
the new module names come in. ``--check`` also finds codes that are off but no longer needed.
"""

from __future__ import annotations

import argparse
import collections
import re
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"
BEGIN = "# --- begin: per-module error codes"
END = "# --- end: per-module error codes\n"
HEADER = """\
# The error codes each module still raises, off in that module only (a ratchet: a new module
# is checked in full; tools/mypy_overrides.py rewrites this section after fixes or moves).
# Mostly Optional attributes set after validation or on first use (union-attr, index,
# arg-type), numpy/Warp stub strictness and Warp functions inside host modules (valid-type,
# attr-defined).
"""
_ERROR = re.compile(r"^(jwarp/[\w/]+)\.py:\d+: error: .*\[([a-z-]+)\]$")


def split(text: str) -> tuple[str, str, str]:
    """(before, section, after) of pyproject.toml's text."""
    b = text.index(BEGIN)
    e = text.index(END, b) + len(END)
    return text[:b], text[b:e], text[e:]


def bare_errors(text: str) -> dict[str, collections.Counter]:
    """{module: Counter(code)} of mypy on jwarp/ with ``text`` less the section."""
    before, _, after = split(text)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "pyproject.toml"
        cfg.write_text(before + after, encoding="utf-8")
        cache = Path(tempfile.gettempdir()) / "jwarp-mypy-cache-bare"
        r = subprocess.run([sys.executable, "-m", "mypy", "--config-file", str(cfg),
                            "--cache-dir", str(cache)], cwd=ROOT, capture_output=True,
                           text=True, timeout=900)
    codes: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for line in r.stdout.splitlines():
        m = _ERROR.match(line.strip())
        if m:
            module = m.group(1).replace("/", ".").removesuffix(".__init__")
            codes[module][m.group(2)] += 1
    if r.returncode not in (0, 1) or (r.returncode == 1 and not codes):
        raise RuntimeError(f"mypy failed:\n{r.stdout}\n{r.stderr}")
    return codes


def section(codes: dict[str, collections.Counter]) -> str:
    """The section's text: modules with the same codes share one override."""
    groups: dict[tuple[str, ...], list[str]] = collections.defaultdict(list)
    for module, counter in codes.items():
        groups[tuple(sorted(counter))].append(module)
    lines = [f"{BEGIN} (tools/mypy_overrides.py)", HEADER.rstrip("\n")]
    for cs, modules in sorted(groups.items(), key=lambda kv: (len(kv[0]), kv[0])):
        n = sum(codes[m][c] for m in modules for c in cs)
        mods = "module = [" + ", ".join(f'"{m}"' for m in sorted(modules)) + "]"
        off = "disable_error_code = [" + ", ".join(f'"{c}"' for c in cs) + "]"
        lines += [f"[[tool.mypy.overrides]]  # {n} errors when enabled",
                  textwrap.fill(mods, 99, subsequent_indent=" " * 10, break_on_hyphens=False),
                  textwrap.fill(off, 99, subsequent_indent=" " * 22, break_on_hyphens=False),
                  ""]
    return "\n".join(lines) + END


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 when the section differs from what mypy needs now")
    args = parser.parse_args(argv)
    text = PYPROJECT.read_text(encoding="utf-8")
    codes = bare_errors(text)
    before, old, after = split(text)
    new = section(codes)
    total = sum(sum(c.values()) for c in codes.values())
    print(f"{total} errors in {len(codes)} modules without the per-module codes")
    if args.check:
        same = re.sub(r"#.*", "", old) == re.sub(r"#.*", "", new)
        if not same:
            print("pyproject.toml: the per-module mypy codes are out of date: run "
                  "python tools/mypy_overrides.py", file=sys.stderr)
        return 0 if same else 1
    PYPROJECT.write_text(before + new + after, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
