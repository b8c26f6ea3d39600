"""Read JSON the way the authors' Tungsten-based renderer does: trailing commas, // and
/* */ comments, NaN and Infinity are accepted (their parser is rapidjson with
kParseCommentsFlag | kParseTrailingCommasFlag | kParseNanAndInfFlag, and their example
scenes rely on the first), so their scene files import as they are.

The text goes to the json module (C speed; it reads NaN and Infinity itself); when that
fails, again after one regular-expression pass blanks the comments and trailing commas,
keeping every other character where it was, so the json module's line and column of a
mistake are the file's. A pure-Python JSON5 parser was far slower
(docs/design/tungsten-import.md, 'Parsing speed (E09)'). Errors are one SceneError line
naming the file and the line and column of the problem.
"""
from __future__ import annotations

import json
import os
import re
import stat

from ..errors import SceneError

MAX_SCENE_BYTES = 64 << 20   # a scene names its big data in files; more is a mistake

# a string (kept), a comment (blanked), or a comma with only blanks and comments before
# a closing bracket (blanked); strings first, so a "//" or "," inside one is left alone.
# The look-ahead's group is atomic: backtracking into a comment let "/* c */" stretch to
# a later "*/" (quadratic in the comments: docs/design/tungsten-import.md, same section)
_LENIENT = re.compile(r'("[^"\\]*(?:\\.[^"\\]*)*")'
                      r'|(//[^\n]*|/\*[\s\S]*?\*/)'
                      r'|(,)(?=(?>\s+|//[^\n]*|/\*[\s\S]*?\*/)*+[\]}])')


def read_lenient_json(path) -> object:
    """The document in file `path`; SceneError (file, "", reason) when unreadable. Only a
    regular file up to MAX_SCENE_BYTES is read: a FIFO would block, /dev/zero never ends."""
    name = str(path)
    try:
        # O_NONBLOCK: opening a FIFO must not wait for a writer before it is refused
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        raise SceneError(name, "", "file not found") from None
    except OSError as exc:
        raise SceneError(name, "", f"cannot read file ({exc.strerror or exc})") from None
    with os.fdopen(fd, "rb") as f:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise SceneError(name, "", "is a directory, not a scene file")
        if not stat.S_ISREG(mode):
            raise SceneError(name, "", "not a regular file")
        try:
            raw = f.read(MAX_SCENE_BYTES + 1)
        except OSError as exc:
            raise SceneError(name, "", f"cannot read file ({exc.strerror or exc})") from None
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneError(name, "", f"larger than {MAX_SCENE_BYTES >> 20} MiB: not a scene file")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise SceneError(name, "", f"not UTF-8 text (byte {exc.start}, line {line})") from None
    return parse_lenient_json(text, name)


def _blank(m: re.Match) -> str:
    if m.group(1) is not None:
        return m.group(1)
    # spaces for what is dropped, newlines kept: later line and column numbers stay true
    return re.sub(r"[^\n]", " ", m.group(0))


def parse_lenient_json(text: str, name: str = "<string>") -> object:
    try:
        try:
            return json.loads(text)   # most files are plain JSON: no second pass
        except json.JSONDecodeError:
            return json.loads(_LENIENT.sub(_blank, text))
    except RecursionError:
        raise SceneError(name, "", "invalid JSON: nested too deeply") from None
    except json.JSONDecodeError as exc:
        raise SceneError(name, "", f"invalid JSON at line {exc.lineno}, column {exc.colno}: "
                         f"{exc.msg}") from None
    except ValueError as exc:   # e.g. an integer literal with too many digits
        raise SceneError(name, "", f"invalid JSON: {exc}") from None
