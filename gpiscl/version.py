"""The version, importable from any layer (it imports nothing of gpiscl)."""
import functools
import subprocess
from pathlib import Path

__version__ = "0.1.0"


@functools.lru_cache(maxsize=None)
def source_commit() -> str:
    """The git commit of the checkout gpiscl runs from ('+' appended when its tracked
    files differ from it), or '' for an installed copy outside a checkout: an output's
    header then says exactly which code made it."""
    here = Path(__file__).resolve().parent
    try:
        def git(*args):
            return subprocess.run(["git", "-C", str(here), *args], capture_output=True,
                                  text=True, timeout=10, check=True).stdout.strip()
        commit = git("rev-parse", "HEAD")
        changed = git("status", "--porcelain", "--untracked-files=no", "--", str(here))
    except (OSError, subprocess.SubprocessError):
        return ""
    return commit + ("+" if changed else "")
