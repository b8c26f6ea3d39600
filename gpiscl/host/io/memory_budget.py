"""How much more memory this process can get, before it allocates: the tightest of
  free RAM      /proc/meminfo MemAvailable
  the process   RLIMIT_AS (`ulimit -v`, as batch systems set it) less the address space it
                maps already (VmSize), RLIMIT_DATA (`ulimit -d`) less its data (VmData)
  its cgroup    a container's or a job's memory limit (v2 memory.max, v1
                memory.limit_in_bytes) less what the cgroup uses, at its own level and at
                every level above it (a parent's limit binds its children)
MemAvailable alone let renders over a process or cgroup limit pass the check and fail late
(docs/design/memory-budget.md, 'The budget').

A cgroup's usage counts its page cache; the inactive file pages among it are the first the
kernel reclaims, so they count as free (the working set container tools report).

The file readers take the /proc and cgroup roots as parameters so that tests can point them
at a made-up tree.
"""
from __future__ import annotations

import os
import resource
from dataclasses import dataclass
from pathlib import Path

PROC = Path("/proc")
CGROUP_ROOT = Path("/sys/fs/cgroup")
UNKNOWN = 1 << 62       # no limit found: do not refuse


@dataclass(frozen=True)
class Budget:
    bytes: int
    limit: str          # which limit binds, for messages: "free RAM (MemAvailable)", ...


def memory_budget(proc: Path = PROC, cgroup_root: Path = CGROUP_ROOT) -> Budget:
    """The tightest limit on what this process can still allocate (never negative)."""
    budgets = [free_ram(proc), *process_limits(proc), *cgroup_limits(proc, cgroup_root)]
    tightest = min(budgets, key=lambda b: b.bytes)
    return Budget(max(tightest.bytes, 0), tightest.limit)


def free_ram(proc: Path = PROC) -> Budget:
    """MemAvailable (free RAM a new allocation can get, caches it may evict included),
    else all RAM."""
    fields = _key_values(proc / "meminfo")
    if "MemAvailable" in fields:
        return Budget(_kib(fields["MemAvailable"]), "free RAM (MemAvailable)")
    try:
        return Budget(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"), "RAM")
    except (ValueError, OSError, AttributeError):
        return Budget(UNKNOWN, "RAM (unknown)")


def process_limits(proc: Path = PROC) -> list:
    """The headroom under this process's soft RLIMIT_AS and RLIMIT_DATA, where set."""
    status = _key_values(proc / "self" / "status")
    out = []
    for name, used, shell in (("RLIMIT_AS", "VmSize", "ulimit -v"),
                              ("RLIMIT_DATA", "VmData", "ulimit -d")):
        soft, _ = resource.getrlimit(getattr(resource, name))
        if soft == resource.RLIM_INFINITY:
            continue
        mapped = _kib(status[used]) if used in status else 0
        out.append(Budget(soft - mapped, f"the process limit {name} ({shell}) of "
                                         f"{size_text(soft)}, {size_text(mapped)} mapped already"))
    return out


def cgroup_limits(proc: Path = PROC, cgroup_root: Path = CGROUP_ROOT) -> list:
    """The headroom under every memory limit of this process's cgroups (v2 and v1), from
    its own cgroup up to the hierarchy's root."""
    try:
        lines = (proc / "self" / "cgroup").read_text().splitlines()
    except OSError:
        return []
    out = []
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        _, controllers, path = parts
        if controllers == "":     # v2: one unified hierarchy
            out += _levels(cgroup_root, path, "memory.max", "memory.current", "inactive_file")
        elif "memory" in controllers.split(","):
            out += _levels(cgroup_root / "memory", path, "memory.limit_in_bytes",
                           "memory.usage_in_bytes", "total_inactive_file")
    return out


def _levels(root: Path, path: str, limit_file: str, usage_file: str, inactive_key: str):
    here = root / path.strip("/")
    levels = [here, *here.parents]
    levels = levels[:levels.index(root) + 1] if root in levels else [root]
    out = []
    for level in levels:
        limit = _number(level / limit_file)
        usage = _number(level / usage_file)
        if limit is None or usage is None or limit >= UNKNOWN:
            continue        # no such file, "max", or v1's "unlimited" (~2^63)
        inactive = _key_values(level / "memory.stat", sep=" ").get(inactive_key, "0")
        used = max(usage - int(inactive), 0)
        out.append(Budget(limit - used, f"the memory cgroup's limit of {size_text(limit)} "
                                        f"({level / limit_file}), {size_text(used)} in use"))
    return out


def _number(path: Path):
    try:
        text = path.read_text().strip()
        return int(text)
    except (OSError, ValueError):   # absent, or "max" (no limit)
        return None


def _key_values(path: Path, sep: str = ":") -> dict:
    try:
        with open(path) as f:
            pairs = (line.split(sep, 1) for line in f if sep in line)
            return {k.strip(): v.strip() for k, v in pairs}
    except OSError:
        return {}


def _kib(text: str) -> int:
    return int(text.split()[0]) * 1024


def size_text(n: float) -> str:
    """Bytes in the largest binary unit that keeps the number >= 1: `192 MiB`, `10 KiB`
    (a --max-memory 10K budget read `9.54e-06 GiB`)."""
    for shift, unit in ((40, "TiB"), (30, "GiB"), (20, "MiB"), (10, "KiB")):
        if abs(n) >= 1 << shift:
            return f"{n / (1 << shift):.3g} {unit}"
    return f"{n:.0f} bytes"
