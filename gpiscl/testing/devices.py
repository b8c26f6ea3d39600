"""Which OpenCL devices the tests run on (the device axis of tests/conftest.py).

A selection is a comma-separated list; each item is `all` (every device that can build a
program and has double precision), `P:D` (platform and device indices, as
`python -m gpiscl devices` prints them), `platform:device` name fragments (pyopencl's
PYOPENCL_TEST form, e.g. `portable:pthread`) or one fragment of "platform device"."""

from gpiscl.host.render.device import compiles, list_devices


def usable(device) -> bool:
    """Double precision (the film needs it) and a compiler that works on this machine
    (PyPI's PoCL 3.0 cannot compile for CPUs newer than its LLVM)."""
    return bool(device.double_fp_config) and compiles(device)


def _matches(item: str, pi: int, di: int, platform: str, device: str) -> bool:
    parts = item.split(":")
    if len(parts) == 2 and all(p.isdigit() for p in parts):
        return (int(parts[0]), int(parts[1])) == (pi, di)
    if len(parts) == 2:
        return parts[0].lower() in platform.lower() and parts[1].lower() in device.lower()
    return item.lower() in f"{platform} {device}".lower()


def select(selection: str, devices=None) -> list:
    """`P:D` of every device the selection names, in list order without repeats; an item
    that names no device is an error (a typo must not shrink the run silently)."""
    devices = list_devices() if devices is None else devices
    chosen = []
    for item in (s.strip() for s in selection.split(",") if s.strip()):
        if item == "all":
            hits = [(pi, di) for pi, di, _, dev in devices if usable(dev)]
        else:
            hits = [(pi, di) for pi, di, plat, dev in devices
                    if _matches(item, pi, di, plat.name, dev.name)]
        if not hits:
            raise ValueError(f"test devices: '{item}' names no usable OpenCL device")
        chosen += [h for h in hits if h not in chosen]
    return [f"{pi}:{di}" for pi, di in chosen]
