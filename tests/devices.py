"""Which devices the test machine has (CI has no GPU: CUDA tests skip there)."""

import pytest
import warp as wp


def cuda_available() -> bool:
    from jwarp.core.arrays import init_warp

    init_warp()
    return wp.is_cuda_available()


#: marks a test that needs a CUDA device
requires_cuda = pytest.mark.skipif(not cuda_available(), reason="no CUDA device")
