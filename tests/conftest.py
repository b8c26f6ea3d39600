"""Shared fixtures: one OpenCL device (PoCL CPU unless PYOPENCL_CTX says otherwise)."""
import pytest

from gpiscl.host.render.device import Device


@pytest.fixture(scope="session")
def device():
    return Device()


def pytest_addoption(parser):
    parser.addoption("--long", action="store_true", default=False,
                     help="run tests marked `long` at their full size (default: short form)")


@pytest.fixture(scope="session")
def long_run(request):
    """True with --long: statistical tests marked `long` use their full sample counts."""
    return request.config.getoption("--long")
