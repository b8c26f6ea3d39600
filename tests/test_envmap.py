import math
from statistics import NormalDist

import numpy as np
import pytest

from gpiscl.host.compile.envmap import (build_envmap_tables, direction_to_pixel, envmap_lookup,
                                envmap_pdf, sample_envmap)
from gpiscl.testing.stats import ALPHA

H, W = 8, 16


def _test_map():
    rng = np.random.default_rng(7)
    rgb = rng.uniform(0.05, 1.0, (H, W, 3)).astype(np.float32)
    rgb[2] = 0.0                       # a black row: never sampled, still a valid CDF
    rgb[5, 3:6] = 0.0                  # black pixels inside a lit row
    rgb[6, 11] = [40.0, 30.0, 10.0]    # a sun-like hot spot
    return rgb


def _pixel_solid_angles(h, w):
    edges = np.cos(np.pi * np.arange(h + 1) / h)
    return np.repeat(((edges[:-1] - edges[1:]) * 2 * np.pi / w)[:, None], w, axis=1)


def test_tables_are_valid_cdfs():
    rgb = _test_map()
    t = build_envmap_tables(rgb)
    assert t.marginal_cdf.shape == (H + 1,) and t.conditional_cdf.shape == (H, W + 1)
    assert t.pixel_pdf.shape == (H, W)
    for a in (t.marginal_cdf, t.conditional_cdf, t.pixel_pdf):
        assert a.dtype == np.float32
    for cdf in (t.marginal_cdf[None], t.conditional_cdf):
        assert np.all(cdf[:, 0] == 0) and np.all(cdf[:, -1] == 1)
        assert np.all(np.diff(cdf, axis=1) >= 0)
    # the black row keeps a uniform conditional so a search in it stays meaningful
    np.testing.assert_allclose(t.conditional_cdf[2], np.arange(W + 1) / W, atol=1e-7)
    lum = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    weight = lum * np.sin(np.pi * (np.arange(H) + 0.5) / H)[:, None]
    # float32 CDF entries carry ~6e-8 absolute error each; differences of two of them
    np.testing.assert_allclose(t.pixel_pdf, weight / weight.sum(), rtol=1e-4, atol=3e-7)
    assert np.all(t.pixel_pdf[2] == 0) and np.all(t.pixel_pdf[5, 3:6] == 0)


def test_black_map_falls_back_to_uniform_sphere():
    t = build_envmap_tables(np.zeros((4, 8, 3), np.float32))
    sin_c = np.sin(np.pi * (np.arange(4) + 0.5) / 4)
    np.testing.assert_allclose(t.pixel_pdf, np.repeat(sin_c[:, None], 8, 1) / (8 * sin_c.sum()),
                               rtol=1e-5)
    d, pdf = sample_envmap(t, np.array([0.1, 0.6, 0.99]), np.array([0.3, 0.5, 0.0]))
    assert np.all(pdf > 0) and np.allclose(np.linalg.norm(d, axis=1), 1)


