"""convert-vdb: a clear way out without an OpenVDB binding, and a correct copy with one
(a stand-in binding with OpenVDB's Python API, since none installs from PyPI)."""
import types

import numpy as np
import pytest

from gpiscl.host.io import vdb
from gpiscl.host.errors import SceneError
from gpiscl.host.io.grids import load_grid
from gpiscl.testing.fake_openvdb import FakeGrid


def test_without_a_binding_the_command_says_how_to_get_one(tmp_path, monkeypatch, capsys):
    from gpiscl.cli import main
    monkeypatch.setattr(vdb, "import_openvdb", lambda: None)  # as on a PyPI-only machine
    code = main(["convert-vdb", str(tmp_path / "a.vdb"), str(tmp_path / "a.npz")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "conda install -c conda-forge openvdb" in err and not (tmp_path / "a.npz").exists()


def test_copy_keeps_values_origin_and_voxel_size(tmp_path, monkeypatch):
    rng = np.random.default_rng(0)
    voxels = {(i, j, k): float(rng.normal()) for i in range(-2, 3) for j in range(1, 4)
              for k in range(0, 6) if rng.uniform() < 0.8}
    voxels[(-2, 1, 0)], voxels[(2, 3, 5)] = 0.5, -0.5   # pin the bounding box
    grid = FakeGrid("mean", voxels, 100.0, 0.25, (1.0, 2.0, 3.0))
    fake = types.SimpleNamespace(readAll=lambda path: ([grid], {}))
    monkeypatch.setattr(vdb, "import_openvdb", lambda: fake)
    out = tmp_path / "g.npz"
    info = vdb.convert_vdb("x.vdb", str(out))
    g = load_grid(out)
    assert g.shape == (5, 3, 6) and info["grid"] == "mean"
    assert g.voxel_size == 0.25 and g.origin == pytest.approx((0.5, 2.25, 3.0))
    for (i, j, k), value in voxels.items():
        assert g.values[i + 2, j - 1, k] == pytest.approx(value)
    inactive = [(i, j, k) for i in range(-2, 3) for j in range(1, 4) for k in range(6)
                if (i, j, k) not in voxels]
    assert all(g.values[i + 2, j - 1, k] == 100.0 for i, j, k in inactive)
    with pytest.raises(SceneError) as info:
        vdb.convert_vdb("x.vdb", str(out), grid_name="density")
    assert info.value.key == "density" and "has: mean" in info.value.reason


def test_convert_vdb_runs_without_pyopencl_or_openexr(tmp_path):
    """Debian's python3-openvdb serves the system Python, which has numpy but neither
    pyopencl nor OpenEXR: the command must not import them, and without a binding it
    names the Debian package."""
    import os
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parent.parent
    code = ("import sys\n"
            "for name in ('pyopencl', 'OpenEXR', 'trimesh', 'igl'):\n"
            "    sys.modules[name] = None  # importing it now raises ImportError\n"
            "from gpiscl.cli import main\n"
            f"sys.exit(main(['convert-vdb', {str(tmp_path / 'a.vdb')!r}, "
            f"{str(tmp_path / 'a.npz')!r}]))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(root)})
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    if "no OpenVDB Python binding" in r.stderr:
        assert "apt install python3-openvdb" in r.stderr


SYSTEM_PYTHON = "/usr/bin/python3"


def _system_python_has_openvdb() -> bool:
    import subprocess
    from pathlib import Path
    if not Path(SYSTEM_PYTHON).exists():
        return False
    probe = ("import numpy\ntry:\n    import openvdb\nexcept ImportError:\n"
             "    import pyopenvdb\n")
    return subprocess.run([SYSTEM_PYTHON, "-c", probe], capture_output=True).returncode == 0


@pytest.mark.skipif(not _system_python_has_openvdb(),
                    reason="no system Python with an OpenVDB binding (apt install "
                    "python3-openvdb)")
def test_convert_vdb_under_debians_binding(tmp_path):
    """A real .vdb written by OpenVDB itself (Debian's python3-openvdb), converted by
    `python -m gpiscl convert-vdb` under that same system Python: values, inactive
    voxels (the background), origin and voxel size survive."""
    import os
    import subprocess
    from pathlib import Path
    root = Path(__file__).resolve().parent.parent
    values = np.random.default_rng(4).normal(size=(4, 3, 5)).astype(np.float32)
    np.save(tmp_path / "values.npy", values)
    write = (
        "import numpy as np, sys\n"
        "try:\n    import openvdb as vdb\nexcept ImportError:\n    import pyopenvdb as vdb\n"
        "g = vdb.FloatGrid(background=100.0)\n"
        "g.name = 'mean'\n"
        f"g.copyFromArray(np.load({str(tmp_path / 'values.npy')!r}), ijk=(2, -1, 0))\n"
        "g.transform = vdb.createLinearTransform(voxelSize=0.25)\n"
        "g.transform.translate((1.0, 2.0, 3.0))\n"
        f"vdb.write({str(tmp_path / 'a.vdb')!r}, grids=[g])\n")
    subprocess.run([SYSTEM_PYTHON, "-c", write], check=True)
    r = subprocess.run([SYSTEM_PYTHON, "-m", "gpiscl", "convert-vdb", str(tmp_path / "a.vdb"),
                        str(tmp_path / "a.npz"), "--grid", "mean"], capture_output=True,
                       text=True, env={**os.environ, "PYTHONPATH": str(root)})
    assert r.returncode == 0, r.stderr
    g = load_grid(tmp_path / "a.npz")
    assert g.shape == values.shape and g.voxel_size == pytest.approx(0.25)
    assert g.origin == pytest.approx((1.5, 1.75, 3.0))   # index (2, -1, 0) in world space
    np.testing.assert_allclose(g.values, values, rtol=1e-6)
