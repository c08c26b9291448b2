"""``jwarp warmup`` covers the kernels the documented commands use (issue 39, item 2): the
basis point set encoding of ``jwarp train`` (family ``learn``), the sphere fit of URDF
imports (``spherize``) and the wide collision cost (``collision``). A module a command
loads is recorded through Warp's ``Module._compile`` (called for every module load, cached
or not) and must be one of :func:`jwarp.cli.warmup.kernel_modules`."""

from __future__ import annotations

import numpy as np
import pytest

import jwarp
from jwarp.cli.warmup import FAMILIES, kernel_modules


@pytest.fixture
def loads(monkeypatch):
    """Names of the Warp modules loaded from now on (compiled or read from the cache)."""
    from jwarp.core.arrays import init_warp

    init_warp()
    from warp._src.context import Module

    seen: list[str] = []
    original = Module._compile

    def record(self, *args, **kwargs):
        seen.append(self.name)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Module, "_compile", record)
    return seen


def test_families_cover_learn_spherize_and_wide_collision():
    assert {"learn", "spherize"} <= set(FAMILIES)
    from jwarp.importers import sphere_refine, spheres
    from jwarp.kernels import collision_wide
    from jwarp.learn import bps

    names = {m.name for m in kernel_modules(robots=jwarp.robots())}
    assert bps.kernels().encode.module.name in names
    for k in (*spheres.fit_kernels(), *sphere_refine.fit_kernels()):
        assert k.module.name in names
    for sc in ("float32", "float64"):
        import warp as wp

        kw = collision_wide.kernels(wp.float32 if sc == "float32" else wp.float64)
        for k in vars(kw).values():
            if isinstance(k, wp.Kernel):
                assert k.module.name in names
    with pytest.raises(ValueError, match="families: unknown value 'bps'"):
        kernel_modules(["bps"])


def test_bps_encoding_loads_only_warmed_modules(loads):
    from jwarp.learn import bps_encode
    from jwarp.world import world_from_occupancy

    lim = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    occ = np.zeros((16, 16), bool)
    occ[6:9, 6:9] = True
    world = world_from_occupancy(occ, lim, 2.0 / 15)
    from jwarp.learn import bps

    # an earlier test of the session may have loaded it already (then nothing loads now;
    # unloading it could free code that recorded launches still hold)
    loaded_before = bool(bps.kernels().encode.module.execs)
    d = bps_encode([world], np.array([[0.0, 0.0], [0.9, 0.9]]), device="cpu")
    assert d.shape == (1, 2) and d[0, 0] < 0 < d[0, 1]
    assert loads or loaded_before, "the encoding loaded no module"
    warm = {m.name for m in kernel_modules(["learn"], ["float32"])}
    assert set(loads) <= warm, set(loads) - warm
