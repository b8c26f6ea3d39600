"""The user-facing errors of every layer: a mistake in a scene or an input file, and no
usable OpenCL device. Imports nothing of gpiscl: every package may import it."""
from __future__ import annotations


class SceneError(Exception):
    """A user mistake in a scene; str() is one line: `<file>: <key path>: <reason>`."""

    def __init__(self, file: str, key: str, reason: str):
        self.file, self.key, self.reason = str(file), key, reason
        parts = [self.file] + ([key] if key else []) + [reason]
        super().__init__(": ".join(parts))

    def __reduce__(self):  # keep it picklable despite the 3-argument constructor
        return type(self), (self.file, self.key, self.reason)


# The `file` of a SceneError about an argument: the Python API's parameters are spelled
# like_this, the command line's options --like-this.
API_SOURCE = "<arguments>"
CLI_SOURCE = "<command line>"


def argument_source(option: str) -> str:
    return CLI_SOURCE if option.startswith("--") else API_SOURCE


class DeviceError(RuntimeError):
    """No usable OpenCL device, or a device-side build failure (a user-facing error)."""
