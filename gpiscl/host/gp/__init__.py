"""The Gaussian-process model: kernels, means, spectral samplers and posteriors (the numpy
twins of both device samplers, test oracles, live in gpiscl/testing/reference/). Imports
numpy only: every other package builds on it.

numpy implementations here are the references for the device kernels (lib/gp_kernels/)
and gp_mean.h and for the scene compiler (their device records: layout/gp_records.py);
see kernels.py, means.py and spectral.py for the pinned conventions. Which kernels exist
is declared in kinds/gp_kernels.py.
"""
from .kernels import (Jet, Kernel, LocallyPeriodic, Matern32, Matern52, Periodic,
                      RationalQuadratic, SquaredExponential, ThinPlate, covariance_matrix)
from .means import (MEANS, Box, Capsule, Constant, Difference, Intersection, Mean, Plane,
                    RoundedBox, SmoothDifference, SmoothIntersection, SmoothUnion, Sphere,
                    Torus, Transform, Union, smooth_max, smooth_min)
from .spectral import RandomFeatures, periodic_order_weights, sample_frequencies

__all__ = [
    "Jet", "Kernel", "LocallyPeriodic", "Matern32", "Matern52", "Periodic",
    "RationalQuadratic",
    "SquaredExponential", "ThinPlate", "covariance_matrix",
    "MEANS", "Box", "Capsule", "Constant", "Difference", "Intersection", "Mean", "Plane",
    "RoundedBox", "SmoothDifference", "SmoothIntersection", "SmoothUnion", "Sphere", "Torus",
    "Transform", "Union", "smooth_max", "smooth_min",
    "RandomFeatures", "periodic_order_weights", "sample_frequencies",
]
