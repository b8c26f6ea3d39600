"""The Python API checks what the command line checks, documents itself, and can write
images and run uq."""
import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import gpiscl
from gpiscl import SceneError
from gpiscl.host.io.images import read_exr, read_exr_attributes

ROOT = Path(__file__).resolve().parents[1]
TINY = {"lights": [{"type": "environment"}], "camera": {"resolution": [4, 3]},
        "render": {"spp": 2}}


@pytest.mark.parametrize("kwargs,name", [
    (dict(spp=0), "spp"), (dict(spp=2.5), "spp"), (dict(spp=True), "spp"),
    (dict(spp=2**31), "spp"),
    (dict(resolution="64x64"), "resolution"), (dict(resolution=(0, 0)), "resolution[0]"),
    (dict(resolution=(4, 100000)), "resolution[1]"), (dict(resolution=(4,)), "resolution"),
    (dict(seed=-1), "seed"), (dict(seed=2**32), "seed"), (dict(seed="1"), "seed"),
    (dict(realization=-1), "realization"), (dict(batch_size=0), "batch_size"),
    (dict(batch_size=2**30), "batch_size"), (dict(time_limit=-5), "time_limit"),
    (dict(time_limit=float("nan")), "time_limit"),
])
def test_bad_arguments_raise_scene_error_naming_them(kwargs, name):
    for fn in (gpiscl.render, gpiscl.render_result):
        with pytest.raises(SceneError) as info:
            fn(TINY, **kwargs)
        assert info.value.file == "<arguments>" and info.value.key == name, str(info.value)


def test_uq_arguments_are_checked():
    for kwargs, name in ((dict(spp=1), "spp"), (dict(realizations=0), "realizations"),
                         (dict(first=-1), "first"), (dict(seed=-3), "seed")):
        with pytest.raises(SceneError) as info:
            gpiscl.uq(TINY, **kwargs)
        assert info.value.key == name


def test_scene_cannot_be_built_unvalidated():
    with pytest.raises(SceneError, match="lights"):
        gpiscl.Scene({"lights": []})
    with pytest.raises(SceneError, match="colour"):
        gpiscl.Scene({"lights": [{"type": "environment"}], "colour": 1})
    s = gpiscl.Scene({"lights": [{"type": "environment"}]})
    assert s.data["render"]["spp"] == 16          # resolved: defaults filled in


def test_the_module_shows_and_documents_its_api():
    names = dir(gpiscl)
    for name in ("render", "render_result", "write_image", "uq", "load_scene", "Scene",
                 "SceneError"):
        assert name in names and name in gpiscl.__all__
        assert getattr(gpiscl, name) is not None
    for fn in (gpiscl.render, gpiscl.render_result, gpiscl.write_image, gpiscl.uq):
        doc = fn.__doc__
        for section in ("Parameters\n    ----------", "Returns\n    -------",
                        "Raises\n    ------"):
            assert section in doc, (fn.__name__, section)


def test_write_image_writes_what_the_command_line_writes(device, tmp_path):
    res = gpiscl.render_result(TINY, device=device, seed=3)
    paths = gpiscl.write_image(tmp_path / "a.exr", res)
    ch = read_exr(paths["exr"])
    np.testing.assert_array_equal(ch["R"], res.image.mean[..., 0])
    assert read_exr_attributes(paths["exr"])["gpiscl:seed"] == "3"
    assert paths["png"].exists() and paths["scene"].exists()
    paths = gpiscl.write_image(tmp_path / "b.png", res)
    assert paths["exr"] is None and paths["png"].read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(SceneError, match="extension"):
        gpiscl.write_image(tmp_path / "c.tiff", res)
    with pytest.raises(SceneError, match="result"):
        gpiscl.write_image(tmp_path / "c.exr", res.image)


def test_uq_from_python(device, tmp_path):
    scene = dict(TINY, shapes=[{"type": "gpis", "proxy": {"type": "sphere", "radius": 2},
                                "mean": {"type": "sphere", "radius": 1},
                                "kernel": {"type": "squared_exponential", "sigma": 0.1,
                                           "length_scale": 0.3}}],
                 camera={"position": [0, 0, 4], "look_at": [0, 0, 0], "resolution": [4, 3]})
    run = gpiscl.uq(scene, realizations=2, spp=2, device=device, output=tmp_path / "u.exr")
    assert run.sums.n == 2 and run.sums.mean.shape == (3, 4, 3)
    assert "var.R" in read_exr(tmp_path / "u.exr")


def test_version_and_console_script_entry():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for cmd in ([sys.executable, "-m", "gpiscl", "--version"],
                [sys.executable, "-c", "from gpiscl.cli import console; console()",
                 "--version"]):
        r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env)
        assert r.returncode == 0 and r.stdout.strip() == f"gpiscl {gpiscl.__version__}"
    assert "gpiscl = gpiscl.cli:console" in (ROOT / "setup.cfg").read_text()


def test_usage_mistakes_are_one_line():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-m", "gpiscl", "render", "--spp", "0"],
                       capture_output=True, text=True, cwd=ROOT, env=env)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--spp" in r.stderr


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_true_draws_a_bar_in_spp_on_a_terminal_only(device, monkeypatch, capsys):
    monkeypatch.setattr(sys, "stderr", Terminal())
    gpiscl.render_result(TINY, device=device, progress=True)
    err = sys.stderr.getvalue()
    assert "spp" in err and "paths/s" in err and "\r" in err
    monkeypatch.undo()
    # elsewhere a line every 10 s (tests/test_batch_costs.py): none for a short render
    gpiscl.render_result(TINY, device=device, progress=True)
    assert capsys.readouterr().err == ""
