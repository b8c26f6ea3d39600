"""Where each random number comes from: named slot ranges, checked disjoint when this
module is imported, emitted as #defines (c_defines, through records.c_header).

The path tracer's stages draw with rng.h's rng4: counter (pixel, sample, bounce, dimension),
four uniforms per call; each stage owns a dimension (STAGE_DIMS).

fs_sampling.h draws from Philox blocks: counter (pixel, sample, bounce, segment, block),
one block = two uniforms. Within a segment (a ray's step) every draw owns fixed blocks,
so a result does not depend on batching or queue order. Normals are numbered in slots,
two to a block (fs_normal: slot s uses block s >> 1); uniforms are numbered in blocks.
Both plans share one block space, so an overlap between them is an error too.

Imports nothing from gpiscl: every layer may read it (tests/test_layering.py).
"""
from __future__ import annotations

from dataclasses import dataclass

NORMALS_PER_BLOCK = 2


@dataclass(frozen=True)
class SlotRange:
    """`count` consecutive slots from `first`; `c_name` is the #define of `first`."""

    name: str
    c_name: str
    first: int
    count: int

    @property
    def last(self) -> int:
        return self.first + self.count - 1


class SlotPlan:
    """Named ranges of one kind of draw, `per_block` of them in a Philox block."""

    def __init__(self, kind: str, per_block: int, ranges):
        self.kind, self.per_block = kind, per_block
        self.ranges = tuple(SlotRange(*r) for r in ranges)
        names = [r.name for r in self.ranges]
        if len(set(names)) != len(names):
            raise ValueError(f"{kind} slot plan names a range twice: {names}")

    def __getitem__(self, name: str) -> SlotRange:
        return next(r for r in self.ranges if r.name == name)

    def blocks(self, r: SlotRange) -> tuple:
        """The Philox blocks range r draws from (first and last, inclusive)."""
        return r.first // self.per_block, r.last // self.per_block

    def c_defines(self) -> list:
        return [line for r in self.ranges for line in
                (f"#define {r.c_name} {r.first}", f"#define {r.c_name}_COUNT {r.count}")]


def overlaps(*plans) -> list:
    """Pairs of ranges (of any of `plans`) that share a Philox block."""
    spans = sorted((*plan.blocks(r), f"{plan.kind}.{r.name}")
                   for plan in plans for r in plan.ranges)
    return [(a[2], b[2]) for i, a in enumerate(spans) for b in spans[i + 1:] if b[0] <= a[1]]


# Normal slots. value: a step's values (the Markov state noise, slots 0..p, p <= 2);
# refine: the root search's points (fs_march.h: one slot each; fs_markov.h: 2 or 4 each,
# at most 33 or 16 points); normal: the hit's two tangential components; markov_start:
# the free components of a Markov start state; tests: the test wrappers' own draws.
NORMAL_SLOTS = SlotPlan("normal", NORMALS_PER_BLOCK, (
    ("value", "FS_SLOT_VALUE", 0, 3),
    ("refine", "FS_SLOT_REFINE", 512, 66),
    ("normal", "FS_SLOT_NORMAL", 578, 2),
    ("markov_start", "FS_MK_SLOT_START", 600, 2),
    ("tests", "FS_SLOT_TESTS", 700, 8),
))
# Uniform blocks. grid: the uniform baseline's offset of a ray's first step; start: the
# truncated-normal start value, and after it the retries of its tail sampler; slope: the
# slope at a hit; track: the heterogeneous medium counterpart's tentative collisions
# (fs_classical.h: block k holds the k-th one's optical depth and acceptance), so a flight
# has at most FS_TRACK_CAP of them and counts a flight that needs more as failed.
FS_TN_TAIL_TRIES = 16   # acceptance > 99.8% each (fs_truncnorm_pos)
FS_TRACK_CAP = 2048
UNIFORM_BLOCKS = SlotPlan("uniform", 1, (
    ("grid", "FS_U_GRID", 1024, 1),
    ("start", "FS_U_START", 1025, 1 + FS_TN_TAIL_TRIES),
    ("slope", "FS_U_SLOPE", 1100, 1),
    ("track", "FS_U_TRACK", 2048, FS_TRACK_CAP),
))
# fs_uniform2's counter holds a block in 12 bits
BLOCK_LIMIT = 1 << 12

# rng4's dimensions (rng.h; another Philox key than fs_sampling.h's, so its own space).
# camera: the pixel offset; light: NEE's light choice and sample; bsdf: the continuation;
# roulette: the path's Russian roulette; shadow_roulette: the survival of a light sample's
# shadow ray at function-space mirror and conductor vertices (scatter.cl); caustic: the light,
# sphere and light point of the manifold NEE (lib/caustics.h); caustic_roulette: the survival
# of its sample. Dimension 4 was
# reserved for GPIS free flights, which draw from the blocks above instead.
STAGE_DIMS = SlotPlan("stage", 1, (
    ("camera", "DIM_CAMERA", 0, 1),
    ("light", "DIM_LIGHT", 1, 1),
    ("bsdf", "DIM_BSDF", 2, 1),
    ("roulette", "DIM_ROULETTE", 3, 1),
    ("shadow_roulette", "DIM_SHADOW_ROULETTE", 5, 1),
    ("caustic", "DIM_CAUSTIC", 6, 1),
    ("caustic_roulette", "DIM_CAUSTIC_ROULETTE", 7, 1),
))

_CLASHES = overlaps(NORMAL_SLOTS, UNIFORM_BLOCKS) + overlaps(STAGE_DIMS)
if _CLASHES:
    raise ValueError(f"random slot ranges share Philox blocks: {_CLASHES}")
_BEYOND = [r.name for plan in (NORMAL_SLOTS, UNIFORM_BLOCKS) for r in plan.ranges
           if plan.blocks(r)[1] >= BLOCK_LIMIT]
if _BEYOND:
    raise ValueError(f"random slot ranges beyond block {BLOCK_LIMIT - 1}: {_BEYOND}")


def c_defines() -> str:
    lines = ["/* Generated from gpiscl/host/layout/random_slots.py: do not edit. */"]
    lines += NORMAL_SLOTS.c_defines() + UNIFORM_BLOCKS.c_defines()
    lines += [f"#define {r.c_name} {r.first}" for r in STAGE_DIMS.ranges]
    lines.append(f"#define FS_TN_TAIL_TRIES {FS_TN_TAIL_TRIES}")
    lines.append(f"#define FS_TRACK_CAP {FS_TRACK_CAP}")
    return "\n".join(lines) + "\n"
