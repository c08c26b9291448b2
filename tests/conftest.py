"""Test configuration: the ``device`` fixture runs a test on the CPU and, where CUDA is
present, on ``cuda:0`` too (CI has no GPU: there the CUDA half is not collected). Select
the CUDA half with ``-k cuda``."""

import os

import pytest

from devices import cpu_available, cuda_available

# no "compiling jwarp kernels ..." line on stderr: tests that read stderr would see it
# only on a cold kernel cache (tests/core/test_kernel_cache.py turns it on where tested)
os.environ.setdefault("JWARP_COMPILE_NOTICE", "0")

DEVICES = ((["cpu"] if cpu_available() else [])
           + (["cuda:0"] if cuda_available() else []))


@pytest.fixture(params=DEVICES)
def device(request) -> str:
    """A Warp device name: "cpu" (where Warp's CPU backend is loaded), then "cuda:0"
    where present."""
    return request.param
