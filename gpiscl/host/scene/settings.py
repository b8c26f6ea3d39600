"""Settings: scene values replaced by key path (`render.nee` = false, `camera.fov` = 30,
`shapes[0].bsdf.albedo` = [1, 0, 0]), the one way the command line's --set and the API's
settings= change a loaded scene. The scene schema checks the result, and an error it finds
under a setting's key path names that setting, not the scene file (the setting made it).
"""
from __future__ import annotations

import copy
import re

from ..errors import API_SOURCE, SceneError
from ..schema import Context, kind_of
from .records import SCENE

# `name`, then any of `.name` and `[index]`: the key paths the scene errors print
_STEP = re.compile(r"\.([A-Za-z_]\w*)|\[(\d+)\]")
_FIRST = re.compile(r"[A-Za-z_]\w*")


def key_path(text) -> list:
    """'shapes[0].bsdf' -> ['shapes', 0, 'bsdf']; ValueError for anything else."""
    first = _FIRST.match(text) if isinstance(text, str) else None
    if first is None:
        raise ValueError("expected a key path like render.nee or shapes[0].bsdf.albedo")
    steps, at = [first[0]], first.end()
    while at < len(text):
        step = _STEP.match(text, at)
        if step is None:
            raise ValueError("expected a key path like render.nee or shapes[0].bsdf.albedo")
        steps.append(step[1] if step[1] is not None else int(step[2]))
        at = step.end()
    return steps


def named(path: str) -> str:
    """How an error names the setting `path`: settings['render.nee']; the command line
    reports it as --set render.nee (gpiscl/cli/args.py)."""
    return f"settings[{path!r}]"


def apply(data: dict, source: str, base_dir: str, settings) -> dict:
    """A resolved copy of a resolved scene's data with each setting's value at its key
    path (an object on the way that is missing is created, so the schema names an
    unknown key). SceneError, naming the setting, for a bad path or value."""
    if not isinstance(settings, dict):
        raise SceneError(API_SOURCE, "settings", "expected a dict of key path -> value (got "
                         f"{kind_of(settings)})")
    data = copy.deepcopy(data)
    for path, value in settings.items():
        try:
            _set(data, key_path(path), value)
        except ValueError as exc:
            raise SceneError(API_SOURCE, named(path), str(exc)) from None
    try:
        return SCENE.resolve(data, "", Context(source, base_dir))
    except SceneError as exc:
        raise _blamed(exc, settings) from None


def _set(data: dict, steps: list, value):
    node = data
    for i, step in enumerate(steps):
        last = i == len(steps) - 1
        where = "".join(f"[{s}]" if isinstance(s, int) else f".{s}" for s in steps[:i])
        if isinstance(step, int):
            if not isinstance(node, list):
                raise ValueError(f"{where.lstrip('.')} is {_a(node)}, not a list")
            if step >= len(node):
                raise ValueError(f"{where.lstrip('.')} has {len(node)} elements")
        elif not isinstance(node, dict):
            raise ValueError(f"{where.lstrip('.')} is {_a(node)}, not an object")
        if last:
            node[step] = value
        else:
            if isinstance(node, dict) and step not in node:
                node[step] = {}
            node = node[step]


def _a(value) -> str:
    kind = kind_of(value)
    return kind if kind == "null" else ("an " if kind[0] in "aeiou" else "a ") + kind


def _blamed(exc: SceneError, settings: dict) -> SceneError:
    """The scene was valid before the settings, so its error is theirs: under one's key
    path it names that setting, and anywhere else (a check across keys) all of them."""
    for path in settings:
        if exc.key == path or exc.key.startswith((path + ".", path + "[")):
            return SceneError(API_SOURCE, named(path) + exc.key[len(path):], exc.reason)
    return SceneError(API_SOURCE, "settings", f"{exc.key}: {exc.reason}" if exc.key
                      else exc.reason)
