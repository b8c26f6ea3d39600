"""The GP axes' kind tables (host/kinds: GP kernels, mean primitives, memory models, colour
fields): every kind has its schema, host class, packer, device id and device functions;
and a kernel registered for the duration of a test, from one device file written here,
samples and renders with the statistics its closed form predicts."""
import math
import re
from dataclasses import dataclass

import numpy as np
import pyopencl as cl
import pytest

from gpiscl import render_result
from gpiscl.host.gp import kernels as K
from gpiscl.host.gp import means as M
from gpiscl.host.kinds.colour_fields import COLOUR_FIELDS
from gpiscl.host.kinds.gp_kernels import GP_KERNELS, KernelHost, kernel, required_functions
from gpiscl.host.kinds.means import MEAN_OPS, MEAN_PRIMITIVES
from gpiscl.host.kinds.memory_models import MEMORY_MODELS
from gpiscl.host.kinds.table import KERNELS_CL
from gpiscl.host.layout import gp_records, records
from gpiscl.host.render.program_sources import fs_sampler_options, fs_sampler_source
from gpiscl.host.schema import Context, Field, Number
from gpiscl.host.scene.colour_fields import COLOR, EMISSION
from gpiscl.host.scene.gpis import GPIS, KERNELS, MEANS
from gpiscl.testing.flights import CAP_MAX, FLIGHT_WRAPPERS as FS_WRAPPERS, WINDOW_MAX, run_crossings
from gpiscl.testing.scenes import camera
from gpiscl.testing.stats import image_mean_se, z_threshold
from gpiscl.testing.weight_space import build as ws_build, dump

CTX = Context("<test>", ".")


def _defines(path) -> set:
    return set(re.findall(r"^inline\s+\w+\s+(\w+)\s*\(", (KERNELS_CL / path).read_text(), re.M))


# --- every kind is whole ----------------------------------------------------------------

@pytest.mark.parametrize("name", GP_KERNELS.names)
def test_every_gp_kernel_has_schema_host_class_packer_id_and_device_functions(name):
    kind = GP_KERNELS[name]
    resolved = KERNELS.resolve({"type": name}, "kernel", CTX)   # the scene's own schema
    params = {k: tuple(v) if isinstance(v, list) else v for k, v in resolved.items()
              if k not in ("type", "sigma_field", "length_scale_field")}
    host = kind.host.cls(**params)
    assert isinstance(host, K.Kernel) and host.kind == name
    packed = gp_records.pack_kernel(host)
    assert packed["kind"] == GP_KERNELS.id(name)
    for field in kind.host.params:   # the packer fills what the device reads
        assert packed[field] == np.float32(getattr(host, field)), field
    assert kind.host.length(resolved) > 0
    assert f"#define GP_KERNEL_{name.upper()} {GP_KERNELS.id(name)}" in records.c_header()
    assert set(required_functions(kind)) <= _defines(kind.device_file)
    assert ("length_scale_field" in KERNELS.variants[name].fields) == kind.traits["length_field"]


@pytest.mark.parametrize("name", MEAN_PRIMITIVES.names)
def test_every_mean_primitive_has_schema_host_class_packer_id_and_device_function(name):
    kind = MEAN_PRIMITIVES[name]
    assert f"{name}_mean" in _defines(kind.device_file)
    assert f"#define GP_MEAN_{name.upper()} {MEAN_PRIMITIVES.id(name)}" in records.c_header()
    if kind.schema is None:   # the grid leaf: built by the scene's mesh, grid, procedural
        assert {"mesh", "grid", "procedural"} <= set(MEANS.variants)
        return
    node = kind.host.build(MEANS.resolve({"type": name}, "mean", CTX))
    assert isinstance(node, M.Mean)
    prog = gp_records.pack_mean(node)
    assert len(prog) == 1 and prog["kind"][0] == MEAN_PRIMITIVES.id(name)


def test_mean_operations_follow_the_primitives_and_build_from_the_scene():
    assert min(MEAN_OPS.id(n) for n in MEAN_OPS.names) >= len(MEAN_PRIMITIVES)
    for name in MEAN_OPS.names:
        m = MEANS.resolve({"type": name, "left": {"type": "sphere"}, "right": {"type": "box"}},
                          "mean", CTX)
        from gpiscl.host.compile.gpis import build_mean
        prog = gp_records.pack_mean(build_mean(m))
        assert prog["kind"][-1] == MEAN_OPS.id(name)


