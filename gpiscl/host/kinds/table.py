"""KindTable: the one declaration of an extension axis, and what is generated from it.

A kind's device id is its position in the table, so ids stay stable while kinds are only
appended. Traits answer the "which kinds do X" questions the device code asks; a trait is
a bool (emitted as a predicate macro) or an int (emitted as a lookup macro), and every
kind of a table must state every trait the table declares, so that a new kind cannot
silently inherit a default.
"""
from __future__ import annotations

import contextlib
import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from ..schema import Record, Tagged

KERNELS_CL = Path(__file__).resolve().parent.parent.parent / "kernels_cl"


@functools.lru_cache(maxsize=None)
def _text(path: Path, stamp: tuple) -> str:
    return path.read_text()


def device_text(path: Path) -> str:
    """A device source file's text, read once per version (its mtime and size): a render
    joins ~50 files and the kinds' ~40 more, and reading them each time was ~10 ms of a
    small render's ~60."""
    st = path.stat()
    return _text(path, (st.st_mtime_ns, st.st_size))


@dataclass(frozen=True)
class Kind:
    """One kind of an axis.

    name: as scene files write it; schema: the fields a scene gives it (None: a kind no
    scene names directly); device_file: the file under kernels_cl/ holding its device
    functions (None: no device code of its own); traits: values of the table's traits;
    host: the host class, packer or whatever the axis's compile step needs.
    """
    name: str
    schema: Record | None = None
    device_file: str | None = None
    traits: Mapping[str, Any] = field(default_factory=dict)
    host: Any = None


