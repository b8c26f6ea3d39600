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
from .queues import DeviceQueue


class LaunchError(TypeError):
    """A launch whose arguments do not match its kernel's Stage."""


def _host_name(keyword: str) -> str:
    return keyword[:-1] if keyword.endswith("_") else keyword


def _checked(stage: Stage, param, value, prefix: str = ""):
    """value, if it fits param; prefix: the group param belongs to, if any."""
    if param.is_buffer:
        if isinstance(value, cl.MemoryObjectHolder):
            return value
        why = f"must be a device buffer, got {type(value).__name__}"
    elif isinstance(value, np.generic) and value.dtype == param.dtype:
        return value
    elif isinstance(value, np.generic):
        why = f"must be {param.dtype}, got {value.dtype}"
    else:
        why = f"must be a numpy {param.dtype} scalar, got {type(value).__name__}"
    c_name = f"{prefix}_{param.name}" if prefix else param.name
    if value is None:
        raise LaunchError(f"kernel {stage.name}: missing argument '{c_name}'")
    raise LaunchError(f"kernel {stage.name}: argument '{c_name}' ({param.ctype}) {why}")


def _group_values(stage: Stage, group: Group, value) -> list:
    if (isinstance(value, DeviceQueue) and value.layout is group.queue
            and value.in_layout_order is not None):
        return value.in_layout_order    # built from this layout: every buffer in place
    if not isinstance(value, Mapping):
        raise LaunchError(f"kernel {stage.name}: argument '{group.prefix}' must map its "
                          f"fields to values, got {type(value).__name__}")
    extra = sorted(set(value) - {q.name for q in group.params})
    if extra:
        raise LaunchError(f"kernel {stage.name}: unknown argument(s) "
                          f"{', '.join(group.prefix + '_' + f for f in extra)}")
    return [_checked(stage, q, value.get(q.name), group.prefix) for q in group.params]


def arguments(stage: Stage, named: dict) -> list:
    """The kernel's arguments in its order, from keywords (parameter names and group
    prefixes; a group's value maps its fields to values). Raises LaunchError naming the
    kernel and the parameter for one missing, unknown or of the wrong kind or dtype."""
    named = {_host_name(k): v for k, v in named.items()}
    unknown = sorted(set(named) - stage.host_names)
    if unknown:
        raise LaunchError(f"kernel {stage.name}: unknown argument(s) {', '.join(unknown)} "
                          f"(it takes {', '.join(sorted(stage.host_names))})")
    args = []
    for param in stage.params:
        if isinstance(param, Group):
            if param.prefix not in named:
                raise LaunchError(f"kernel {stage.name}: missing argument '{param.prefix}' "
                                  f"(its {param.prefix}_* parameters)")
            args += _group_values(stage, param, named[param.prefix])
        else:
            args.append(_checked(stage, param, named.get(param.name)))
    return args


def launch(program: Program, stage: Stage, global_size: int, /, *, local: int | None = None,
           max_items: int | None = None, **named):
    """Enqueue `stage` over global_size items with its arguments by name (timed under the
    stage's name); local and max_items as Program.enqueue. Returns the event."""
    return program.enqueue(stage.name, global_size, arguments(stage, named), local, max_items)
