"""Statistical comparisons with thresholds derived from the number of comparisons."""
import math
from statistics import NormalDist

import numpy as np

# Family-wise false-alarm rate of every statistical assertion in the suite.
ALPHA = 1e-3


def z_threshold(num_tests: int, alpha: float = ALPHA) -> float:
    """Two-sided Bonferroni threshold for num_tests independent z-scores."""
    return NormalDist().inv_cdf(1.0 - alpha / (2.0 * num_tests))


def image_mean_se(*stderrs) -> float:
    """Standard error of the difference of whole-image means (over pixels and channels)
    of independent renders, from their per-pixel standard errors. A pixel's channels come
    from the same paths, so they are not independent: taken as fully correlated (exact for
    grey scenes, whose channels are equal; an upper bound otherwise). Treating them as
    independent made the error sqrt(3) too small for grey scenes."""
    var = 0.0
    for se in stderrs:
        se = np.asarray(se, np.float64)
        per_pixel = se.sum(axis=-1) if se.ndim == 3 else se
        var += float((per_pixel**2).sum()) / se.size**2
    return float(np.sqrt(var))


def block_means(image, stderr, block: int):
    """Means of block x block tiles and their standard errors (pixels independent)."""
    h, w = image.shape[:2]
    img = image[: h - h % block, : w - w % block]
    se = stderr[: h - h % block, : w - w % block]
    shape = (img.shape[0] // block, block, img.shape[1] // block, block) + img.shape[2:]
    mean = img.reshape(shape).mean(axis=(1, 3))
    var = (se.reshape(shape) ** 2).sum(axis=(1, 3)) / block**4
    return mean, np.sqrt(var)


def assert_agree(a, se_a, b, se_b=None, block=1, what="images"):
    """z-test per element (or per block) that a and b have the same expectation."""
    if block > 1:
        a, se_a = block_means(a, se_a, block)
        if se_b is not None:
            b, se_b = block_means(b, se_b, block)
        else:
            b, _ = block_means(b, np.zeros_like(b), block)
    se2 = se_a**2 + (0.0 if se_b is None else se_b**2)
    diff = np.asarray(a - b, dtype=np.float64)
    # elements with zero variance are deterministic: they must match to float precision
    exact = se2 == 0
    assert np.all(np.abs(diff[exact]) <= 1e-5 * (1 + np.abs(b[exact] if np.ndim(b) else b))), (
        f"{what}: deterministic elements differ")
    z = np.abs(diff[~exact]) / np.sqrt(se2[~exact])
    if z.size:
        t = z_threshold(z.size)
        assert z.max() < t, f"{what}: max |z| = {z.max():.2f} over {z.size} tests (threshold {t:.2f})"
    return z


def ks_two_sample(a, b, num_tests):
    """Two-sample Kolmogorov-Smirnov: statistic and its Bonferroni critical value
    (asymptotic, c(alpha) = sqrt(-ln(alpha / 2) / 2))."""
    a, b = np.sort(a), np.sort(b)
    grid = np.concatenate([a, b])
    D = np.max(np.abs(np.searchsorted(a, grid, "right") / len(a)
                      - np.searchsorted(b, grid, "right") / len(b)))
    alpha = ALPHA / num_tests
    return D, math.sqrt(-math.log(alpha / 2) / 2) * math.sqrt((len(a) + len(b)) / (len(a) * len(b)))


def chi2_threshold(df, num_tests=1):
    """Upper chi-square quantile by Wilson-Hilferty (accurate to <1% for df >= 5)."""
    z = NormalDist().inv_cdf(1.0 - ALPHA / num_tests)
    return df * (1.0 - 2.0 / (9 * df) + z * math.sqrt(2.0 / (9 * df))) ** 3
