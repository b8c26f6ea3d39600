"""Every file path named in a comment, docstring or doc exists, so prose that points a
reader somewhere cannot go stale unnoticed when a file moves.

A path is a name with a file extension and at least one folder (`compile/bvh.py`,
`gpiscl/kernels_cl/lib/bsdf.h`); it counts as existing if it names a tracked file
relative to the repository root, the citing file's folder or one of its parents, or the
package roots readers abbreviate (`gpiscl/`, `gpiscl/host/`, `gpiscl/kernels_cl/`).
Paths of files a user or a run creates (`out/`, `~/`, `/tmp`, URLs) are not checked."""
import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CITING = ("gpiscl/", "tools/", "docs/", "tests/", "README.md")
SUFFIXES = (".py", ".h", ".cl", ".md", ".c", ".cfg", ".toml")
PATH = re.compile(r"(?<![\w./~-])((?:[A-Za-z_][\w-]*/)+[\w-]+\.(?:py|h|cl|md|c|cfg|toml))\b")
ABBREVIATED_ROOTS = ("", "gpiscl", "gpiscl/host", "gpiscl/kernels_cl")
# prefixes of paths that name something outside this repository
FOREIGN = ("src/", "warp/", "pbrt/", "mitsuba/", "http", "site-packages/", "usr/",
           "pyopencl-random123/")


def repository_files():
    """Tracked files and new ones not yet added (not the ignored ones)."""
    out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"],
                         cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return set(out.split())


def citing_files(tracked):
    return sorted(p for p in tracked if p.startswith(CITING) and p.endswith(SUFFIXES)
                  and p != "tests/test_doc_paths.py")   # its examples are missing on purpose


def resolves(name: str, citing: str, tracked) -> bool:
    folders = list(ABBREVIATED_ROOTS)
    parent = Path(citing).parent
    while str(parent) != ".":
        folders.append(str(parent))
        parent = parent.parent
    return any(str(Path(f) / name) in tracked for f in folders)


def stale_references():
    tracked = repository_files()
    stale = []
    for rel in citing_files(tracked):
        for lineno, line in enumerate((ROOT / rel).read_text().splitlines(), 1):
            for name in PATH.findall(line):
                if name.startswith(FOREIGN) or resolves(name, rel, tracked):
                    continue
                stale.append(f"{rel}:{lineno}: {name}")
    return stale


def test_every_cited_path_exists():
    stale = stale_references()
    assert not stale, "paths named in prose that do not exist:\n" + "\n".join(stale)


def test_the_check_sees_a_missing_path_and_a_present_one():
    tracked = repository_files()
    assert resolves("compile/bvh.py", "gpiscl/host/render/device.py", tracked)
    assert resolves("lib/bsdf.h", "gpiscl/kernels_cl/stages/scatter.cl", tracked)
    assert not resolves("kernels_cl/bvh.h", "gpiscl/host/compile/bvh.py", tracked)
    assert PATH.findall("see gpiscl/host/rough_conductor.py.") == ["gpiscl/host/rough_conductor.py"]
