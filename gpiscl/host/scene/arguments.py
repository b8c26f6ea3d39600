"""One check of a render's arguments for the command line and the Python API.

The API used to pass arguments straight through: `render(s, spp=0)` gave a black image,
`resolution="64x64"` a 6x4 one, `seed=-1` a numpy error. Both front ends now send their
overrides through check(), which uses the scene schema's own specs (so the bounds are the
scene file's bounds) and raises SceneError naming the argument as the caller wrote it:
`<arguments>: spp: must be >= 1 (got 0)` from Python, `<command line>: --spp: ...` from
the shell.
"""
from __future__ import annotations

import os

from .records import CAMERA, MAX_BATCH, RENDER
from ..schema import Context, Int, Nullable, Number

# spp: the device counts sample indices in int32
SPECS = {
    "spp": Int(ge=1, lt=2**31),
    "seed": RENDER.fields["seed"].spec,
    "resolution": CAMERA.fields["resolution"].spec,
    "realization": RENDER.fields["realization"].spec,
    "batch_size": Nullable(Int(ge=1, le=MAX_BATCH)),
    "time_limit": Nullable(Number(gt=0)),
    # stops: 2**exposure must stay a float
    "exposure": Number(ge=-100, le=100),
    "max_memory": Nullable(Int(ge=1, le=2**62)),
}
API_SOURCE = "<arguments>"
CLI_SOURCE = "<command line>"


def cli_name(arg: str) -> str:
    return "--" + arg.replace("_", "-")


def check(source: str = API_SOURCE, name=lambda arg: arg, **values) -> dict:
    """The values given (None: not given, left out) resolved by their specs; SceneError
    naming name(argument) for the first bad one."""
    ctx = Context(source, os.getcwd())
    out = {}
    for arg, value in values.items():
        if value is None:
            continue
        out[arg] = SPECS[arg].resolve(value, name(arg), ctx)
    return out
