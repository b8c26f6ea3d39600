"""The scene-file reference (docs/scene-format.md), generated from the schema's
declarations so that it cannot drift from what the loader accepts: every key, its type and
range, and its default. tests/test_scene_reference.py checks the committed page;
`python tools/make_scene_reference.py` writes it."""
from __future__ import annotations

import json
import math

from ..schema import (REQUIRED, Enum, File, Int, ListOf, Nullable, Number, OfType, Record,
                      Tagged, Vector)
from . import gpis  # noqa: F401  (registers the "gpis" shape with records.SHAPES)
from .records import SCENE


def _number(spec: Number) -> str:
    name = "integer" if isinstance(spec, Int) else "number"
    bounds = [f"{op} {_value(b)}" for b, op in ((spec.ge, ">="), (spec.gt, ">"), (spec.le, "<="),
                                          (spec.lt, "<")) if b is not None]
    return f"{name} {', '.join(bounds)}".strip()


def _value(b) -> str:
    if float(b).is_integer() and abs(b) >= 2**20 and float(b) == 2 ** round(math.log2(b)):
        return f"2^{round(math.log2(b))}"
    return str(int(b)) if float(b).is_integer() else f"{b:g}"


class _Writer:
    def __init__(self):
        self.sections, self.done, self.queue = [], {}, []

    def link(self, title: str, spec) -> str:
        if id(spec) not in self.done:
            self.done[id(spec)] = title
            self.queue.append((title, spec))
        anchor = self.done[id(spec)].lower().replace(" ", "-")
        return f"[{self.done[id(spec)]}](#{anchor})"

    def describe(self, spec, title: str) -> str:
        if isinstance(spec, Nullable):
            return f"{self.describe(spec.inner, title)} or null"
        if isinstance(spec, Number):
            return _number(spec)
        if isinstance(spec, Enum):
            return "one of " + ", ".join(f"`{c}`" for c in spec.choices)
        if isinstance(spec, Vector):
            item = self.describe(spec.item, title)
            text = f"{spec.n} x ({item})"
            return f"{text}; a single number for all" if spec.broadcast else text
        if isinstance(spec, File):
            return "file" + (f" ({', '.join(spec.extensions)})" if spec.extensions else "")
        if isinstance(spec, ListOf):
            return f"list of {self.describe(spec.item, title)}"
        if isinstance(spec, Tagged):
            return f"a {spec.family}: {self.link(spec.family, spec)}"
        if isinstance(spec, Record):
            return f"object: {self.link(title, spec)}"
        if isinstance(spec, OfType):
            return spec.expected
        return spec.expected

    def record(self, title: str, record: Record) -> list:
        rows = ["| key | value | default |", "|---|---|---|"]
        for key, field in record.fields.items():
            default = "required" if field.default is REQUIRED else \
                f"`{json.dumps(field.default)}`"
            rows.append(f"| `{key}` | {self.describe(field.spec, key)} | {default} |")
        return rows if record.fields else ["(no keys)"]

    def section(self, title: str, spec) -> list:
        lines = [f"## {title}", ""]
        if isinstance(spec, Tagged):
            lines += [f"A {spec.family} object is one of these, chosen by its `type`:", ""]
            for name, record in spec.variants.items():
                lines += [f"### {title}: `{name}`", ""] + self.record(name, record) + [""]
        else:
            lines += self.record(title, spec) + [""]
        return lines

    def page(self) -> str:
        self.link("scene", SCENE)
        body = []
        while self.queue:
            body += self.section(*self.queue.pop(0))
        head = ["# Scene file reference", "",
                "Generated from the schema (gpiscl/host/scene/reference.py; do not edit by "
                "hand: `python tools/make_scene_reference.py`). Every key not listed is an "
                "error; defaults are what the resolved scene (`NAME.scene.json`) records.", ""]
        return "\n".join(head + body).rstrip() + "\n"


def scene_reference() -> str:
    """The Markdown page of every scene key."""
    return _Writer().page()
