"""A small declarative schema: specs check a JSON value and return its resolved form.

New scene object kinds are added by declaring them (`Tagged.register`, or a kind table in
host/kinds/), never by writing validation code; scene/records.py and scene/gpis.py hold
the declarations.

May import: errors and io (float ranges); below kinds, layout and scene, which declare
their records with it.
"""
from __future__ import annotations

import copy
import json
import math
import numbers
import operator
import os

from .errors import SceneError
from .io.float_range import MAGNITUDE, TINY, WHY_MAGNITUDE


class Context:
    """Where the document came from: names errors and anchors relative file paths."""

    def __init__(self, file: str, base_dir: str):
        self.file, self.base_dir = file, base_dir

    def fail(self, path: str, reason: str):
        raise SceneError(self.file, path, reason)


REQUIRED = object()


def show(value) -> str:
    """A short JSON-ish rendering of a user's value for error messages."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


_KINDS = ((type(None), "null"), (bool, "boolean"), (numbers.Number, "number"),
          (str, "string"), (dict, "object"), ((list, tuple), "list"))


def kind_of(value) -> str:
    """The JSON name of a value's type (bool first: it is also a number)."""
    return next((name for t, name in _KINDS if isinstance(value, t)), type(value).__name__)


def child(path: str, key) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else str(key)


def is_number(v) -> bool:
    # bool is an int subclass, and numpy bools are not Real: both stay out
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def is_sequence(v) -> bool:
    if isinstance(v, (list, tuple)):
        return True
    # numpy arrays arrive only through dict scenes; accepted for convenience
    return getattr(v, "ndim", None) == 1 and hasattr(v, "tolist")


class Spec:
    """resolve(value, path, ctx) returns the resolved value or calls ctx.fail."""
    expected = "a value"

    def wrong_type(self, value, path, ctx):
        ctx.fail(path, f"expected {self.expected} (got {kind_of(value)} {show(value)})")


_BOUNDS = (("ge", ">=", operator.ge), ("gt", ">", operator.gt),
           ("le", "<=", operator.le), ("lt", "<", operator.lt))


INT32 = 2**31


class Number(Spec):
    """A finite float; the bounds are inclusive (ge/le) or exclusive (gt/lt)."""
    expected = "a number"

    def __init__(self, ge=None, gt=None, le=None, lt=None):
        self.ge, self.gt, self.le, self.lt = ge, gt, le, lt

    def check_range(self, v, path, ctx):
        for attr, op, ok in _BOUNDS:
            bound = getattr(self, attr)
            if bound is not None and not ok(v, bound):
                ctx.fail(path, f"must be {op} {_fmt(bound)} (got {_fmt(v)}){self.range_text()}")

    def range_text(self) -> str:
        lo = [f"{_fmt(b)} {op} " for b, op in ((self.ge, "<="), (self.gt, "<")) if b is not None]
        hi = [f" {op} {_fmt(b)}" for b, op in ((self.le, "<="), (self.lt, "<")) if b is not None]
        return f"; allowed: {lo[0]}x{hi[0]}" if lo and hi else ""

    def resolve(self, value, path, ctx):
        if not is_number(value):
            self.wrong_type(value, path, ctx)
        try:
            v = float(value)
        except OverflowError:  # an int too large for a double
            v = math.inf
        if not math.isfinite(v):
            ctx.fail(path, f"must be a finite number (got {show(value)})")
        self.check_range(v, path, ctx)   # first: a field's own bounds say it best
        if abs(v) > MAGNITUDE:
            ctx.fail(path, f"must be within +-{MAGNITUDE:g} (got {show(value)}): {WHY_MAGNITUDE}")
        if 0 < abs(v) < TINY:
            ctx.fail(path, f"must be 0 or at least {TINY:g} in magnitude (got {show(value)}): "
                           "the device computes in float32, where it would vanish")
        return v


def _fmt(v) -> str:  # -1.0 reads as -1 in messages, as the user probably wrote it
    return str(int(v)) if isinstance(v, float) and v.is_integer() and abs(v) < 1e15 else str(v)


class Int(Number):
    """An integer; a float (even 3.0) is a type error, so counts stay exact."""
    expected = "an integer"

    def resolve(self, value, path, ctx):
        if not isinstance(value, numbers.Integral) or isinstance(value, bool):
            self.wrong_type(value, path, ctx)
        v = int(value)
        self.check_range(v, path, ctx)
        if self.le is None and self.lt is None and v >= INT32:
            # no bound of its own: it still goes to the device as an int32
            ctx.fail(path, f"must be < 2**31 (got {v}): the device counts in int32")
        return v


class OfType(Spec):
    """A value of one Python type, passed through (bool is not an int here)."""

    def __init__(self, kind: type, expected: str):
        self.kind, self.expected = kind, expected

    def resolve(self, value, path, ctx):
        if not isinstance(value, self.kind) or (self.kind is not bool and isinstance(value, bool)):
            self.wrong_type(value, path, ctx)
        return value


def Bool():
    return OfType(bool, "true or false")


def String():
    return OfType(str, "a string")


class Enum(Spec):
    """One of a fixed set of strings."""

    def __init__(self, *choices: str):
        self.choices = choices
        self.expected = f"one of: {', '.join(map(show, choices))}"

    def resolve(self, value, path, ctx):
        if value not in self.choices or not isinstance(value, str):
            self.wrong_type(value, path, ctx)
        return value


class Nullable(Spec):
    def __init__(self, inner: Spec):
        # a copy, so the inner spec's type errors mention null too
        self.inner = copy.copy(inner)
        self.inner.expected = self.expected = f"{inner.expected} or null"

    def resolve(self, value, path, ctx):
        return None if value is None else self.inner.resolve(value, path, ctx)


