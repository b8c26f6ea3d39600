"""Memory models of the function-space sampler: what a path remembers of the realization
between its rays (scene key sampler.memory).

Every model is three hooks in kernels_cl/lib/fs_memory.h, which asks these traits:
  fs_memory_start_rows  the rows a ray starts from at a hit: the path's ring of every
                        observation so far (ring), the hit's value and slope (renews), or
                        nothing (a fresh value at the ray's start); renewal draws the
                        slope afresh given the value (fresh_slope), renewal_plus keeps it
  fs_memory_record      what a hit records for later rays: its ray's rows into the ring
  fs_memory_markov_ok   whether fs_markov.h's exact Matern sampler may run: only when every
                        row a ray conditions on lies on that ray (not ring)
and fs_objects.h asks `exponential`: the flight is fs_classical.h's medium counterpart
(Rice's entry rate as extinction: exponential where it is constant, tracked elsewhere)
instead of the sampler's.
"""
from __future__ import annotations

from .table import Kind, KindTable

_SAMPLED = {"exponential": False}
MEMORY_MODELS = KindTable("memory model", "GPIS_MEMORY", [
    Kind("none", traits={"ring": False, "renews": False, "fresh_slope": False, **_SAMPLED}),
    Kind("renewal", traits={"ring": False, "renews": True, "fresh_slope": True, **_SAMPLED}),
    Kind("renewal_plus", traits={"ring": False, "renews": True, "fresh_slope": False,
                                 **_SAMPLED}),
    Kind("global", traits={"ring": True, "renews": False, "fresh_slope": False, **_SAMPLED}),
    # remembers nothing and samples no realization: the medium counterpart ("classical":
    # "medium" selects it; docs/design/classical-limits.md)
    Kind("classical_medium", traits={"ring": False, "renews": False, "fresh_slope": False,
                                     "exponential": True}),
], traits=("ring", "renews", "fresh_slope", "exponential"))
