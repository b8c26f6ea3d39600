"""The host's packages import only downwards, in the order data flows, with no circles
and no private names borrowed across modules (gpiscl/host/__init__.py lists the order)."""
import ast
import functools
from pathlib import Path

import gpiscl

ROOT = Path(gpiscl.__file__).resolve().parent
# A package may import packages of a lower rank (and itself), never a higher or equal one.
RANK = {"errors": 0, "gp": 1, "io": 2, "schema": 3, "kinds": 4, "layout": 5, "scene": 6,
        "compile": 7, "render": 8, "uq": 9, "figures": 9, "distributed": 10}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@functools.lru_cache(maxsize=None)
def _imports(path: Path) -> tuple:
    """(imported module, names) of every import in the file, function-level ones too.
    Parsed once per run: four tests read every file's imports (~0.4 s a pass)."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for a in node.names:
                found.append((a.name, ()))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            found.append((target, tuple(a.name for a in node.names)))
    return tuple(found)


def _graph():
    modules = {_module_name(p): p for p in ROOT.rglob("*.py")}
    edges = {}
    for mod, path in modules.items():
        out = set()
        for target, names in _imports(path):
            if not target.startswith("gpiscl"):
                continue
            subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in modules]
            out.update(subs or [target])
        edges[mod] = out - {mod}
    return modules, edges


def _layer(mod: str):
    if mod in ("gpiscl.version", "gpiscl.host.layout.constants",
               "gpiscl.host.layout.random_slots"):
        return "errors"  # import nothing of gpiscl: any layer may read them
    parts = mod.split(".")
    if len(parts) >= 3 and parts[1] == "host":
        return parts[2]
    return None  # gpiscl, gpiscl.api, gpiscl.cli, gpiscl.__main__, gpiscl.host: the top


def test_packages_import_only_lower_layers():
    _, edges = _graph()
    upward = []
    for mod, targets in edges.items():
        src = _layer(mod)
        for t in targets:
            dst = _layer(t)
            if t in ("gpiscl", "gpiscl.host") or dst is None:
                if src is not None and t != "gpiscl.host":
                    upward.append(f"{mod} -> {t}")
                continue
            if src is not None and src != dst and not RANK[dst] < RANK[src]:
                upward.append(f"{mod} -> {t}")
    assert not upward, "imports that go up or sideways:\n" + "\n".join(sorted(upward))


def test_no_import_circles():
    _, edges = _graph()
    state, cycles = {}, []

    def visit(m, stack):
        state[m] = 1
        stack.append(m)
        for t in sorted(edges.get(m, ())):
            if state.get(t) == 1:
                cycles.append(" -> ".join(stack[stack.index(t):] + [t]))
            elif t in edges and t not in state:
                visit(t, stack)
        stack.pop()
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m, [])
    assert not cycles, "import circles:\n" + "\n".join(cycles)


def test_no_private_names_borrowed_across_modules():
    modules, _ = _graph()
    borrowed = [f"{mod}: {target}.{n}" for mod, path in modules.items()
                for target, names in _imports(path) if target.startswith("gpiscl")
                for n in names if n.startswith("_") and not n.startswith("__")]
    assert not borrowed, "private names imported:\n" + "\n".join(borrowed)


def test_every_package_says_what_it_owns_and_may_import():
    for pkg in RANK:
        init = ROOT / "host" / pkg / "__init__.py"
        if pkg in ("errors", "schema"):
            init = ROOT / "host" / f"{pkg}.py"
        doc = ast.get_docstring(ast.parse(init.read_text()))
        assert doc and "import" in doc.lower(), pkg


# What gpiscl/cli/ may import of the host: the rest it reaches through gpiscl.api, so that
# the command line holds no rendering logic and the API can do all that it does.
CLI_MAY_IMPORT = {"gpiscl.host.scene.arguments", "gpiscl.host.errors"}


def test_the_command_line_imports_of_the_host_only_arguments_and_errors():
    modules, _ = _graph()
    found = [f"{mod} -> {target}" for mod, path in modules.items()
             if mod == "gpiscl.cli" or mod.startswith("gpiscl.cli.")
             for target, names in _imports(path)
             for t in ([f"{target}.{n}" for n in names] if target == "gpiscl.host" else [target])
             if t.startswith("gpiscl.host") and t not in CLI_MAY_IMPORT]
    assert not found, "the command line reaches past gpiscl.api:\n" + "\n".join(found)
