"""Every file path named in a comment, docstring or doc exists, so prose that points a
reader somewhere cannot go stale unnoticed when a file moves.

Prose is a Python file's comments and docstrings, a C or OpenCL file's comments, and the
whole of a Markdown file. A path is a name with a file extension and at least one folder
(`compile/bvh.py`, `gpiscl/kernels_cl/lib/bvh.h`); it exists if it names a file of the
repository relative to the root, the citing file's folder or one of its parents, or a
root readers abbreviate (`gpiscl/`, `gpiscl/host/`, `gpiscl/kernels_cl/`, its `lib/`)."""
import ast
import io
import re
import subprocess
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CITING = ("gpiscl/", "tools/", "docs/", "tests/", "README.md")
SUFFIXES = (".py", ".h", ".cl", ".c", ".md")
PATH = re.compile(r"(?<![\w./~-])((?:[A-Za-z_][\w-]*/)+[\w-]+\.(?:py|h|cl|md|c|cfg|toml))\b")
ABBREVIATED_ROOTS = ("", "gpiscl", "gpiscl/host", "gpiscl/kernels_cl", "gpiscl/kernels_cl/lib")
# prefixes of paths that name something outside this repository
FOREIGN = ("src/", "warp/", "pbrt/", "mitsuba/", "http", "site-packages/", "usr/",
           "pyopencl-random123/")
C_COMMENT = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)


def repository_files():
    """Tracked files and new ones not yet added (not the ignored ones)."""
    out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"],
                         cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return set(out.split())


def citing_files(files):
    return sorted(p for p in files if p.startswith(CITING) and p.endswith(SUFFIXES)
                  and p != "tests/test_doc_paths.py")   # its examples are missing on purpose


def prose(text: str, suffix: str):
    """(first line number, text) of each piece of prose in a file."""
    if suffix == ".md":
        yield 1, text
    elif suffix == ".py":
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type == tokenize.COMMENT:
                yield tok.start[0], tok.string
        for node in ast.walk(ast.parse(text)):
            body = getattr(node, "body", None)
            if isinstance(body, list) and body and isinstance(body[0], ast.Expr) \
                    and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                yield body[0].lineno, body[0].value.value
    else:
        for m in C_COMMENT.finditer(text):
            yield text.count("\n", 0, m.start()) + 1, m.group()


def resolves(name: str, citing: str, files) -> bool:
    folders = list(ABBREVIATED_ROOTS)
    parent = Path(citing).parent
    while str(parent) != ".":
        folders.append(str(parent))
        parent = parent.parent
    return any(str(Path(f) / name) in files for f in folders)


def stale_references():
    files = repository_files()
    stale = []
    for rel in citing_files(files):
        for first, text in prose((ROOT / rel).read_text(), Path(rel).suffix):
            for offset, line in enumerate(text.splitlines()):
                for name in PATH.findall(line):
                    if not name.startswith(FOREIGN) and not resolves(name, rel, files):
                        stale.append(f"{rel}:{first + offset}: {name}")
    return stale


def test_every_cited_path_exists():
    stale = stale_references()
    assert not stale, "paths named in prose that do not exist:\n" + "\n".join(stale)


def test_the_check_sees_a_missing_path_and_a_present_one():
    files = repository_files()
    assert resolves("compile/bvh.py", "gpiscl/host/render/device.py", files)
    assert resolves("lib/bvh.h", "gpiscl/kernels_cl/stages/intersect.cl", files)
    assert not resolves("kernels_cl/bvh.h", "gpiscl/host/compile/bvh.py", files)
    assert PATH.findall("see gpiscl/host/rough_conductor.py.") == ["gpiscl/host/rough_conductor.py"]
    code = 'x = "lib/nope.h"  # see compile/bvh.py\ndef f():\n    """kernels_cl/bvh.h"""\n'
    assert [t for _, t in prose(code, ".py")] == ["# see compile/bvh.py", "kernels_cl/bvh.h"]
    assert [n for _, n in prose("int a; /* lib/x.h */ // y/z.c\n", ".h")] == ["/* lib/x.h */",
                                                                                 "// y/z.c"]


def test_nothing_cites_the_workspace_outside_the_repository():
    """The product and its tests never point at the developers' workspace beside the
    checkout (a reader of a clone cannot open it): what they need lives in docs/."""
    outside = re.compile(r"\.\./" + "shared/|/work/" + "shared")
    hits = [f"{rel}:{n}" for rel in citing_files(repository_files())
            for n, line in enumerate((ROOT / rel).read_text().splitlines(), 1)
            if outside.search(line)]
    assert not hits, hits
