"""`sample --noise` and sample_figures(noise=) are a standard deviation, as a scene's
observations.noise is (the posterior itself takes variances)."""
import subprocess
import sys

import numpy as np

from gpiscl import api
from gpiscl.host.figures import samples


def test_noise_is_a_standard_deviation(monkeypatch, tmp_path):
    seen = {}
    monkeypatch.setattr(samples, "load_observations",
                        lambda path, noise: seen.setdefault("variance", noise))
    monkeypatch.setattr(samples, "write_figures", lambda *a, **kw: [])
    points = tmp_path / "points.txt"
    np.savetxt(points, np.eye(3))
    api.sample_figures("rational_quadratic", tmp_path, observations=points, noise=0.03)
    assert np.isclose(seen["variance"], 0.03 ** 2)


def test_a_negative_noise_is_one_line_naming_the_option():
    r = subprocess.run([sys.executable, "-m", "gpiscl", "sample", "rational_quadratic",
                        "--noise", "-0.1"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 2
    assert r.stderr == "error: <command line>: --noise: must be > 0 (got -0.1)\n"
    help_text = subprocess.run([sys.executable, "-m", "gpiscl", "sample", "--help"],
                               capture_output=True, text=True, timeout=600).stdout
    assert "standard deviation" in " ".join(help_text.split())
