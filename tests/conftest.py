"""Test configuration: the ``device`` fixture runs a test on the CPU and, where CUDA is
present, on ``cuda:0`` too (CI has no GPU: there the CUDA half is not collected). Select
the CUDA half with ``-k cuda``."""

import pytest

from devices import cpu_available, cuda_available

DEVICES = ((["cpu"] if cpu_available() else [])
           + (["cuda:0"] if cuda_available() else []))


@pytest.fixture(params=DEVICES)
def device(request) -> str:
    """A Warp device name: "cpu" (where Warp's CPU backend is loaded), then "cuda:0"
    where present."""
    return request.param