class Vector(Spec):
    """`n` numbers, each checked by `item`. broadcast: one number stands for n equal ones
    (grey colours, uniform scales). normalize is idempotent, so resolved scenes reload
    bit-identically."""

    def __init__(self, n=3, item: Spec | None = None, broadcast=False, nonzero=False,
                 normalize=False):
        self.n, self.item = n, item or Number()
        self.broadcast, self.nonzero, self.normalize = broadcast, nonzero, normalize
        self.expected = f"a list of {n} {'integers' if isinstance(self.item, Int) else 'numbers'}"
        if broadcast:
            self.expected = f"a number or {self.expected}"

    def resolve(self, value, path, ctx):
        if self.broadcast and is_number(value):
            return [self.item.resolve(value, path, ctx)] * self.n
        if not is_sequence(value):
            self.wrong_type(value, path, ctx)
        items = list(value)
        if len(items) != self.n:
            ctx.fail(path, f"expected {self.expected} (got {len(items)} items)")
        out = [self.item.resolve(v, child(path, i), ctx) for i, v in enumerate(items)]
        if self.nonzero or self.normalize:
            if any(math.isinf(x * x) for x in out):  # rescale so hypot cannot overflow
                out = [x / max(map(abs, out)) for x in out] if self.normalize else out
            norm = math.hypot(*out)
            if norm == 0.0:
                ctx.fail(path, f"must be a non-zero vector (got {show(out)})")
            if self.normalize and abs(norm - 1.0) > 1e-12:
                out = [x / norm for x in out]
        return out


class File(Spec):
    """A path relative to the document's folder, resolved to an absolute one.
    check(path) returns None, or a reason the file is unusable."""
    expected = "a file path string"

    def __init__(self, extensions=(), check=None):
        self.extensions, self.check = tuple(extensions), check

    def resolve(self, value, path, ctx):
        if not isinstance(value, str) or not value:
            self.wrong_type(value, path, ctx)
        full = os.path.normpath(os.path.join(ctx.base_dir, value))
        ext = os.path.splitext(full)[1].lower()
        if self.extensions and ext not in self.extensions:
            ctx.fail(path, f"unsupported file type {show(ext or value)} "
                           f"(expected one of: {', '.join(self.extensions)})")
        if not os.path.isfile(full):
            ctx.fail(path, f"file not found: {full}")
        try:
            with open(full, "rb"):
                pass
            problem = self.check(full) if self.check else None
        except OSError as exc:   # unreadable (permissions, I/O): the reason, not a traceback
            problem = f"cannot read file ({exc.strerror or type(exc).__name__})"
        if problem:
            ctx.fail(path, f"{problem}: {full}")
        return full


class Field:
    def __init__(self, spec: Spec, default=REQUIRED):
        self.spec, self.default = spec, default


class Record(Spec):
    """A JSON object with a fixed set of keys; unknown keys are errors. Defaults pass
    through their spec like user values, so the resolved form is uniform. checks: rules
    tying fields together, functions of the resolved dict returning None or (key, reason)."""
    expected = "an object"

    def __init__(self, fields: dict, checks=()):
        self.fields, self.checks = fields, tuple(checks)

    def keys_text(self, extra=()) -> str:
        return ", ".join(list(self.fields) + list(extra))

    def resolve(self, value, path, ctx, extra_keys=()):
        if not isinstance(value, dict):
            self.wrong_type(value, path, ctx)
        for key in getattr(value, "duplicate_keys", ()):
            ctx.fail(child(path, key), "duplicate key (each key may appear only once)")
        for key in value:
            if key not in self.fields and key not in extra_keys:
                ctx.fail(child(path, str(key)),
                         f"unknown key (expected one of: {self.keys_text(extra_keys)})")
        out = {}
        for key, field in self.fields.items():
            if key in value:
                raw = value[key]
            elif field.default is REQUIRED:
                ctx.fail(child(path, key), "missing required key")
            else:
                raw = field.default
            out[key] = field.spec.resolve(raw, child(path, key), ctx)
        for check in self.checks:
            problem = check(out)
            if problem:
                ctx.fail(child(path, problem[0]), problem[1])
        return out


class Tagged(Spec):
    """An object whose "type" key picks the Record that describes the rest."""

    def __init__(self, family: str, variants: dict | None = None):
        self.family, self.variants = family, dict(variants or {})
        self.expected = f"a {family} object"

    def register(self, name: str, record: Record):
        self.variants[name] = record
        return record

    def resolve(self, value, path, ctx):
        if not isinstance(value, dict):
            self.wrong_type(value, path, ctx)
        if "type" not in value:
            ctx.fail(child(path, "type"), f"missing required key (the {self.family} type; "
                                          f"one of: {', '.join(self.variants)})")
        name = value["type"]
        if not isinstance(name, str) or name not in self.variants:
            ctx.fail(child(path, "type"), f"unknown {self.family} type {show(name)} "
                                          f"(expected one of: {', '.join(self.variants)})")
        out = {"type": name}
        out.update(self.variants[name].resolve(value, path, ctx, extra_keys=("type",)))
        return out


class ListOf(Spec):
    def __init__(self, item: Spec, min_len=0, too_short="must not be empty"):
        self.item, self.min_len, self.too_short = item, min_len, too_short
        self.expected = (f"a list of {item.family} objects" if isinstance(item, Tagged)
                         else f"a list (each {item.expected})")

    def resolve(self, value, path, ctx):
        if not isinstance(value, (list, tuple)):
            self.wrong_type(value, path, ctx)
        if len(value) < self.min_len:
            ctx.fail(path, self.too_short)
        return [self.item.resolve(v, child(path, i), ctx) for i, v in enumerate(value)]
