"""Built-in scenes as plain dicts (pass them to load_scene / render, or edit them first)."""
from __future__ import annotations


def _wall(center, u, v, albedo):
    # cross(u, v) faces into the room
    return {"type": "rectangle", "center": center, "u": u, "v": v,
            "bsdf": {"type": "diffuse", "albedo": albedo}}


def default_scene() -> dict:
    """A Cornell-style box, 2 units on a side, lit by a rectangle in its ceiling, holding a
    box, a mirror sphere and a weight-space GPIS."""
    white, red, green = [0.73, 0.73, 0.73], [0.63, 0.065, 0.05], [0.14, 0.45, 0.091]
    return {
        # the open front of the box just fills the 40-degree view from here
        "camera": {"position": [0, 1, 3.6], "look_at": [0, 1, 0], "up": [0, 1, 0],
                   "fov": 40, "resolution": [256, 256]},
        "render": {"spp": 16, "max_depth": 8, "seed": 0},
        "shapes": [
            _wall([0, 0, 0], [2, 0, 0], [0, 0, -2], white),     # floor
            _wall([0, 2, 0], [2, 0, 0], [0, 0, 2], white),      # ceiling
            _wall([0, 1, -1], [2, 0, 0], [0, 2, 0], white),     # back
            _wall([-1, 1, 0], [0, 2, 0], [0, 0, 2], red),       # left
            _wall([1, 1, 0], [0, 0, 2], [0, 2, 0], green),      # right
            {"type": "box", "min": [-0.75, 0, -0.75], "max": [-0.15, 0.25, -0.15],
             "bsdf": {"type": "diffuse", "albedo": white}},
            # a rough blue blob: a GPIS around a sphere mean, averaged over realizations
            {"type": "gpis", "proxy": {"type": "sphere", "center": [-0.45, 0.6, -0.45],
                                       "radius": 0.6},
             "mean": {"type": "sphere", "center": [-0.45, 0.6, -0.45], "radius": 0.32},
             "kernel": {"type": "squared_exponential", "sigma": 0.04, "length_scale": 0.08},
             "sampler": {"type": "weight_space"},
             "bsdf": {"type": "diffuse", "albedo": [0.25, 0.35, 0.7]}},
            {"type": "sphere", "center": [0.42, 0.38, 0.25], "radius": 0.38,
             "bsdf": {"type": "mirror", "albedo": 0.95}},
        ],
        # just below the ceiling so the two never coincide; faces down
        "lights": [{"type": "rectangle", "center": [0, 1.995, 0], "u": [0.5, 0, 0],
                    "v": [0, 0, 0.5], "radiance": [18.0, 15.0, 11.0]}],
    }


def furnace_sphere(albedo=1.0, bsdf: str = "diffuse") -> dict:
    """A unit sphere in a unit white environment: with albedo 1 every pixel is 1."""
    material = {"type": bsdf}
    if bsdf != "null":
        material["albedo"] = albedo
    return {
        "camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "up": [0, 1, 0],
                   "fov": 40, "resolution": [32, 32]},
        "render": {"spp": 16},
        "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "bsdf": material}],
        "lights": [{"type": "environment", "radiance": 1.0}],
    }
