"""Which devices the test machine has (CI has no GPU: CUDA tests skip there)."""

import pytest
import warp as wp


def cuda_available() -> bool:
    from jwarp.core.arrays import init_warp

    init_warp()
    return wp.is_cuda_available()


def cpu_available() -> bool:
    """Warp's CPU backend (LLVM) is loaded: a GPU-only install has none."""
    from jwarp.core.arrays import init_warp

    init_warp()
    return wp.is_cpu_available()


#: marks a test that needs Warp's CPU backend (a reference computed by CPU kernels)
requires_cpu = pytest.mark.skipif(not cpu_available(), reason="no Warp CPU backend")

#: marks a test that needs a CUDA device
requires_cuda = pytest.mark.skipif(not cuda_available(), reason="no CUDA device")
