"""The authors' scene keys that the Tungsten importer (tungsten.py) does not map: what each
does in their renderer and what gpiscl does instead. A note is printed only when the
scene's value changes their renderer's behaviour away from what gpiscl does anyway, so
their example scenes convert with a short list of real differences.

Each table maps a key to (the value that behaves as gpiscl does, or None when any value
differs; the note, with {v} for the scene's value).
"""
from __future__ import annotations

MEDIUM = {
    "normal_method": ("conditioned_gaussian",
                      'normals "{v}" (their alternative normal model); gpiscl always samples '
                      "the normal from the GP conditioned on the hit (their "
                      "conditioned_gaussian)"),
    "intersect_method": ("gp_discrete",
                         'intersection "{v}" (theirs sphere-traces the mean); gpiscl always '
                         "samples the GP along the ray (their gp_discrete)"),
    "skip_space": (0, "skips a ray's start while the occupancy P(f < 0) is below {v}; gpiscl "
                      "skips empty space by its own occupancy bounds, always on"),
    "step_size": (0, "caps their step at {v} when step_size_cov is 0; gpiscl caps the step by "
                     "correlation only (sampler.step_corr)"),
    "max_bounces": (1024, "ends a path after {v} medium events since the last surface; "
                          "gpiscl counts every event against render.max_depth"),
    "transmittance": (None, "unused by their GP media; ignored"),
}

INTEGRATOR = {
    "min_bounces": (0, "no Russian roulette before bounce {v} in theirs; gpiscl's roulette "
                       "follows its own rule"),
    "low_order_scattering": (True, "= {v} drops paths with one medium event before a surface "
                                   "(a transport-order study switch); gpiscl renders all "
                                   "orders"),
    "include_surfaces": (True, "= {v} drops surface light before the first medium event (a "
                               "transport-order study switch); gpiscl renders all paths"),
    "enable_consistency_checks": (False, "their debug checks; nothing to map"),
    "enable_two_sided_shading": (True, "= {v} shades back faces black in theirs; gpiscl's "
                                       "diffuse and mirror surfaces are two-sided"),
}

CAMERA = {
    "reconstruction_filter": ("box", 'their "{v}" pixel filter; gpiscl averages samples '
                                     "spread uniformly over each pixel (a box filter)"),
}


def notes_for(table: dict, block: dict, key: str) -> list[str]:
    """One note per key of `table` present in `block` whose value departs from gpiscl's
    behaviour."""
    out = []
    for name, (same, text) in table.items():
        if name in block and block[name] != same:
            out.append(f"{key}.{name}: " + text.format(v=block[name]))
    return out


# top-level keys of a Tungsten scene that no gpiscl scene has
TUNGSTEN_TOP_KEYS = ("primitives", "media", "bsdfs", "integrator", "renderer")


def tungsten_hint(doc) -> str | None:
    """The reason to give when a document handed to the scene loader is a Tungsten scene
    (two or more of their top-level keys and none of ours), else None: `media: unknown
    key` did not tell a user that the file only needs converting."""
    if not isinstance(doc, dict) or "shapes" in doc or "lights" in doc:
        return None
    found = [k for k in TUNGSTEN_TOP_KEYS if k in doc]
    if len(found) < 2:
        return None
    return (f"this looks like a Tungsten scene (top-level {', '.join(found)}), not a gpiscl "
            "scene; convert it first: gpiscl convert-tungsten SCENE.json OUT.json")


def tungsten_hint_of_text(text: str) -> str | None:
    """tungsten_hint of a text that is not strict JSON (their files may have trailing
    commas and comments), read as their renderer reads it."""
    from ..errors import SceneError
    from ..io.lenient_json import parse_lenient_json
    try:
        return tungsten_hint(parse_lenient_json(text))
    except SceneError:
        return None
