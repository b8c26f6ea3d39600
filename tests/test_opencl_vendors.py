"""gpiscl leaves PyPI's bundled PoCL out where the system's only OpenCL driver is a PoCL
(gpiscl/opencl_vendors.py), in a real subprocess, and never overrides the user's choice."""
import os
import subprocess
import sys

from gpiscl.opencl_vendors import only_system_pocl

# what the child prints: the loader's driver list, and which PoCL libraries got mapped
PROBE = r"""
import gpiscl, os
from gpiscl.host.render.device import list_devices
n = len(list_devices())
maps = open("/proc/self/maps").read()
print(os.environ.get("OCL_ICD_VENDORS"), n, "pyopencl/.libs/libpocl" in maps)
"""


def run_probe(env_extra=None):
    env = {k: v for k, v in os.environ.items() if not k.startswith("OCL_ICD")}
    env.update(env_extra or {})
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True,
                         text=True, check=True, timeout=120).stdout.split()
    return out[0], int(out[1]), out[2] == "True"


def write_icds(folder, contents):
    os.makedirs(folder, exist_ok=True)
    for name, text in contents.items():
        with open(os.path.join(folder, name), "w") as f:
            f.write(text)


def test_only_a_lone_pocl_driver_is_chosen(tmp_path):
    write_icds(tmp_path / "a", {"pocl.icd": "libpocl.so.2.10.0\n"})
    assert only_system_pocl(str(tmp_path / "a")) == str(tmp_path / "a" / "pocl.icd")
    # a GPU driver beside it: keep every driver (the loader cannot name two files)
    write_icds(tmp_path / "b", {"pocl.icd": "libpocl.so.2\n", "nvidia.icd": "libnvidia-opencl.so.1\n"})
    assert only_system_pocl(str(tmp_path / "b")) is None
    write_icds(tmp_path / "c", {"intel.icd": "libintelocl.so\n", "README": "libpocl"})
    assert only_system_pocl(str(tmp_path / "c")) is None
    assert only_system_pocl(str(tmp_path / "missing")) is None


def test_the_system_pocl_alone_is_loaded_when_it_is_the_only_driver():
    icd = only_system_pocl()
    chosen, devices, bundled_mapped = run_probe()
    if icd is None:   # no system PoCL here: PyPI's is the CPU runtime and nothing changes
        assert chosen == "None" and devices >= 1
        return
    assert chosen == icd
    assert devices == 1 and not bundled_mapped


def test_the_users_choice_of_drivers_is_kept():
    bundled = os.path.join(os.path.dirname(__import__("pyopencl").__file__), ".libs", "pocl.icd")
    chosen, devices, bundled_mapped = run_probe({"OCL_ICD_VENDORS": bundled})
    assert chosen == bundled and devices >= 1 and bundled_mapped
