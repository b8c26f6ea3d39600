"""Pictures of random geometry: the numpy data behind them (always), the PNG files (when
matplotlib is installed) and the one-line error when it is not (always, simulated)."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from gpiscl.cli import main
from gpiscl.host.gp import RationalQuadratic, Sphere, SquaredExponential
from gpiscl.host.figures.plotting import PLOTS_MISSING
from gpiscl.host.figures.samples import (empirical_covariance, exact_samples,
                                        fig2_data, implied_kernel, kernel_covariance,
                                        line_points, load_observations, occupancy,
                                        plane_points, posterior_maps, resolve_target,
                                        weight_space_samples, write_figures)
from gpiscl.host.errors import SceneError

from gpiscl.testing.stats import z_threshold

KERNELS = [SquaredExponential(sigma=1.5, length_scale=0.5),
           RationalQuadratic(sigma=0.75, length_scale=0.4, alpha=0.5)]
LAGS = np.array([0.0, 0.1, 0.25, 0.5, 1.0, 2.0])

SCENE = {"lights": [{"type": "environment"}],
         "shapes": [{"type": "gpis", "proxy": {"type": "box", "min": [-1, -1, -1],
                                               "max": [1, 1, 1]},
                     "mean": {"type": "sphere", "radius": 0.5},
                     "kernel": {"type": "squared_exponential", "sigma": 0.25,
                                "length_scale": 0.3}}]}


def have_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
        return True
    except ImportError:
        return False


def test01_targets_from_kernel_names_json_and_scenes(tmp_path):
    t = resolve_target("rational_quadratic")
    assert t.kernel.kind == "rational_quadratic" and t.mean is None
    t = resolve_target('{"type": "periodic", "w": 2.0}')
    assert t.kernel.w == 2.0 and t.kernel_spec["length_scale"] == 1.0
    path = tmp_path / "s.json"
    path.write_text(json.dumps(SCENE))
    t = resolve_target(str(path))
    assert t.kernel.sigma == 0.25 and t.mean is not None and t.half_extent == 1.0
    for bad, key in [("cubic", "KERNEL_OR_SCENE"), ('{"type": "rq"}', "kernel.type"),
                     ('{"type": "periodic", "w": -1}', "kernel.w")]:
        with pytest.raises(SceneError, match=key.replace(".", r"\.")):
            resolve_target(bad)
    with pytest.raises(SceneError, match="--object"):
        resolve_target(str(path), obj=1)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.kind)
@pytest.mark.parametrize("m", [10, 1000])
def test02_weight_space_curves_have_the_kernel_covariance(kernel, m):
    """Features redrawn per realization: cov over realizations is k for any M."""
    x = line_points(LAGS)
    samples = weight_space_samples(kernel, m, x, 8000, np.random.default_rng(m))
    cov, se = empirical_covariance(samples)
    z = (cov - kernel_covariance(kernel, x)) / se
    assert np.abs(z).max() < z_threshold(2 * 2 * len(LAGS)), np.round(z, 2)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.kind)
def test03_exact_samples_have_the_kernel_covariance(kernel):
    x = line_points(np.concatenate([LAGS, np.linspace(0.05, 3.0, 60)]))  # dense: singular K
    samples = exact_samples(kernel, x, 20000, np.random.default_rng(3))
    cov, se = empirical_covariance(samples)
    z = (cov - kernel_covariance(kernel, x)) / se
    assert np.abs(z).max() < z_threshold(2 * len(x)), np.round(z, 2)


def test04_one_basis_approximates_the_kernel_better_with_more_features():
    """Fig. 2's point: a single draw of M features implies k_M, which converges to k
    like 1/sqrt(M); the rough RQ kernel is further off than SE at the same M."""
    r = np.linspace(0.0, 3.0, 61)
    rng = np.random.default_rng(4)

    def error(kernel, m):
        k = kernel.value(line_points(r))
        return np.mean([np.abs(implied_kernel(kernel, m, r, rng) - k).mean()
                        for _ in range(40)]) / kernel.variance

    for kernel in KERNELS:
        e10, e1000 = error(kernel, 10), error(kernel, 1000)
        assert 5.0 < e10 / e1000 < 20.0, (kernel.kind, e10, e1000)   # sqrt(100) = 10


def test05_prior_occupancy_is_phi_of_minus_mean_over_sigma():
    kernel, mean = SquaredExponential(sigma=0.25, length_scale=0.3), Sphere(radius=0.5)
    x = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.75, 0.0], [3.0, 0.0, 0.0]])
    phi = lambda v: 0.5 * math.erfc(-v / math.sqrt(2.0))
    expect = [phi(0.5 / 0.25), 0.5, phi(-0.25 / 0.25), phi(-2.5 / 0.25)]
    np.testing.assert_allclose(occupancy(kernel, mean, x), expect, rtol=1e-12, atol=1e-300)


def test06_fig2_data_has_every_panel():
    d = fig2_data(KERNELS[0], {"type": "squared_exponential", "sigma": 1.5,
                               "length_scale": 0.5, "aniso": [1, 1, 1]},
                  features=(10, 100), curves=3, draws=2, points=50, cov_curves=20)
    assert d["exact"].shape == (3, 50) and d["kernel"].shape == (50,)
    assert set(d["weight_space"]) == {10, 100} and d["implied"][10].shape == (2, 50)
    assert set(d["empirical"]) == {10, 100, "exact"}
    assert d["kernel"][0] == pytest.approx(1.5**2)


def test07_without_matplotlib_the_command_says_how_to_install(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "matplotlib", None)   # makes the import fail
    assert main(["sample", "squared_exponential", "-o", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install -e '.[plots]'" in err[0]
    assert PLOTS_MISSING in err[0]


def test08_the_renderer_does_not_import_matplotlib():
    code = ("import sys, gpiscl, gpiscl.__main__, gpiscl.host.uq.realizations, gpiscl.host.figures.samples;"
            "sys.exit('matplotlib' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test09_figures_are_written_when_matplotlib_is_installed(tmp_path, capsys):
    """With matplotlib: every PNG exists. Without: the data test above stands in, and
    this checks the refusal through the Python entry point instead."""
    path = tmp_path / "s.json"
    path.write_text(json.dumps(SCENE))
    target = resolve_target(str(path))
    if not have_matplotlib():
        with pytest.raises(SceneError, match="pip install"):
            write_figures(target, tmp_path / "figs")
        return
    out = tmp_path / "figs"
    pts = tmp_path / "pts.xyz"
    np.savetxt(pts, sphere_points(40, 0.4))
    assert main(["sample", str(path), "-o", str(out), "--features", "10,100",
                 "--realizations", "2", "--resolution", "32", "--observations", str(pts)]) == 0
    for name in ("lines.png", "slices.png", "features.png", "occupancy.png", "posterior.png",
                 "posterior_sd.png", "posterior_occupancy.png", "posterior_slices.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert main(["sample", "rational_quadratic", "-o", str(tmp_path / "k"), "--features",
                 "10", "--realizations", "1", "--resolution", "16"]) == 0
    assert not (tmp_path / "k" / "occupancy.png").exists()   # no mean: no occupancy
    assert main(["sample", "thin_plate", "-o", str(tmp_path / "t")]) == 2


def sphere_points(n, radius, normals=False):
    d = np.random.default_rng(n).standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.concatenate([radius * d, d], 1) if normals else radius * d


def test10_posterior_maps_honour_the_observed_surface(tmp_path):
    path = tmp_path / "s.json"
    path.write_text(json.dumps(SCENE))
    target = resolve_target(str(path))
    f = tmp_path / "pts.txt"
    np.savetxt(f, sphere_points(60, 0.4, normals=True))
    obs = load_observations(f, noise=1e-6)
    assert len(obs) == 60 * 4                       # a value and three derivatives each
    # probes: the observed points themselves, and the centre (inside the observed sphere)
    probes = np.concatenate([obs.x[:60], [[0.0, 0.0, 0.0]]])[:, None, :]
    maps = posterior_maps(target, obs, probes, 3, 256, np.random.default_rng(0))
    sd0 = math.sqrt(target.kernel.variance)
    assert np.abs(maps["mean"][:60]).max() < 0.02 * sd0
    assert maps["sd"][:60].max() < 0.05 * sd0
    np.testing.assert_allclose(maps["occupancy"][:60], 0.5, atol=0.3)
    assert maps["occupancy"][60, 0] > 0.99
    for sample in maps["samples"]:                  # pathwise draws pass through the data
        assert np.abs(sample[:60]).max() < 0.05 * sd0
    grid = plane_points([0, 0, 0], 1.0, 8)
    maps = posterior_maps(target, obs, grid, 1, 16, np.random.default_rng(1))
    assert maps["mean"].shape == maps["samples"][0].shape == (8, 8)
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2\n3 4\n")
    with pytest.raises(SceneError, match=r"rows of 3 \(x y z\) or 6"):
        load_observations(bad)


def test_spatially_varying_kernels_are_refused_with_the_key(tmp_path, capsys):
    import json
    from pathlib import Path
    from gpiscl.cli import main
    scene = json.loads((Path(__file__).resolve().parent.parent / "scenes" /
                        "fs_sphere_se.json").read_text())
    scene["shapes"][1]["kernel"]["sigma_field"] = {
        "type": "radial", "center": [0, 0, 0], "radius": 1.0, "width": 0.1,
        "inner": 0.5, "outer": 1.5}
    path = tmp_path / "s.json"
    path.write_text(json.dumps(scene))
    assert main(["sample", str(path), "-o", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "kernel.sigma_field" in err


def test_a_scene_whose_kernel_varies_in_space_is_refused_at_its_own_key(tmp_path):
    """Issue 30 item 9: `sample bunny_grid.json` named `<command line>: kernel...`, not
    the scene's file and key."""
    from pathlib import Path
    scene = Path(__file__).resolve().parents[1] / "scenes" / "bunny_grid.json"
    r = subprocess.run([sys.executable, "-m", "gpiscl", "sample", str(scene), "-o",
                        str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith(f"error: {scene}: shapes[1].kernel.sigma_field: a spatially "
                               "varying kernel has no spectral density"), r.stderr
    assert r.stderr.count("\n") == 1 and not any(tmp_path.iterdir())