def test_direction_convention():
    # +y, -y, then just above the horizon at phi = 0, pi/2, just below 2 pi, just below pi
    dirs = np.array([[0, 1, 0], [0, -1, 0], [1, 1e-9, 0], [0, 1e-9, 1], [1, 1e-9, -1e-9],
                     [-1, 1e-9, 1e-9]])
    row, col, _ = direction_to_pixel(dirs, H, W)
    np.testing.assert_array_equal(row, [0, H - 1] + [H // 2 - 1] * 4)
    np.testing.assert_array_equal(col[2:], [0, W // 4, W - 1, W // 2 - 1])
    rgb = _test_map()
    yy, xx = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    theta, phi = np.pi * (yy + 0.5) / H, 2 * np.pi * (xx + 0.5) / W
    centres = np.stack([np.sin(theta) * np.cos(phi), np.cos(theta),
                        np.sin(theta) * np.sin(phi)], -1).reshape(-1, 3)
    np.testing.assert_array_equal(envmap_lookup(rgb, centres), rgb.reshape(-1, 3))


def test_pdf_integrates_to_one():
    # pdf * sin(theta) is constant on each pixel, so a midpoint rule on a grid aligned with
    # pixel edges is exact; only float64 rounding (<1e-12) is left, hence the tolerance.
    t = build_envmap_tables(_test_map())
    k = 5
    th = (np.arange(H * k) + 0.5) * np.pi / (H * k)
    ph = (np.arange(W * k) + 0.5) * 2 * np.pi / (W * k)
    th, ph = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], -1)
    pdf = envmap_pdf(t, d.reshape(-1, 3)).reshape(th.shape)
    integral = (pdf * np.sin(th)).sum() * (np.pi / (H * k)) * (2 * np.pi / (W * k))
    assert integral == pytest.approx(1.0, abs=1e-9)


def test_sample_histogram_matches_pixel_pdf():
    t = build_envmap_tables(_test_map())
    rng = np.random.default_rng(11)
    n = 400_000
    d, _ = sample_envmap(t, rng.random(n), rng.random(n))
    row, col, _ = direction_to_pixel(d, H, W)
    counts = np.bincount(row * W + col, minlength=H * W)
    p = t.pixel_pdf.reshape(-1).astype(np.float64)
    assert counts[p == 0].sum() == 0
    expected = n * p[p > 0] / p.sum()
    assert expected.min() >= 5  # the chi-square approximation holds
    chi2 = ((counts[p > 0] - expected) ** 2 / expected).sum()
    # Wilson-Hilferty upper quantile of chi-square(k) at ALPHA (accurate to <1% for k > 30)
    k = expected.size - 1
    z = NormalDist().inv_cdf(1 - ALPHA)
    threshold = k * (1 - 2 / (9 * k) + z * math.sqrt(2 / (9 * k))) ** 3
    assert chi2 < threshold, f"chi2 = {chi2:.1f} over {k} dof, threshold {threshold:.1f}"


def test_pdf_of_sample_matches_sampled_pdf():
    t = build_envmap_tables(_test_map())
    rng = np.random.default_rng(3)
    d, pdf = sample_envmap(t, rng.random(20_000), rng.random(20_000))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-12)
    assert np.all(pdf > 0)
    np.testing.assert_allclose(envmap_pdf(t, d), pdf, rtol=1e-9)


def test_importance_sampled_integral_matches_pixel_sum():
    rgb = _test_map()
    t = build_envmap_tables(rgb)
    exact = (rgb.astype(np.float64) * _pixel_solid_angles(H, W)[..., None]).sum(axis=(0, 1))
    rng = np.random.default_rng(5)
    n = 100_000
    d, pdf = sample_envmap(t, rng.random(n), rng.random(n))
    f = envmap_lookup(rgb, d) / pdf[:, None]
    mean, se = f.mean(axis=0), f.std(axis=0, ddof=1) / math.sqrt(n)
    assert np.all(np.abs(mean - exact) < 4 * se), (mean, exact, se)


def test_hdr_and_exr_maps_render_alike(tmp_path, device):
    """An environment_map file may be Radiance .hdr (the authors' scenes) or OpenEXR: the
    same radiance (values RGBE holds exactly) renders the same image from either."""
    from gpiscl import render_result
    from gpiscl.host.io.images import write_exr
    from gpiscl.host.io.radiance_hdr import write_hdr
    rng = np.random.default_rng(5)
    rgb = (rng.integers(128, 256, (8, 16, 3)) * 2.0 ** rng.integers(-9, -5, (8, 16, 1)))
    rgb[..., 1:] = np.minimum(rgb[..., 1:], rgb[..., :1])  # channel 0 holds the exponent
    rgb = rgb.astype(np.float32)
    write_hdr(tmp_path / "sky.hdr", rgb)
    write_exr(tmp_path / "sky.exr", rgb)
    images = []
    for name in ("sky.hdr", "sky.exr"):
        scene = {"camera": {"position": [0, 0, 0], "look_at": [0, 0.3, 1], "fov": 90,
                            "resolution": [8, 8]},
                 "render": {"spp": 2, "seed": 3},
                 "shapes": [{"type": "sphere", "center": [0, 0, 3], "radius": 1,
                             "bsdf": {"type": "diffuse", "albedo": 0.5}}],
                 "lights": [{"type": "environment_map", "file": str(tmp_path / name),
                             "rotation": 30}]}
        images.append(render_result(scene, device=device).image.mean)
    assert images[0].max() > 0
    np.testing.assert_array_equal(images[0], images[1])


def _whole_map_tables(rgb):
    """The tables as built before they were streamed by bands of rows: the whole map in
    double at once (~80 bytes a texel at the peak). The streamed tables must equal these
    bit for bit, or the images of the shipped sky would change."""
    rgb = np.asarray(rgb, dtype=np.float64)
    h = rgb.shape[0]
    lum = np.maximum(np.nan_to_num(rgb[..., :3] @ np.array([0.2126, 0.7152, 0.0722]),
                                   nan=0.0, posinf=0.0, neginf=0.0), 0.0)
    if not lum.any():
        lum = np.ones_like(lum)
    weight = lum * np.sin(np.pi * (np.arange(h) + 0.5) / h)[:, None]
    row_sum = weight.sum(axis=1)

    def cdf(x):
        c = np.cumsum(x, axis=-1)
        out = np.zeros(x.shape[:-1] + (x.shape[-1] + 1,), np.float32)
        out[..., 1:] = c / c[..., -1:]
        out[..., -1] = 1.0
        return out
    return cdf(row_sum), cdf(np.where(row_sum[:, None] > 0, weight, 1.0))


@pytest.mark.parametrize("band_texels", [1, 50, 1 << 18])
def test_tables_built_by_bands_of_rows_equal_the_whole_map_ones(monkeypatch, band_texels):
    import gpiscl.host.compile.envmap as envmap
    from gpiscl.host.io.radiance_hdr import read_environment_rgb
    from pathlib import Path
    monkeypatch.setattr(envmap, "BAND_TEXELS", band_texels)
    rng = np.random.default_rng(3)
    wild = (rng.random((37, 61, 3)) ** 4 * 10.0 ** rng.uniform(-8, 8, (37, 61, 1)))
    wild[2], wild[20, :30] = 0.0, 0.0
    wild[3, 4, 1], wild[5, 6, 0], wild[7, 8, 2] = np.nan, np.inf, -3.0
    sky = read_environment_rgb(Path(__file__).parents[1] / "scenes/assets/sky.exr")
    for rgb in (sky, _test_map(), wild.astype(np.float32), np.zeros((5, 9, 3), np.float32),
                np.ones((1, 1, 3), np.float32)):
        marginal, conditional = _whole_map_tables(rgb)
        t = envmap.build_envmap_tables(rgb)
        assert t.marginal_cdf.tobytes() == marginal.tobytes()
        assert t.conditional_cdf.tobytes() == conditional.tobytes()
        # texels as the device holds them (float4) give the same tables
        rgba = np.concatenate([rgb, np.zeros(rgb.shape[:2] + (1,), np.float32)], -1)
        aligned = envmap.build_envmap_tables(rgba, aligned=True)
        assert aligned.conditional_cdf.tobytes() == conditional.tobytes()
        assert aligned.conditional_cdf.ctypes.data % 4096 == 0


def test_compiled_map_is_float4_texels_the_device_uses_in_place(tmp_path):
    from gpiscl.host.compile.envmap import compile_envmap
    from gpiscl.host.io.images import write_exr
    rgb = _test_map()
    write_exr(tmp_path / "sky.exr", rgb)
    env = compile_envmap(tmp_path / "sky.exr")
    assert env.size == (W, H) and env.texels.shape == (H * W, 4)
    np.testing.assert_array_equal(env.texels[:, :3], rgb.reshape(-1, 3))
    assert not env.texels[:, 3].any()
    assert env.texels.ctypes.data % 4096 == 0 and env.conditional.ctypes.data % 4096 == 0
    t = build_envmap_tables(rgb)
    assert env.conditional.tobytes() == t.conditional_cdf.tobytes()
    assert env.marginal.tobytes() == t.marginal_cdf.tobytes()


def test_an_empty_map_never_reaches_the_device():
    for shape in ((0, 0, 3), (0, 4, 3), (4, 0, 3)):
        with pytest.raises(ValueError, match="at least one pixel"):
            build_envmap_tables(np.zeros(shape, np.float32))
