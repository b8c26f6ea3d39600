"""GP covariance kernels: the one declaration of each kernel.

An entry names its scene fields, its host class (gp/kernels.py, the numpy model), the
GpKernel fields its packer fills, and the file kernels_cl/lib/gp_kernels/<name>.h holding
its device maths. The traits answer the device's "which kernels do X" questions and say
which device functions the file must define (required_functions):
  radial           a function of s = r^T A r alone: <name>_radial_arg (the exponent whose
                   exp it takes) and <name>_radial_of (k, 2 k'(s), 4 k''(s) given that exp);
                   otherwise a product sigma^2 exp(-h): <name>_log_terms (h, grad h,
                   diag Hess h)
  spectral         has a spectral density, so weight space samples it: <name>_ws_scale
                   (the Gaussian scale-mixture factor of a frequency) and <name>_ws_lambda2
                   (the spectral second moment along a direction)
  periodic_orders  its spectrum adds integer multiples of 2 pi w sqrt(A) (the periodic
                   order tables, gp/spectral.py order_table)
  markov_order     p > 0: (f, ..., f^(p)) along a ray is a Markov state (Matern p + 1/2);
                   fs_markov.h samples it exactly
  corr_lag         <name>_corr_lag gives the lag of a correlation in closed form (else the
                   step rule bisects)
  length_field     a length-scale field l(x) keeps it positive definite (Paciorek-
                   Schervish): <name>_ps_exponent
  ws_posterior     weight space conditions it pathwise (ws_posterior.h)
Each device file holds two parts: the covariance functions (GP_KERNEL_PART_COVARIANCE,
joined into gp_kernel.h) and the spectral ones (GP_KERNEL_PART_SPECTRAL, joined into
ws_features.h, where the weight-space vector types exist).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from ..gp import kernels as K
from ..io.grids import load_field_grid, problem_of
from ..schema import Field, File, Nullable, Number, Record, Tagged, Vector
from .table import KERNELS_CL, Kind, KindTable, device_text

VEC3 = Vector()
POSITIVE3 = Vector(broadcast=True, item=Number(gt=0))
TWO_PI = 6.283185307179586

# Spatially varying multipliers (function space only): sigma(x) = sigma m(x) on every
# kernel ("sigma_field"), l(x) = l m(x) on kernels with the length_field trait (the
# Paciorek-Schervish form, gpiscl/host/gp/kernels.py). A field is 1 where it is absent.
#   linear  m = value + gradient . (x - origin); must stay positive over the proxy
#   radial  m = inner + (outer - inner) (1 + tanh((|x - center|^2 - radius^2)
#               / (2 radius width))) / 2: inner inside the sphere, outer beyond, blended
#               over about `width`
#   grid    trilinear in an .npz laid out like a mean grid (values (nx, ny, nz) > 0,
#           origin, voxel_size), the border value held outside the sample box
FIELDS = Tagged("field", {
    "linear": Record({"value": Field(Number(gt=0), 1.0), "gradient": Field(VEC3, [0, 0, 0]),
                      "origin": Field(VEC3, [0, 0, 0])}),
    "radial": Record({"center": Field(VEC3, [0, 0, 0]), "radius": Field(Number(gt=0)),
                      "width": Field(Number(gt=0)), "inner": Field(Number(gt=0)),
                      "outer": Field(Number(gt=0))}),
    "grid": Record({"file": Field(File((".npz",), problem_of(load_field_grid)))}),
})
FIELD_KEYS = ("sigma_field", "length_scale_field")
TRAITS = ("radial", "spectral", "periodic_orders", "markov_order", "corr_lag", "length_field",
          "ws_posterior")
# Random Fourier features per realization when a scene gives none.
DEFAULT_FEATURES = 256


@dataclass(frozen=True)
class KernelHost:
    """cls: the host model (gp/kernels.py); params: the GpKernel fields it fills besides
    kind, sigma2 and aniso (layout/gp_records.py pack_kernel); length(k): the length on
    which a realization of the resolved kernel k varies (root tolerances and steps scale
    with it); features: random Fourier features per realization by default; window:
    samples a function-space flight conditions on besides its memory (None: the
    sampler's default)."""
    cls: type
    params: tuple
    length: Callable[[dict], float]
    features: int = DEFAULT_FEATURES
    window: int | None = None


def kernel_schema(params: dict, length_field: bool) -> Record:
    """A kernel's scene record: sigma, its own parameters, aniso and the fields."""
    fields = {"sigma": Field(Number(gt=0), 1.0), **params, "aniso": Field(POSITIVE3, 1.0),
              "sigma_field": Field(Nullable(FIELDS), None)}
    if length_field:
        fields["length_scale_field"] = Field(Nullable(FIELDS), None)
    return Record(fields)


def kernel(name: str, params: dict, host: KernelHost, device_file: str | None = None,
           **traits) -> Kind:
    """The Kind of a kernel whose device maths is in lib/gp_kernels/<name>.h (or, for a
    test's temporary kernel, the absolute `device_file`)."""
    return Kind(name, kernel_schema(params, traits["length_field"]),
                device_file or f"lib/gp_kernels/{name}.h", traits, host)


def required_functions(kind: Kind) -> tuple:
    """The device functions a kernel's file must define, by its traits."""
    t = kind.traits
    names = ["radial_arg", "radial_of"] if t["radial"] else ["log_terms"]
    names += ["ws_scale", "ws_lambda2"] if t["spectral"] else []
    names += ["corr_lag"] if t["corr_lag"] else []
    names += ["ps_exponent"] if t["length_field"] else []
    return tuple(f"{kind.name}_{n}" for n in names)


def _isotropic_length(k: dict) -> float:
    return k["length_scale"] / max(k["aniso"]) ** 0.5


_L = {"length_scale": Field(Number(gt=0), 1.0)}
_W = {"w": Field(Number(gt=0), TWO_PI)}
_SMOOTH = dict(radial=True, spectral=True, periodic_orders=False, markov_order=0)

# The rational quadratic's and Matern's spectra are heavy-tailed scale mixtures: they need
# more features for the same covariance error. The rational quadratic's window: its
# correlation falls like 1/t^2, so samples many length scales back still inform the next
# (docs/design/gp_kernels.md).
GP_KERNELS = KindTable("GP kernel", "GP_KERNEL", [
    kernel("squared_exponential", _L,
           KernelHost(K.SquaredExponential, ("length_scale",), _isotropic_length),
           **_SMOOTH, corr_lag=True, length_field=True, ws_posterior=True),
    kernel("rational_quadratic", {**_L, "alpha": Field(Number(gt=0), 1.0)},
           KernelHost(K.RationalQuadratic, ("length_scale", "alpha"), _isotropic_length,
                      features=1024, window=32),
           **_SMOOTH, corr_lag=True, length_field=True, ws_posterior=True),
    kernel("periodic", {**_L, **_W},
           KernelHost(K.Periodic, ("length_scale", "w"),
                      lambda k: k["length_scale"] / k["w"]),
           radial=False, spectral=True, periodic_orders=True, markov_order=0,
           corr_lag=False, length_field=False, ws_posterior=False),
    kernel("locally_periodic", {**_L, **_W, "se_length_scale": Field(Number(gt=0), 1.0)},
           KernelHost(K.LocallyPeriodic, ("length_scale", "w", "se_length_scale"),
                      lambda k: min(k["length_scale"] / k["w"], k["se_length_scale"])),
           radial=False, spectral=True, periodic_orders=True, markov_order=0,
           corr_lag=False, length_field=False, ws_posterior=False),
    # compactly supported; no spectral density (weight space cannot sample it)
    kernel("thin_plate", {"radius": Field(Number(gt=0), 1.0)},
           KernelHost(K.ThinPlate, ("radius",), lambda k: k["radius"]),
           radial=True, spectral=False, periodic_orders=False, markov_order=0,
           corr_lag=False, length_field=False, ws_posterior=False),
    kernel("matern32", _L, KernelHost(K.Matern32, ("length_scale",), _isotropic_length,
                                      features=1024),
           **{**_SMOOTH, "markov_order": 1}, corr_lag=False, length_field=False,
           ws_posterior=False),
    kernel("matern52", _L, KernelHost(K.Matern52, ("length_scale",), _isotropic_length,
                                      features=1024),
           **{**_SMOOTH, "markov_order": 2}, corr_lag=False, length_field=False,
           ws_posterior=False),
], traits=TRAITS, family="kernel")

# (device function, return type, parameters, arguments, default, trait that selects the
# kinds; None: every kind): the generated dispatch of each part of the device files.
_PARTS = {
    "covariance": (
        ("radial_arg", "GP_REAL", "GpKernel p, GP_REAL s", "p, s", "0", "radial"),
        ("radial_of", "void", "GpKernel p, GP_REAL s, GP_REAL e, GP_REAL* k, GP_REAL* dk2, "
                              "GP_REAL* ddk4", "p, s, e, k, dk2, ddk4", None, "radial"),
        ("log_terms", "GP_REAL", "GpKernel p, GP_REAL3 r, GP_REAL3* dh, GP_REAL3* hh",
         "p, r, dh, hh", "(GP_REAL)NAN", "!radial"),
        ("corr_lag", "double", "GpKernel p, double dad, double c", "p, dad, c", "NAN",
         "corr_lag"),
        ("ps_exponent", "GP_REAL", "GpKernel p, GP_REAL s, GP_REAL S, GP_REAL* beta",
         "p, s, S, beta", "(GP_REAL)NAN", "length_field"),
    ),
    "spectral": (
        ("ws_scale", "wsf", "GpKernel k, uint2 key, int object, wsi idx", "k, key, object, idx",
         "(wsf)NAN", "spectral"),
        ("ws_lambda2", "float", "GpKernel k, float s", "k, s", "NAN", "spectral"),
    ),
}


def _kinds_with(table: KindTable, trait: str) -> tuple:
    if trait.startswith("!"):
        return table.with_trait(trait[1:], False)
    return table.with_trait(trait)


def device_source(part: str, table: KindTable = GP_KERNELS) -> str:
    """One part of every kernel's device file, then the dispatch over them: what replaces
    the `@kinds gp_kernels <part>` line of gp_kernel.h / ws_features.h."""
    flag = f"GP_KERNEL_PART_{part.upper()}"
    out = [f"#define {flag} 1"]
    for kind in table:
        out.append(f'#line 1 "{kind.device_file}"')
        out.append(device_text(KERNELS_CL / kind.device_file))
    out.append(f"#undef {flag}")
    for fn, returns, params, args, default, trait in _PARTS[part]:
        out.append(table.c_dispatch(fn, returns, params, args, default,
                                    kinds=_kinds_with(table, trait)))
    return "\n".join(out) + "\n"