class KindTable:
    def __init__(self, axis: str, prefix: str, kinds: Sequence[Kind] = (),
                 traits: Sequence[str] = (), family: str | None = None,
                 first_id: int = 0, schema: Tagged | None = None,
                 shared_files: Sequence[str] = ()):
        """first_id: the id of the first kind (a table sharing its C prefix with another
        starts past it); schema: a Tagged shared with another table (one scene key whose
        variants two tables declare); shared_files: device files under kernels_cl/ that
        several kinds use, joined before every kind's own."""
        self.axis, self.prefix, self.trait_names = axis, prefix, tuple(traits)
        self.shared_files = tuple(shared_files)
        self.family = family or axis
        self.first_id = first_id
        self._kinds: list[Kind] = []
        self.schema = schema if schema is not None else Tagged(self.family)
        self._views: list = []   # (trait, Tagged): schema_where's
        for kind in kinds:
            self.register(kind)

    # --- the declarations -------------------------------------------------------------
    def register(self, kind: Kind) -> Kind:
        if kind.name in self.names:
            raise ValueError(f"{self.axis}: kind {kind.name!r} declared twice")
        missing = set(self.trait_names) - set(kind.traits)
        unknown = set(kind.traits) - set(self.trait_names)
        if missing or unknown:
            raise ValueError(f"{self.axis}: kind {kind.name!r} traits: missing "
                             f"{sorted(missing)}, unknown {sorted(unknown)}")
        # a path outside kernels_cl/ (absolute) serves tests' temporary kinds
        if kind.device_file is not None and not self.device_path(kind).is_file():
            raise ValueError(f"{self.axis}: kind {kind.name!r}: no device file "
                             f"{self.device_path(kind)}")
        self._kinds.append(kind)
        if kind.schema is not None:
            self.schema.register(kind.name, kind.schema)
            for trait, view in self._views:
                if kind.traits[trait]:
                    view.register(kind.name, kind.schema)
        return kind

    def unregister(self, name: str):
        kind = self[name]
        if kind is not self._kinds[-1]:
            raise ValueError(f"{self.axis}: only the last kind can be removed (ids are "
                             f"positions)")
        self._kinds.pop()
        self.schema.variants.pop(name, None)
        for _, view in self._views:
            view.variants.pop(name, None)

    @contextlib.contextmanager
    def registered(self, kind: Kind):
        """The table with `kind` appended for the duration (tests' temporary kinds)."""
        self.register(kind)
        try:
            yield kind
        finally:
            self.unregister(kind.name)

    # --- lookups ----------------------------------------------------------------------
    @property
    def names(self) -> tuple:
        return tuple(k.name for k in self._kinds)

    def __iter__(self):
        return iter(self._kinds)

    def __len__(self):
        return len(self._kinds)

    def __contains__(self, name) -> bool:
        return name in self.names

    def __getitem__(self, name: str) -> Kind:
        for kind in self._kinds:
            if kind.name == name:
                return kind
        raise KeyError(f"{self.axis}: no kind {name!r} (one of: {', '.join(self.names)})")

    def id(self, name: str) -> int:
        return self.first_id + self.names.index(self[name].name)

    def with_trait(self, trait: str, value=True) -> tuple:
        return tuple(k.name for k in self._kinds if k.traits[trait] == value)

    def schema_where(self, trait: str, family: str) -> Tagged:
        """A scene schema of the kinds whose bool `trait` is true (e.g. the micro-BSDFs a
        GPIS takes), kept in step with later registrations."""
        view = Tagged(family, {k.name: k.schema for k in self._kinds
                               if k.schema is not None and k.traits[trait]})
        self._views.append((trait, view))
        return view

    @staticmethod
    def device_path(kind: Kind) -> Path:
        """Its device file: relative to kernels_cl/, or absolute (a test's own kind)."""
        return KERNELS_CL / kind.device_file

    # --- generated C ------------------------------------------------------------------
    def c_name(self, name: str) -> str:
        return f"{self.prefix}_{name.upper()}"

    def c_enum(self, count: bool = True) -> list:
        """The ids, and PREFIX_COUNT unless `count` is false (a second table of a prefix)."""
        lines = [f"#define {self.c_name(k.name)} {self.id(k.name)}" for k in self._kinds]
        return lines + ([f"#define {self.prefix}_COUNT {len(self._kinds)}"] if count else [])

    def c_traits(self) -> list:
        """`PREFIX_IS_TRAIT(k)` for bool traits, `PREFIX_TRAIT(k)` for int traits."""
        lines = []
        for trait in self.trait_names:
            values = [k.traits[trait] for k in self._kinds]
            macro = f"{self.prefix}_{trait.upper()}"
            if all(isinstance(v, bool) for v in values):
                hits = [self.c_name(k.name) for k in self._kinds if k.traits[trait]]
                body = " || ".join(f"(k) == {h}" for h in hits) or "0"
                lines.append(f"#define {self.prefix}_IS_{trait.upper()}(k) ({body})")
            else:
                expr = "0"
                for k in reversed(self._kinds):
                    expr = f"((k) == {self.c_name(k.name)} ? {int(k.traits[trait])} : {expr})"
                lines.append(f"#define {macro}(k) {expr}")
        return lines

    def c_dispatch(self, function: str, returns: str, params: str, args: str,
                   default: str = "0", kinds: Sequence[str] | None = None,
                   name: str | None = None) -> str:
        """`returns prefix_function(int kind, params)` (or `name`): a switch calling
        `<kind>_<function>(args)` for each kind (or the `kinds` named), `default` for the
        others. A `void` function calls and returns (its default does nothing)."""
        chosen = [self[n] for n in kinds] if kinds is not None else self._kinds
        call = "{}; return;" if returns == "void" else "return {};"
        cases = "\n".join(f"    case {self.c_name(k.name)}: "
                          + call.format(f"{k.name}_{function}({args})") for k in chosen)
        tail = "return;" if returns == "void" else f"return {default};"
        head = f"inline {returns} {name or self.prefix.lower() + '_' + function}(int kind, {params})"
        return f"{head} {{\n  switch (kind) {{\n{cases}\n    default: {tail}\n  }}\n}}"

    def device_files(self) -> list:
        """The shared files, then every kind's, in the order device_source joins them."""
        return [*self.shared_files,
                *(k.device_file for k in self._kinds if k.device_file is not None)]

    def device_source(self) -> str:
        """The shared files, then every kind's device file in id order, with #line markers
        for the compiler's messages (the axis's shared header and generated dispatch go
        around it)."""
        return "\n".join(f'#line 1 "{name}"\n{device_text(KERNELS_CL / name)}'
                         for name in self.device_files())
