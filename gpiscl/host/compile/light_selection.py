"""Which light next-event estimation picks: each with probability proportional to its
power estimate (the kind's LightHost.power, kinds/lights.py), drawn in O(1) from an alias
table (Walker/Vose) built once per scene. docs/design/light-sampling.md derives it.

The table is the LIGHT_CHOICE records (layout/records.py), one per light: pmf, the
probability of choosing that light (every MIS weight of a light divides by it); and the
alias table's threshold and alias: with s = u * n, i = floor(s), light i is chosen when
s - i < threshold[i], else alias[i]. Two tables of n records each, one after the other
(kernels_cl/lib/lights.h light_choice_at): for vertices with a cosine-wide BSDF lobe,
and for those that leave environments to BSDF sampling (function-space mirrors): their
lobe is narrow, environments get 0 there, and each light's estimate weighs the chance
that a BSDF sample of a NARROW_LOBE misses it.
"""
from __future__ import annotations

import math

import numpy as np

from ..kinds.lights import LIGHTS
from ..layout import records as layouts


def selection_pmf(powers) -> np.ndarray:
    """Probabilities in proportion to the powers; uniform when none is positive (a scene
    of black lights: any choice is as good, and each must still be pickable)."""
    p = np.maximum(np.asarray(powers, dtype=np.float64), 0.0)
    p[~np.isfinite(p)] = 0.0
    total = p.sum()
    if len(p) == 0:
        return p
    return p / total if total > 0.0 else np.full(len(p), 1.0 / len(p))


def alias_table(pmf) -> tuple:
    """(threshold, alias) of Vose's alias method: choosing i = floor(u n) and keeping it
    when the fraction is below threshold[i], else taking alias[i], draws i with pmf."""
    n = len(pmf)
    scaled = np.asarray(pmf, dtype=np.float64) * n
    threshold, alias = np.ones(n), np.arange(n)
    small = [i for i in range(n) if scaled[i] < 1.0]
    large = [i for i in range(n) if scaled[i] >= 1.0]
    while small and large:
        s, g = small.pop(), large.pop()
        threshold[s], alias[s] = scaled[s], g
        scaled[g] -= 1.0 - scaled[s]
        (small if scaled[g] < 1.0 else large).append(g)
    # what is left holds 1 up to rounding: it keeps itself
    return threshold, alias


# The solid angle of a function-space mirror's reflection lobe, as a light's estimate
# sees it: a cone of 30 degrees (normals spread by up to 15: the shipped mirror GPISs have
# 0.1-16). A light wider than it is found by BSDF sampling as well as by a light sample.
NARROW_LOBE = 2.0 * math.pi * (1.0 - math.cos(math.radians(30.0)))


def _records(powers) -> np.ndarray:
    pmf = selection_pmf(powers)
    threshold, alias = alias_table(pmf)
    out = layouts.LIGHT_CHOICE.zeros(len(pmf))
    out["pmf"], out["threshold"], out["alias"] = pmf, threshold, alias
    return out


def light_choice(fields: list, kinds: list, radius: float) -> np.ndarray:
    """The LIGHT_CHOICE records of a scene's lights, the wide lobe's table then the
    narrow lobe's: fields, each light's packed fields (kinds/lights.py); kinds, their kind
    names; radius, the scene's bounding radius."""
    hosts = [LIGHTS[k].host for k in kinds]
    wide = [h.power(f, radius) for h, f in zip(hosts, fields)]
    narrow = [0.0 if LIGHTS[k].traits["environment"] else h.power(f, radius, NARROW_LOBE)
              for h, f, k in zip(hosts, fields, kinds)]
    return np.concatenate([_records(wide), _records(narrow)])
