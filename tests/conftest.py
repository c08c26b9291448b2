"""Test configuration: the ``device`` fixture runs a test on the CPU and, where CUDA is
present, on ``cuda:0`` too (CI has no GPU: there the CUDA half is not collected). Select
the CUDA half with ``-k cuda``."""

import pytest

from devices import cuda_available

DEVICES = ["cpu"] + (["cuda:0"] if cuda_available() else [])


@pytest.fixture(params=DEVICES)
def device(request) -> str:
    """A Warp device name: "cpu", then "cuda:0" where present."""
    return request.param
