"""The commands quoted in jwarp's docs (README.md, docs/*.md, examples/README.md), extracted
from their fenced code blocks for tests/test_docs_commands.py.

A command is a line of a shell-like fence (no language, ``bash``, ``sh``, ``console``; not
``python``, ``json``, ``yaml``, ...) whose first word, after an optional ``$ `` prompt and
``NAME=value`` environment assignments, is ``jwarp``, ``python`` or ``python3``; backslash
continuations are joined and a trailing ``# comment`` is dropped. Lines whose first word is a
path (``jwarp/__init__.py  facade ...``, the README's source tree) or ``jwarp:`` (a printed
message) are not commands.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: fences whose lines may be commands (the info string after the opening ```)
SHELL_FENCES = {"", "bash", "sh", "shell", "console"}
#: fences whose lines may hold a jwarp command after ``RUN``, ``run:`` or ``&&``
EMBED_FENCES = {"dockerfile", "yaml", "yml"}
_EMBEDDED = re.compile(r"(?:^|&&|\bRUN\s|\brun:)\s*(jwarp\s[^&#\\]*)")

COMMAND_WORDS = {"jwarp", "python", "python3"}
_ENV = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*=\S*$")


@dataclass(frozen=True)
class DocCommand:
    """One command of a doc: ``where`` is ``file:line`` (first line of the command, file
    relative to the repository root), ``text`` the joined command without its comment."""

    file: str
    line: int
    text: str
    comment: str = ""  # the trailing "# ..." of the command's last line, without "#"

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"

    @property
    def program(self) -> str:
        """``jwarp`` or ``python`` (``python3`` counts as ``python``)."""
        return "python" if words(self.text)[0].startswith("python") else "jwarp"


def doc_files(root: Path = ROOT) -> list[Path]:
    """README.md, every docs/*.md and examples/README.md, in that order."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md")),
            root / "examples" / "README.md"]


def strip_comment(line: str) -> str:
    """``line`` without a trailing ``# comment`` (a ``#`` outside quotes that starts a word)."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].rstrip()
    return line.rstrip()


def words(text: str) -> list[str]:
    """Shell words of ``text`` without leading ``NAME=value`` environment assignments."""
    w = shlex.split(text)
    while w and _ENV.match(w[0]):
        w.pop(0)
    return w


def is_command(line: str) -> bool:
    """Whether a (prompt-stripped) fence line starts a jwarp or python command."""
    try:
        w = words(strip_comment(line.rstrip("\\").strip()))
    except ValueError:
        return False
    return bool(w) and w[0] in COMMAND_WORDS


def extract(path: Path, root: Path = ROOT) -> list[DocCommand]:
    """The commands of one markdown file (see the module docstring)."""
    rel = path.relative_to(root).as_posix()
    found: list[DocCommand] = []
    fence: str | None = None  # info string of the open fence, None outside fences
    buf: str | None = None
    start = 0
    last_end = -10  # line of the end of the last command
    for i, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        s = raw.strip()
        if s.startswith("```"):
            fence = s[3:].strip().lower() if fence is None else None
            last_end = -10
            if buf is not None:
                raise ValueError(f"{rel}:{start}: a continued command runs into a fence end")
            continue
        if fence in EMBED_FENCES:
            for m in _EMBEDDED.finditer(s):
                found.append(DocCommand(rel, i, " ".join(m.group(1).split())))
            continue
        if fence is None or fence not in SHELL_FENCES:
            continue
        if s.startswith("$ "):
            s = s[2:]
        if (buf is None and found and i == last_end + 1 and raw[:1].isspace()
                and s[:1] in "[-"):
            # an indented synopsis line ("    [--opt X] --other Y") continues the command above
            prev = found.pop()
            more = " ".join(strip_comment(s).split())
            found.append(DocCommand(rel, prev.line, f"{prev.text} {more}"))
            last_end = i
            continue
        if buf is None:
            if not is_command(s):
                continue
            start = i
            buf = ""
        cont = s.endswith("\\")
        part = strip_comment(s[:-1] if cont else s)
        buf = f"{buf} {part}".strip()
        if not cont:
            comment = s[len(part):].strip().lstrip("#").strip()
            found.append(DocCommand(rel, start, " ".join(buf.split()), comment))
            buf = None
            last_end = i
    return found


def all_commands(root: Path = ROOT) -> list[DocCommand]:
    """Every command of :func:`doc_files`, in file and line order."""
    return [c for f in doc_files(root) for c in extract(f, root)]


# ------------------------------------------------------------------ synopsis notation
def _tree(tokens: list[str]) -> list:
    """Synopsis words as a tree: a list of items, each a word or ``("opt", [alt, ...])`` for
    an optional group ``[a b | c d]`` (each alternative again a list of items)."""
    root: list = []
    stack: list[list[list]] = [[root]]  # per depth: the alternatives of the open group
    for tok in tokens:
        while tok.startswith("["):
            group: list[list] = [[]]
            stack[-1][-1].append(("opt", group))
            stack.append(group)
            tok = tok[1:]
        closes = len(tok) - len(tok.rstrip("]"))
        tok = tok.rstrip("]")
        if tok == "|" and len(stack) > 1:
            stack[-1].append([])
        elif tok:
            stack[-1][-1].append(tok)
        for _ in range(closes):
            if len(stack) == 1:
                raise ValueError(f"unbalanced ']' in {' '.join(tokens)!r}")
            stack.pop()
    if len(stack) != 1:
        raise ValueError(f"unbalanced '[' in {' '.join(tokens)!r}")
    return root


def _width(items: list) -> int:
    """Most alternatives of any choice (``a|b`` word or optional group) in ``items``."""
    n = 1
    for it in items:
        if isinstance(it, tuple):
            n = max(n, len(it[1]), *(_width(a) for a in it[1]))
        elif "|" in it:
            n = max(n, len(it.split("|")))
    return n


def _render(items: list, k: int, optional: bool, out: list[tuple[str, bool]], inside: bool):
    for it in items:
        if isinstance(it, tuple):
            if optional:
                alts = it[1]
                _render(alts[min(k, len(alts) - 1)], k, optional, out, True)
        else:
            alts = it.split("|")
            out.append((alts[min(k, len(alts) - 1)], inside))


def expand(argv: list[str]) -> list[list[tuple[str, bool]]]:
    """The concrete variants of a synopsis (words after ``jwarp``): variant k takes the k-th
    alternative of every choice (``a|b`` and ``[x | y]``, the last one where a choice has
    fewer) with every optional group, plus one variant without any optional group. Each word
    comes with whether it stood inside an optional group."""
    # an optional suffix of a word ("NAME[=VALUE]") is kept: "NAME=VALUE"
    tree = _tree([re.sub(r"(?<=[^\s\[])\[([^\]\s]*)\]", r"\1", w) for w in argv])
    out = []
    for k in range(_width(tree)):
        v: list[tuple[str, bool]] = []
        _render(tree, k, True, v, False)
        out.append(v)
    v = []
    _render(tree, 0, False, v, False)
    out.append(v)
    return out
