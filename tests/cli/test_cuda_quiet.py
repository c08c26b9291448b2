"""Issue 39 item 5: on a machine without CUDA, Warp's native "CUDA driver not found" line is
not printed (by jwarp's commands and its Python API; :mod:`jwarp.utils.warp_init`), and
``jwarp info`` says in one line that there is no CUDA. Subprocesses: Warp initialises once
per process and prints from C, past pytest's capture of ``sys.stderr``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from jwarp.utils.warp_init import CUDA_DRIVER_WARNING, cuda_driver_found

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "JWARP_DEBUG": ""}

pytestmark = pytest.mark.skipif(cuda_driver_found(),
                                reason="a CUDA driver is installed: Warp finds it")


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True,
                          timeout=300, cwd=ROOT, env=ENV)


def test_python_api_prints_no_cuda_warning():
    r = _run("-c", "import numpy as np, jwarp; print(jwarp.fk('arm7', np.zeros(7)).shape)")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().endswith(", 4, 4)"), r.stdout
    assert CUDA_DRIVER_WARNING not in r.stderr, r.stderr


def test_info_says_no_cuda_in_one_line():
    r = _run("-m", "jwarp", "info", "planar4")
    assert r.returncode == 0, r.stderr
    assert CUDA_DRIVER_WARNING not in r.stderr, r.stderr
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("devices:")]
    assert lines == ["devices: cpu only (no CUDA: no NVIDIA CUDA driver found; jwarp "
                     "computes on the CPU)"], r.stdout


def test_other_warp_output_is_passed_on():
    """Only the one line is filtered: what else the native library writes during the
    initialisation still reaches stderr."""
    code = ("import os, warp as wp\n"
            "real = wp.init\n"
            "def noisy():\n"
            "    os.write(2, b'native hello\\n')\n"
            "    real()\n"
            "wp.init = noisy\n"
            "from jwarp.utils.warp_init import init_quietly\n"
            "init_quietly()\n")
    r = _run("-c", code)
    assert r.returncode == 0, r.stderr
    assert "native hello" in r.stderr and CUDA_DRIVER_WARNING not in r.stderr, r.stderr
