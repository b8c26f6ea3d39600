"""Complex refractive indices (eta + i k) of common metals, as RGB.

The values are the per-channel averages of measured spectra that PBRT, Mitsuba and the
authors' Tungsten ship for their conductor presets (the wedge scene's "Cu" included), so
a converted scene reflects the same colour. Any other metal: give "eta" and "k".
"""
from __future__ import annotations

CONDUCTORS = {
    "Cu": ((0.2004376970, 0.9240334304, 1.1022119527), (3.9129485033, 2.4528477015, 2.1421879552)),
    "Au": ((0.1431189557, 0.3749570432, 1.4424785571), (3.9831604247, 2.3857207478, 1.6032152899)),
    "Ag": ((0.1552646489, 0.1167232965, 0.1383806959), (4.8283433224, 3.1222459278, 2.1469504455)),
    "Al": ((1.6574599595, 0.8803689579, 0.5212287346), (9.2238691996, 6.2695232477, 4.8370012281)),
}


def eta_k(bsdf: dict):
    """(eta, k) RGB of a resolved conductor (rough_conductor, or a mirror with a Fresnel
    term): its own eta and k, else those of the preset its "material" names."""
    if bsdf.get("eta") is not None:
        return tuple(bsdf["eta"]), tuple(bsdf["k"])
    return CONDUCTORS[bsdf["material"]]
