"""Which OpenCL drivers (ICDs) the process loads: the system's PoCL alone, when it is the
system's only driver, without PyPI's copy.

`pip install pyopencl[pocl]` brings its own ICD loader, which loads every driver it knows
of before the first platform query: the system's (/etc/OpenCL/vendors) and PyPI's bundled
PoCL 3.0. Loading a PoCL maps and relocates its LLVM and clang (resident memory:
docs/design/startup.md, 'Drivers') even if it is never used, and
PyPI's PoCL (LLVM 14) cannot compile for CPUs newer than it (render/device.py), so where
the system's only driver is a PoCL (what the README's set-up installs) PyPI's is left out.
The loader can be limited only by naming one .icd file in OCL_ICD_VENDORS (a folder there
still gets pyopencl's bundled drivers added, since pyopencl sets PYOPENCL_HOME), hence
"only driver": a system with a GPU driver as well keeps all of them. Nothing is changed
when the user chose the drivers (OCL_ICD_VENDORS or OCL_ICD_FILENAMES set), when the
system has no PoCL (PyPI's is then the CPU runtime), or when pyopencl is already imported
(its loader has read the list by then).
"""
from __future__ import annotations

import os
import sys

SYSTEM_VENDORS = "/etc/OpenCL/vendors"
CHOSEN = "OCL_ICD_VENDORS"


def only_system_pocl(vendors: str = SYSTEM_VENDORS) -> str | None:
    """The .icd file of a vendors folder whose only driver is a PoCL, else None."""
    try:
        names = sorted(n for n in os.listdir(vendors) if n.endswith(".icd"))
    except OSError:
        return None
    if len(names) != 1:
        return None
    path = os.path.join(vendors, names[0])
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return path if "libpocl" in f.read(4096) else None
    except OSError:
        return None


def prefer_system_pocl() -> None:
    """Point the ICD loader at the system's PoCL alone, if it is the system's only driver."""
    if CHOSEN in os.environ or "OCL_ICD_FILENAMES" in os.environ or "pyopencl" in sys.modules:
        return
    icd = only_system_pocl()
    if icd:
        os.environ[CHOSEN] = icd
