"""fs_sampling.h on the device: the truncated normal against its analytic law and the step
rule against the numpy reference (the free-flight harness: gpiscl/testing/flights.py)."""
import math

import numpy as np
import pyopencl as cl
import pytest

from gpiscl.host.gp import RationalQuadratic
from gpiscl.host.gp import SquaredExponential
from gpiscl.host.gp import ThinPlate
from gpiscl.host.gp import Periodic
from gpiscl.host.layout import gp_records
from gpiscl.testing.reference import function_space as FS
from gpiscl.testing.stats import chi2_threshold, z_threshold
from gpiscl.testing.wrappers import buffer


SE = SquaredExponential(sigma=1.0, length_scale=1.0)
RQ = RationalQuadratic(sigma=1.0, length_scale=1.0, alpha=1.0)


@pytest.mark.parametrize("a", [-1.5, 0.0, 3.0, 12.0, 40.0])
def test_truncated_normal_matches_analytic_law(device, flight_prg, a):
    """a = -mu/s standard deviations of truncation; 40 exercises the rejection tail."""
    n, s = 200_000, 0.7
    mu = -a * s
    buf = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 8 * n)
    flight_prg["tn_draw"](device.queue, (n,), None, np.float64(mu), np.float64(s), np.uint32(3), buf)
    x = np.empty(n)
    cl.enqueue_copy(device.queue, x, buf)
    assert np.all(x >= 0.0)
    mean, var = FS.truncnorm_moments(mu, s)
    z = z_threshold(2 * 5)
    se_mean = math.sqrt(var / n)
    se_var = math.sqrt(np.mean((x - mean) ** 4) - var**2) / math.sqrt(n)
    assert abs(x.mean() - mean) < z * se_mean
    assert abs(x.var() - var) < z * se_var
    # probability integral transform: uniform in 20 equiprobable bins
    pit = 1.0 - FS.truncnorm_survival(x, mu, s)
    counts = np.bincount(np.minimum((pit * 20).astype(int), 19), minlength=20)
    chi2 = np.sum((counts - n / 20) ** 2 / (n / 20))
    assert chi2 < chi2_threshold(19, 5)


@pytest.mark.parametrize("kernel", [SE, RQ, RationalQuadratic(0.5, 2.0, 0.375, (1, 0.5, 2)),
                                    ThinPlate(1.0, 3.0), Periodic(1.0, 2.0, 0.25)],
                         ids=["se", "rq", "rq-aniso", "thin_plate", "periodic"])
def test_step_rule(device, flight_prg, kernel):
    d = np.array([0.6, 0.0, 0.8]) * 1.5
    out = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 8)
    for c in (0.5, 0.9, 0.99):
        flight_prg["step_rule"](device.queue, (1,), None, buffer(device, gp_records.pack_kernel(kernel)),
                         buffer(device, np.r_[np.zeros(3), d]), np.float64(c), out)
        dt = np.empty(1)
        cl.enqueue_copy(device.queue, dt, out)
        assert abs(FS.correlation(kernel, d, dt[0]) - c) < 1e-9
        assert abs(dt[0] - FS.step_size(kernel, d, c)) < 1e-9 * dt[0]
    if kernel is SE:   # the closed form of the brief: l sqrt(-2 ln c) / sqrt(d'Ad)
        assert abs(dt[0] - math.sqrt(-2 * math.log(0.99)) / 1.5) < 1e-12
