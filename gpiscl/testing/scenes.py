"""Small scenes the render tests share, and a render that fails on any lost path."""
import numpy as np

from gpiscl import render_result

MEMORIES = ("none", "renewal", "renewal_plus", "global")


def gpis_scene(sampler, bsdf, albedo, lights, spp, seed=3, max_depth=256, rr_start=100000):
    """A rough GPIS ball (sigma comparable to the mean's curvature, l small): concave
    pockets make paths scatter several times inside the proxy."""
    return {"camera": {"position": [0, 0, 3.0], "look_at": [0, 0, 0], "up": [0, 1, 0],
                       "fov": 40, "resolution": [16, 16]},
            "render": {"spp": spp, "seed": seed, "max_depth": max_depth,
                       "russian_roulette": {"start_depth": rr_start}},
            "shapes": [{"type": "gpis", "proxy": {"type": "box", "min": [-1.1] * 3,
                                                  "max": [1.1] * 3},
                        "mean": {"type": "sphere", "radius": 0.7},
                        "kernel": {"type": "squared_exponential", "sigma": 0.3,
                                   "length_scale": 0.2},
                        "sampler": sampler, "bsdf": {"type": bsdf, "albedo": albedo}}],
            "lights": lights}


def function_space_sampler(memory, **kw):
    """The function-space sampler with memory model `memory` (48 rows unless kw says)."""
    return {"type": "function_space", "memory": memory, "memory_cap": 48, **kw}


def render_checked(scene, device, **kw):
    """render_result, failing on any NaN, failed or truncated path."""
    res = render_result(scene, device=device, **kw)
    st = res.stats
    assert st.nan_paths == 0 and st.gpis_failed == 0 and st.truncated_paths == 0, st.summary()
    return res


def fibonacci_sphere(n, radius=1.0):
    """n points spread evenly over the sphere of the given radius (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    phi, z = np.pi * (3.0 - 5.0**0.5) * i, 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    return radius * np.stack([r * np.cos(phi), z, r * np.sin(phi)], 1)


# a sun and a dim sky
SUN_AND_SKY = [{"type": "directional", "direction": [-0.3, -1, -0.4], "irradiance": 3.0},
               {"type": "environment", "radiance": 0.3}]


def sphere_scene(mean_radius, sigma, spp, observations=None, seed=5, res=16):
    g = {"type": "gpis", "proxy": {"type": "box", "min": [-1.6] * 3, "max": [1.6] * 3},
         "mean": {"type": "sphere", "radius": mean_radius},
         "kernel": {"type": "squared_exponential", "sigma": sigma, "length_scale": 0.5},
         "sampler": {"type": "function_space"},
         "bsdf": {"type": "diffuse", "albedo": 0.8}}
    if observations is not None:
        g["observations"] = observations
    return {"camera": {"position": [0, 0, 3.5], "look_at": [0, 0, 0], "up": [0, 1, 0],
                       "fov": 45, "resolution": [res, res]},
            "render": {"spp": spp, "seed": seed, "max_depth": 8,
                       "russian_roulette": {"start_depth": 3}},
            "shapes": [g], "lights": SUN_AND_SKY}


def noisy_sphere_points(path, n, noise, seed=0):
    """n points on the unit sphere, each moved along its normal by N(0, noise^2)."""
    x = fibonacci_sphere(n)
    x *= 1.0 + np.random.default_rng(seed).normal(0.0, noise, (n, 1))
    np.savetxt(path, x, header="noisy unit sphere")
    return str(path)


def slow_scene(resolution=(12, 12), spp=1_000_000):
    return {
        "camera": {"position": [0, 0.3, 4], "look_at": [0, 0, 0], "resolution": list(resolution)},
        "render": {"spp": spp},
        "shapes": [
            {"type": "rectangle", "center": [0, -1, 0], "u": [6, 0, 0], "v": [0, 0, -6],
             "bsdf": {"type": "diffuse", "albedo": 0.5}},
            {"type": "gpis", "proxy": {"type": "sphere", "radius": 1.4},
             "mean": {"type": "sphere", "radius": 0.8},
             "kernel": {"type": "rational_quadratic", "sigma": 0.06, "length_scale": 0.15,
                        "alpha": 0.5},
             "sampler": {"type": "weight_space", "features": 4096}}],
        "lights": [{"type": "environment", "radiance": 0.6},
                   {"type": "directional", "direction": [0.3, 1, 0.4], "irradiance": 2.0}],
    }


def camera(res, position=(0, 0, 4), fov=36.0):
    """A square camera looking at the origin from `position`."""
    return {"position": list(position), "look_at": [0, 0, 0], "up": [0, 1, 0], "fov": fov,
            "resolution": [res, res]}


def posterior_tables(post=None, lead=3):
    """(GpisObject, rows, doubles): the posterior tables of one object, after `lead`
    rows and doubles of another's (so the lookup must use the object's offsets)."""
    from ..host.compile import posterior as PC
    from ..host.layout import function_space_records as FL
    from ..host.layout import records as layouts
    g = layouts.GPIS_OBJECT.zeros(1)
    rows, doubles = FL.FS_OBS.zeros(lead), np.full(lead, np.nan)
    if post is not None:
        r, d = PC.pack_posterior(post)
        g["posterior_first"], g["posterior_count"], g["posterior_doubles"] = lead, len(r), lead
        rows, doubles = np.concatenate([rows, r]), np.concatenate([doubles, d])
    return g, rows, doubles


def sun_sky_floor(resolution=16, seed=3, max_depth=5, sun_radius=0.265):
    """A diffuse floor and sphere under a sun (angular radius in degrees) and a constant
    sky: issue 31's light-choice case, for its tests and tools/bench_light_sampling.py."""
    return {"camera": {"position": [0, 2, 4], "look_at": [0, 0, 0], "up": [0, 1, 0],
                       "fov": 40, "resolution": [resolution, resolution]},
            "render": {"spp": 64, "seed": seed, "max_depth": max_depth},
            "shapes": [{"type": "rectangle", "center": [0, 0, 0], "u": [20, 0, 0],
                        "v": [0, 0, -20], "bsdf": {"type": "diffuse", "albedo": 0.5}},
                       {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5,
                        "bsdf": {"type": "diffuse", "albedo": 0.8}}],
            "lights": [{"type": "directional", "direction": [0.3, 1, 0.2],
                        "irradiance": 3.0, "angular_radius": sun_radius},
                       {"type": "environment", "radiance": 0.5}]}


def classical_stage(shape: dict, spp: int, seed: int, light: str = "rectangle") -> dict:
    """One GPIS shape before the classical counterparts' camera (32x32): lit by a dim sky
    and a rectangle light, or by a white constant environment alone (light="furnace")."""
    lights = ([{"type": "environment", "radiance": 1.0}] if light == "furnace" else
              [{"type": "environment", "radiance": 0.2},
               {"type": "rectangle", "center": [1.5, 2.5, 1.5], "u": [1, 0, 0], "v": [0, 0, 1],
                "radiance": 8.0}])
    return {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "up": [0, 1, 0],
                       "fov": 40, "resolution": [32, 32]},
            "render": {"spp": spp, "seed": seed, "max_depth": 32}, "shapes": [shape],
            "lights": lights}