def test_memory_models_are_the_scene_choices_and_drive_the_device_hooks():
    sampler = GPIS.fields["sampler"].spec.variants["function_space"].fields["memory"]
    assert tuple(sampler.spec.choices) == MEMORY_MODELS.names
    header = records.c_header()
    for trait in MEMORY_MODELS.trait_names:
        assert f"#define GPIS_MEMORY_IS_{trait.upper()}(k)" in header
    hooks = _defines("lib/fs_memory.h")
    assert {"fs_memory_start_rows", "fs_memory_record", "fs_memory_markov_ok"} <= hooks
    # no model is named anywhere in the device code: the hooks ask traits
    for path in (KERNELS_CL / "lib").glob("*.h"):
        for name in MEMORY_MODELS.names:
            assert f"GPIS_MEMORY_{name.upper()}" not in path.read_text(), path.name


@pytest.mark.parametrize("name", COLOUR_FIELDS.names)
def test_every_colour_field_has_both_schemas_a_packer_and_an_id(name):
    from gpiscl.host.compile.colour_fields import pack_field
    assert name in COLOR.family.variants and name in EMISSION.family.variants
    assert f"#define GPIS_FIELD_{name.upper()} {COLOUR_FIELDS.id(name)}" in records.c_header()
    assert COLOUR_FIELDS.id(name) > max(gp_records.MEAN_KINDS.values())
    if name != "grid":   # (a grid needs a file: tests/test_gpis_fields.py packs one)
        value = {"constant": {"value": 0.5}, "checker": {"scale": 1, "a": 0, "b": 1},
                 "gradient": {"start": [0, 0, 0], "end": [1, 0, 0], "a": 0, "b": 1}}[name]
        field = COLOR.family.resolve({"type": name, **value}, "color", CTX)
        assert pack_field(field)["kind"][0] == COLOUR_FIELDS.id(name)


# --- a kernel from one file -------------------------------------------------------------

# k = sigma^2 / (1 + s / (2 l^2)): the rational quadratic at alpha = 1, written afresh. Its
# spectral law is a Gaussian scale mixture with tau ~ Exponential(rate l^2); -k''(0) =
# sigma^2 / l^2 along a unit direction.
TOY_DEVICE = r"""
/* toy_cauchy: k = sigma^2 / (1 + s / (2 l^2)) (tests/test_kinds_gp.py) */
#ifdef GP_KERNEL_PART_COVARIANCE
inline GP_REAL toy_cauchy_radial_arg(GpKernel p, GP_REAL s)
{
    GP_REAL l2 = (GP_REAL)p.length_scale * (GP_REAL)p.length_scale;
    return -log1p(s / (2 * l2));
}

inline void toy_cauchy_radial_of(GpKernel p, GP_REAL s, GP_REAL e, GP_REAL* k, GP_REAL* dk2,
                                 GP_REAL* ddk4)
{
    GP_REAL l2 = (GP_REAL)p.length_scale * (GP_REAL)p.length_scale, base = 1 + s / (2 * l2);
    *k = (GP_REAL)p.sigma2 * e;
    *dk2 = -*k / (l2 * base);
    *ddk4 = 2 * *k / (l2 * l2 * base * base);
}
#endif
#ifdef GP_KERNEL_PART_SPECTRAL
inline wsf toy_cauchy_ws_scale(GpKernel k, uint2 key, int object, wsi idx)
{
    return sqrt(ws_gamma(1.0f, key, object, idx) / (k.length_scale * k.length_scale));
}

inline float toy_cauchy_ws_lambda2(GpKernel k, float s)
{
    return s / (k.length_scale * k.length_scale);
}
#endif
"""


