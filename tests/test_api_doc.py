"""docs/api.md is generated (issue "Finish the house", item 5): docs/api_intro.md followed by
the public facades' ``__all__`` with their signatures and docstrings (tools/gen_api.py). The
page must equal what the script writes now, so that a changed docstring, signature or
``__all__`` without a regenerated page fails here."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _gen_api():
    spec = importlib.util.spec_from_file_location("gen_api", ROOT / "tools" / "gen_api.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_api_md_is_generated_from_the_facades():
    text = _gen_api().generate()
    page = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    if page != text:
        import difflib

        diff = "".join(list(difflib.unified_diff(page.splitlines(True), text.splitlines(True),
                                                 "docs/api.md", "generated", n=1))[:80])
        raise AssertionError("docs/api.md is out of date: run python tools/gen_api.py\n" + diff)


def test_api_md_documents_every_facade_name():
    gen = _gen_api()
    page = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    for facade in gen.FACADES:
        mod = importlib.import_module(facade)
        missing = [n for n in mod.__all__ if f"### `{mod.__name__}.{n}`" not in page]
        assert not missing, f"docs/api.md lacks {mod.__name__}: {missing}"


def test_signatures_hold_no_addresses():
    gen = _gen_api()

    class Thing:
        pass

    def f(a, b=Thing(), *, c: int = 1) -> Thing:  # noqa: B008
        """First paragraph
        on two lines.

        Second paragraph."""

    sig = gen.format_signature("f", gen.signature(f))
    assert "0x" not in sig and sig.startswith("f(a, b=<")
    assert sig.endswith("*, c: int = 1) -> Thing")
    assert gen.first_paragraph(f) == "First paragraph\non two lines."
    long = gen.format_signature("f" * 90, gen.signature(f), width=96)
    assert all(len(line) <= 96 for line in long.splitlines()[1:])
