"""Static checks of jwarp/, tests/, tools/ and benchmarks/ (issue "Finish the house", item 5;
issue 40 item 7): ruff (``ruff check jwarp tests tools benchmarks`` with pyproject.toml's
``[tool.ruff.lint]``: pyflakes ``F``, syntax errors ``E9``, import order ``I``, bugbear ``B``,
simplify ``SIM``, pyupgrade ``UP`` and the ban on heavy module-level imports ``TID253``),
the same command as ``.ci/run``. ruff is in the test extra; without it the test is skipped,
said so."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PATHS = ("jwarp", "tests", "tools", "benchmarks")  # as .ci/run


def _ruff() -> list[str]:
    exe = shutil.which("ruff")
    if exe:
        return [exe]
    try:
        import ruff  # noqa: F401
    except ImportError:
        pytest.skip("ruff is not installed (pip install -e '.[test]')")
    return [sys.executable, "-m", "ruff"]


def test_ruff_rules_pass_on_jwarp_tests_tools_benchmarks():
    r = subprocess.run([*_ruff(), "check", *PATHS, "--output-format", "concise"], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
