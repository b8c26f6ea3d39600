"""Read JSON the way the authors' Tungsten-based renderer does: trailing commas, // and
/* */ comments, NaN and Infinity are accepted (their parser is rapidjson with
kParseCommentsFlag | kParseTrailingCommasFlag | kParseNanAndInfFlag, and their example
scenes rely on the first), so their scene files import as they are.

The parsing is json5's (a maintained JSON5 parser; JSON5 is a superset of what rapidjson
accepts with those flags, except rapidjson's short `Inf` spelling). Errors are one
SceneError line naming the file and the line and column of the problem.
"""
from __future__ import annotations

import re

import json5

from ..errors import SceneError

# json5 reports "<string>:LINE Unexpected ... at column COL"; reworded into our form
_WHERE = re.compile(r"^<string>:(\d+) (.*) at column (\d+)$")


def read_lenient_json(path) -> object:
    """The document in file `path`; SceneError (file, "", reason) when unreadable."""
    name = str(path)
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except FileNotFoundError:
        raise SceneError(name, "", "file not found") from None
    except IsADirectoryError:
        raise SceneError(name, "", "is a directory, not a scene file") from None
    except OSError as exc:
        raise SceneError(name, "", f"cannot read file ({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise SceneError(name, "", f"not UTF-8 text (byte {exc.start}, line {line})") from None
    return parse_lenient_json(text, name)


def parse_lenient_json(text: str, name: str = "<string>") -> object:
    try:
        return json5.loads(text)
    except RecursionError:
        raise SceneError(name, "", "invalid JSON: nested too deeply") from None
    except ValueError as exc:
        m = _WHERE.match(str(exc))
        if m:
            line, what, col = m.groups()
            reason = f"invalid JSON at line {line}, column {col}: {what}"
        else:
            reason = f"invalid JSON: {exc}"
        raise SceneError(name, "", reason) from None
