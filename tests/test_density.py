"""gpiscl density (figures/density.py, render/flight_samples.py): the flights it draws
obey the laws docs/design/classical-limits.md derives for them, and the command writes
its CSV and PNG (or says in one line how to get matplotlib)."""
import csv
import json
import math
import sys

import numpy as np
import pytest

from gpiscl.cli import main
from gpiscl.host.errors import SceneError
from gpiscl.host.figures.density import Ray, density_data, parse_ray, write_density
from gpiscl.host.figures.plotting import PLOTS_MISSING
from gpiscl.host.gp import Constant, SquaredExponential
from gpiscl.host.gp import classical as C
from gpiscl.host.render.flight_samples import flights

SCENE = {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0]},
         "shapes": [{"type": "gpis", "clip": True,
                     "proxy": {"type": "box", "min": [-1, -1, -1], "max": [1, 1, 1]},
                     "mean": {"type": "constant", "value": 1.0},
                     "kernel": {"type": "squared_exponential", "sigma": 1.0,
                                "length_scale": 0.1},
                     "sampler": {"type": "function_space"}}],
         "lights": [{"type": "environment", "radiance": 1.0}]}


def have_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def test01_the_medium_counterpart_flies_rice_and_sees_sphere_normals(device):
    """classical_medium flights are exponential with exactly Rice's entry rate (KS to
    Exp(nu / Phi)), its hit normals follow the visible normals of a sphere (cos theta to
    -d has density 2c: CDF c^2) and a second flight is the same exponential (no memory)."""
    kernel, level, n = SquaredExponential(1.0, 0.2), 1.5, 20000
    rate = float(C.entry_rate(kernel, level))
    out = flights(device, kernel, Constant(offset=level), (0, 0, 0), (1, 0, 0), 12 / rate, n,
                  memory="classical_medium", bounces=2, seed=4)
    crit = C.ks_critical(n, 1e-3 / 3)
    for b in range(2):
        t = out[:, b, 0]
        assert C.ks_to_exponential(np.where(t >= 0, t, np.inf), rate) < crit, b
    g = out[out[:, 0, 0] >= 0, 0, 1:4]
    c = -g[:, 0] / np.linalg.norm(g, axis=1)
    assert np.all(c > 0)
    assert C.ks_to_cdf(c, lambda x: x * x) < crit


def test02_density_data_rows(device):
    """Every model's first flight is the same draw (memory acts at vertices only); the
    summary carries Rice's rate and, for a plane-free constant mean, no Beckmann row."""
    kernel = SquaredExponential(1.0, 0.2)
    ray = Ray(np.zeros(3), np.array([1.0, 0.0, 0.0]), 6.0)
    data = density_data(kernel, Constant(offset=1.0), ray, paths=2000, device=device)
    runs = data["runs"]
    assert set(runs) == {"none", "renewal", "renewal_plus", "global", "classical_medium"}
    for m in ("renewal", "renewal_plus", "global"):
        np.testing.assert_array_equal(runs[m][:, 0, 0], runs["none"][:, 0, 0])
    rows = [r for r in data["summary"] if r["flight"] == 1]
    assert all(math.isclose(r["rice_entry_rate"], C.entry_rate(kernel, 1.0)) for r in rows)
    assert all("beckmann_alpha" not in r for r in rows)


def test03_ray_option_errors_name_it():
    assert parse_ray("0,0,0,0,0,-2,3").direction.tolist() == [0, 0, -1]
    for bad in ("0,0,0,0,0,0,1", "1,2,3", "0,0,0,1,0,0,-1", "a,b,c,d,e,f,g"):
        with pytest.raises(SceneError, match="--ray"):
            parse_ray(bad)


def test04_without_matplotlib_the_command_says_how_to_install(monkeypatch, tmp_path, capsys):
    path = tmp_path / "s.json"
    path.write_text(json.dumps(SCENE))
    monkeypatch.setitem(sys.modules, "matplotlib", None)   # makes the import fail
    assert main(["density", str(path), "-o", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and PLOTS_MISSING in err[0]
    assert not (tmp_path / "d").exists()


def test05_the_command_writes_csv_and_png_when_matplotlib_is_installed(tmp_path, device):
    """With matplotlib: the files exist and the CSV has a row per model and flight.
    Without: the refusal through the Python entry point."""
    path = tmp_path / "s.json"
    path.write_text(json.dumps(SCENE))
    if not have_matplotlib():
        with pytest.raises(SceneError, match="pip install"):
            write_density(str(path), 0, tmp_path / "d", paths=10)
        return
    out = tmp_path / "d"
    assert main(["density", str(path), "-o", str(out), "--paths", "500"]) == 0
    rows = list(csv.DictReader(open(out / "summary.csv")))
    assert len(rows) == 5 * 2
    assert (out / "free_flight.png").read_bytes()[:4] == b"\x89PNG"
    assert sum(1 for _ in open(out / "flights.csv")) > 500
