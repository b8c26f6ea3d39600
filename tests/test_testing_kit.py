"""The test kit (gpiscl/testing) stays test-only, and the device axis selects what it says."""
import ast
from pathlib import Path
from types import SimpleNamespace

import pytest

import gpiscl
from gpiscl.testing.devices import select

PACKAGE = Path(gpiscl.__file__).resolve().parent


def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            yield node.module
            yield from (f"{node.module}.{a.name}" for a in node.names)


def test_the_product_never_imports_the_test_kit():
    """So a numpy twin or a harness can never become a production dependency, and the
    kit can import any product module without a circle."""
    users = sorted(str(p.relative_to(PACKAGE.parent)) for p in PACKAGE.rglob("*.py")
                   if "testing" not in p.relative_to(PACKAGE).parts
                   and any(m == "gpiscl.testing" or m.startswith("gpiscl.testing.")
                           for m in _imports(p)))
    assert not users, f"production modules importing gpiscl.testing: {users}"


def _fake(platform, device, double=True):
    return (SimpleNamespace(name=platform), SimpleNamespace(name=device, double_fp_config=double))


DEVICES = [(0, 0, *_fake("Portable Computing Language", "pthread-skylake-avx512")),
           (1, 0, *_fake("NVIDIA CUDA", "NVIDIA H200")),
           (1, 1, *_fake("NVIDIA CUDA", "NVIDIA A100"))]


@pytest.mark.parametrize("selection, specs", [
    ("1:1", ["1:1"]),
    ("portable:pthread,nvidia:h200", ["0:0", "1:0"]),  # pyopencl's PYOPENCL_TEST form
    ("nvidia", ["1:0", "1:1"]),
    ("1:0, nvidia", ["1:0", "1:1"]),                   # listed order, no repeats
])
def test_a_selection_names_devices_by_index_or_name(selection, specs):
    assert select(selection, DEVICES) == specs


def test_a_selection_that_names_no_device_is_an_error():
    with pytest.raises(ValueError, match="'amd'"):
        select("nvidia,amd", DEVICES)


def test_all_is_every_device_that_builds_with_double_precision(monkeypatch):
    from gpiscl.testing import devices
    monkeypatch.setattr(devices, "usable", lambda dev: dev.name != "NVIDIA A100")
    assert select("all", DEVICES) == ["0:0", "1:0"]
