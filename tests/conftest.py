"""Test configuration: a test taking ``device`` runs on the CPU and, where CUDA is present,
on ``cuda:0`` too (CI has no GPU: there the CUDA half is not collected). Select one device
with ``pytest --device cpu`` or ``pytest --device cuda:0`` (as MuJoCo Warp's test option;
an unavailable device is a usage error), or the CUDA half with ``-k cuda``."""

import os

import pytest
from devices import cpu_available, cuda_available

# no "compiling jwarp kernels ..." line on stderr: tests that read stderr would see it
# only on a cold kernel cache (tests/core/test_kernel_cache.py turns it on where tested)
os.environ.setdefault("JWARP_COMPILE_NOTICE", "0")

DEVICES = ((["cpu"] if cpu_available() else [])
           + (["cuda:0"] if cuda_available() else []))


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--device", action="store", default=None, metavar="DEVICE",
                     help="run the tests that take a device on DEVICE only (cpu, cuda, "
                          "cuda:N); default: every available device")


def selected_devices(config: pytest.Config) -> list[str]:
    """The devices of the ``device`` parameter: ``--device`` or every available one."""
    want = config.getoption("--device")
    if want is None:
        return DEVICES
    want = "cuda:0" if want == "cuda" else want
    available = list(DEVICES)
    if cuda_available():
        import warp as wp

        available += [f"cuda:{k}" for k in range(wp.get_cuda_device_count())]
    if want not in available:
        raise pytest.UsageError(f"--device: {want!r} is not available here "
                                f"(available: {', '.join(sorted(set(available))) or 'none'})")
    return [want]


def pytest_configure(config: pytest.Config) -> None:
    selected_devices(config)  # an unavailable --device stops the run before collection


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """``device`` of every test that takes it (directly or through a fixture), unless the
    test parametrizes ``device`` itself."""
    if "device" not in metafunc.fixturenames:
        return
    for mark in metafunc.definition.iter_markers("parametrize"):
        names = mark.args[0]
        names = [n.strip() for n in names.split(",")] if isinstance(names, str) else names
        if "device" in names:
            return
    metafunc.parametrize("device", selected_devices(metafunc.config))
