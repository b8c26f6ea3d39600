"""Kernel launches by parameter name: the arguments are ordered from the kernel's Stage
(layout/stages.py), which also generates its C parameter list, and checked before they
reach OpenCL, where a wrong one would be a silent misread or an opaque CL error.

A keyword that is a Python keyword takes a trailing underscore (in_=rays for the queue
`in`).
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pyopencl as cl

from ..layout.stages import Group, Stage
from .device import Program


class LaunchError(TypeError):
    """A launch whose arguments do not match its kernel's Stage."""


def _host_name(keyword: str) -> str:
    return keyword[:-1] if keyword.endswith("_") else keyword


def _check(stage: Stage, c_name: str, param, value):
    def fail(why):
        raise LaunchError(f"kernel {stage.name}: argument '{c_name}' ({param.ctype}) {why}")
    if param.is_buffer:
        if not isinstance(value, cl.MemoryObjectHolder):
            fail(f"must be a device buffer, got {type(value).__name__}")
    elif not isinstance(value, np.generic):
        fail(f"must be a numpy {param.dtype} scalar, got {type(value).__name__}")
    elif value.dtype != param.dtype:
        fail(f"must be {param.dtype}, got {value.dtype}")


def arguments(stage: Stage, named: dict) -> list:
    """The kernel's arguments in its order, from keywords (parameter names and group
    prefixes; a group's value maps its fields to values). Raises LaunchError naming the
    kernel and the parameter for one missing, unknown or of the wrong kind or dtype."""
    named = {_host_name(k): v for k, v in named.items()}
    unknown = sorted(set(named) - set(stage.host_names))
    if unknown:
        raise LaunchError(f"kernel {stage.name}: unknown argument(s) {', '.join(unknown)} "
                          f"(it takes {', '.join(stage.host_names)})")
    for group in stage.params:
        if isinstance(group, Group) and group.prefix in named:
            value = named[group.prefix]
            if not isinstance(value, Mapping):
                raise LaunchError(f"kernel {stage.name}: argument '{group.prefix}' must map "
                                  f"its fields to values, got {type(value).__name__}")
            extra = sorted(set(value) - {q.name for q in group.params})
            if extra:
                raise LaunchError(f"kernel {stage.name}: unknown argument(s) "
                                  f"{', '.join(group.prefix + '_' + f for f in extra)}")
    args = []
    for (name, field, param), c_name in zip(stage.flat(), stage.c_names()):
        value = named.get(name)
        if field is not None and value is not None:
            value = value.get(field)
        if value is None:
            raise LaunchError(f"kernel {stage.name}: missing argument '{c_name}'")
        _check(stage, c_name, param, value)
        args.append(value)
    return args


def launch(program: Program, stage: Stage, global_size: int, /, *, local: int | None = None,
           max_items: int | None = None, **named):
    """Enqueue `stage` over global_size items with its arguments by name (timed under the
    stage's name); local and max_items as Program.enqueue. Returns the event."""
    return program.enqueue(stage.name, global_size, arguments(stage, named), local, max_items)
