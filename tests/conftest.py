"""Shared fixtures: one OpenCL device (PoCL CPU unless PYOPENCL_CTX says otherwise)."""
import pytest

from gpiscl.host.render.device import Device


@pytest.fixture(scope="session")
def device():
    return Device()