@dataclass(frozen=True)
class ToyCauchy(K.Kernel):
    sigma: float = 1.0
    length_scale: float = 1.0
    aniso: tuple = (1.0, 1.0, 1.0)
    kind = "toy_cauchy"

    def jet(self, r):
        a, r = np.asarray(self.aniso, float), np.asarray(r, float)
        l2 = self.length_scale ** 2
        base = 1.0 + np.sum(a * r * r, -1) / (2.0 * l2)
        k = self.sigma ** 2 / base
        dk2, ddk4 = -k / (l2 * base), 2.0 * k / (l2 * l2 * base * base)
        return K.Jet(k, dk2[..., None] * a * r, ddk4, a * r, dk2[..., None] * a)


@pytest.fixture
def toy(tmp_path):
    path = tmp_path / "toy_cauchy.h"
    path.write_text(TOY_DEVICE)
    kind = kernel("toy_cauchy", {"length_scale": Field(Number(gt=0), 1.0)},
                  KernelHost(ToyCauchy, ("length_scale",), lambda k: k["length_scale"]),
                  device_file=str(path), radial=True, spectral=True, periodic_orders=False,
                  markov_order=0, corr_lag=False, length_field=False, ws_posterior=False)
    with GP_KERNELS.registered(kind):
        yield ToyCauchy()
    assert "toy_cauchy" not in GP_KERNELS and "toy_cauchy" not in KERNELS.variants


def test_a_registered_kernel_samples_rays_with_rices_crossing_count(device, toy):
    """Function space, level 0, unit ray of length L: E[down-crossings] = L sqrt(lambda2)
    / (2 pi) + 1/4 (Rice, plus the start's f -> -f symmetry), lambda2 = 1 / l^2."""
    program = cl.Program(device.ctx, fs_sampler_source(FS_WRAPPERS)).build(
        options=fs_sampler_options(WINDOW_MAX, CAP_MAX))
    prg = {k.function_name: k for k in program.all_kernels()}
    n, L = 400, 40.0
    out = run_crossings(device, prg, toy, 0.0, n, L, memory="renewal_plus", seed=5)
    cnt = out[:, 0]
    expect = L / (2.0 * math.pi) + 0.25
    se = cnt.std(ddof=1) / math.sqrt(n)
    assert abs(cnt.mean() - expect) < z_threshold(3) * se, (cnt.mean(), expect, se)


def test_a_registered_kernel_draws_frequencies_of_its_spectral_law(device, toy):
    """Weight space: E[cos(theta . r)] = k(r) / sigma^2 = 2/3 at |r| = l, and the device's
    lambda2 is 1 / l^2 (tolerance from the feature count)."""
    prg = ws_build(device)
    keys = np.stack([np.arange(64), np.full(64, 9)], -1).astype(np.uint32)
    theta, _, _ = dump(device, prg, toy, keys, 256)
    c = np.cos(theta[..., 0]).ravel()
    assert abs(c.mean() - 2.0 / 3.0) < z_threshold(3) * c.std(ddof=1) / math.sqrt(c.size)
    t2 = (theta[..., 1] ** 2).ravel()      # E[tau z^2] = E[tau] = 1 / l^2
    assert abs(t2.mean() - 1.0) < z_threshold(3) * t2.std(ddof=1) / math.sqrt(t2.size)


def test_a_registered_kernel_renders_the_white_furnace(device, toy):
    """A scene names the kernel; an albedo-1 diffuse realization in a unit environment
    leaves every path's value 1."""
    shape = {"type": "gpis", "proxy": {"type": "sphere", "radius": 1.6},
             "mean": {"type": "sphere", "radius": 1.0},
             "kernel": {"type": "toy_cauchy", "sigma": 0.1, "length_scale": 0.2},
             "sampler": {"type": "weight_space", "features": 64},
             "bsdf": {"type": "diffuse", "albedo": 1.0}}
    scene = {"camera": camera(8), "lights": [{"type": "environment", "radiance": 1.0}],
             "render": {"spp": 8, "seed": 3, "max_depth": 256,
                        "russian_roulette": {"start_depth": 1000}},
             "shapes": [shape]}
    res = render_result(scene, device=device)
    assert res.stats.killed_paths == 0 and res.stats.nan_paths == 0, res.stats.summary()
    img = res.image
    assert abs(img.mean.mean() - 1.0) <= z_threshold(1) * image_mean_se(img.stderr) + 1e-6
