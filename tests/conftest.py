"""Shared fixtures and options.

The device axis: tests that take the `device` fixture run on
- by default, the first usable device (PoCL's CPU device unless PYOPENCL_CTX names one), as
  one test each;
- the devices GPISCL_TEST_DEVICES names (else PYOPENCL_TEST, pyopencl's variable), or the
  ones `--device SELECTION` names (it wins over both): a comma-separated list of `all`,
  `P:D` indices (`python -m gpiscl devices`), `platform:device` name fragments
  (`portable:pthread`) or one name fragment. Each device-bound test is then collected once per
  device, its id ending in `[P:D]`; `pytest --device all` runs everything on every device
  that builds programs and has double precision.

`--long`: tests marked `long` run at full size (by default their short form runs, still a
check that can fail, so that the default run stays within a few minutes: README.md).
`flight_prg`: the function-space sampler's free-flight wrappers (gpiscl/testing/flights.py),
built once per device.
"""
import functools
import os

import pytest

from gpiscl.host.render.device import Device
from gpiscl.testing.devices import select
from gpiscl.testing.flights import flight_program


def pytest_addoption(parser):
    parser.addoption("--long", action="store_true", default=False,
                     help="run tests marked `long` at their full size (default: short form)")
    parser.addoption("--device", default=None, metavar="SELECTION",
                     help="OpenCL devices for device-bound tests: all, P:D, platform:device "
                          "or a name fragment, comma-separated (default: "
                          "GPISCL_TEST_DEVICES, PYOPENCL_TEST, else the first usable device)")


def _selection(config):
    return (config.getoption("--device") or os.environ.get("GPISCL_TEST_DEVICES")
            or os.environ.get("PYOPENCL_TEST"))


@functools.lru_cache(maxsize=None)
def _specs(selection: str) -> list:
    return select(selection)


def pytest_configure(config):
    selection = _selection(config)
    if selection:
        try:
            _specs(selection)
        except ValueError as e:
            raise pytest.UsageError(str(e)) from None


def pytest_generate_tests(metafunc):
    selection = _selection(metafunc.config)
    if selection and "device" in metafunc.fixturenames:
        specs = _specs(selection)
        metafunc.parametrize("device", specs, ids=specs, indirect=True, scope="session")


@pytest.fixture(scope="session")
def device(request):
    """A Device on the selected OpenCL device (see the module docstring)."""
    return Device(getattr(request, "param", None))


@pytest.fixture(scope="session")
def long_run(request):
    """True with --long: statistical tests marked `long` use their full sample counts."""
    return request.config.getoption("--long")


@pytest.fixture
def flight_prg(device):
    """The free-flight wrapper kernels by name, on `device` (gpiscl/testing/flights.py)."""
    return flight_program(device.ctx)
