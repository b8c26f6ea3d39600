"""One check of the arguments of the Python API, which the command line goes through too.

The API used to pass arguments straight through: `render(s, spp=0)` gave a black image,
`resolution="64x64"` a 6x4 one, `seed=-1` a numpy error. Every front end now sends its
arguments through check(), which uses the scene schema's own specs (so the bounds are the
scene file's bounds) and raises SceneError naming the argument: `<arguments>: spp: must be
>= 1 (got 0)`. The command line passes its options on under the same names and reports
such an error as `<command line>: --spp: ...` (gpiscl/cli/args.py).
"""
from __future__ import annotations

import os
import re
from decimal import Decimal

from ..errors import API_SOURCE, CLI_SOURCE  # noqa: F401  (the front ends' sources)
from .records import CAMERA, MAX_BATCH, RENDER
from ..schema import Context, Int, ListOf, Nullable, Number

# realization="none": average over realizations whatever the scene says
NO_REALIZATION = "none"
MAX_TIME_LIMIT = 1e9   # seconds
SIZE_UNITS = {"": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}


def parse_size(text: str) -> int:
    """`512M`, `8G`, `8GiB`, `1.5g`, `1000000` -> bytes."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([kmgt]?)(i?b)?\s*", str(text).lower())
    if not m:
        raise ValueError(f"expected a size like 8G, 512M or a number of bytes (got {text!r})")
    # exact: through a float, 4611686018427387905 rounded to 2**62 and passed its bound
    size = int(Decimal(m[1]) * SIZE_UNITS[m[2]])
    if size <= 0:
        raise ValueError(f"expected a size > 0 (got {text!r})")
    return size


class Word:
    """One word taken as itself (lower case), anything else checked by spec."""

    def __init__(self, word: str, spec):
        self.word, self.spec = word, spec

    def resolve(self, value, path, ctx):
        if isinstance(value, str) and value.lower() == self.word:
            return self.word
        return self.spec.resolve(value, path, ctx)


class Size:
    """A number of bytes, or a size like '8G' (parse_size)."""

    def __init__(self, spec):
        self.spec = spec

    def resolve(self, value, path, ctx):
        if isinstance(value, str):
            try:
                value = parse_size(value)
            except ValueError as exc:
                ctx.fail(path, str(exc))
        return self.spec.resolve(value, path, ctx)


# spp: the device counts sample indices in int32
SPECS = {
    "spp": Int(ge=1, lt=2**31),
    "seed": RENDER.fields["seed"].spec,
    "resolution": CAMERA.fields["resolution"].spec,
    "realization": Word(NO_REALIZATION, RENDER.fields["realization"].spec),
    "batch_size": Nullable(Int(ge=1, le=MAX_BATCH)),
    # ~31 years: beyond any render, and every deadline stays a float far from overflow
    "time_limit": Nullable(Number(gt=0, le=MAX_TIME_LIMIT)),
    # stops: 2**exposure must stay a float
    "exposure": Number(ge=-100, le=100),
    "max_memory": Size(Nullable(Int(ge=1, le=2**62))),
}
# uq: each realization needs K >= 2 samples for a sample variance that removes the Monte
# Carlo part; realization ids are distinct only modulo 2**31
UQ_SPECS = dict(SPECS, spp=Int(ge=2, lt=2**31), realizations=Int(ge=1, le=2**31),
                first=Int(ge=0, lt=2**31))
SAMPLE_SPECS = {
    "object": Int(ge=0, lt=2**31),
    "features": ListOf(Int(ge=1, lt=2**31), min_len=1),
    "realizations": Int(ge=1, lt=2**31),
    "resolution": Int(ge=1, lt=2**31),
    "seed": Int(ge=0, lt=2**32),
    "noise": Number(gt=0),
}


def check(specs: dict = SPECS, **values) -> dict:
    """The values given (None: not given, left out) resolved by their specs; SceneError
    naming the first bad one."""
    ctx = Context(API_SOURCE, os.getcwd())
    out = {}
    for arg, value in values.items():
        if value is None:
            continue
        out[arg] = specs[arg].resolve(value, arg, ctx)
    return out
