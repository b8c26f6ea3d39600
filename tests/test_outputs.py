"""What -o writes: the format from the extension, checked before rendering, each file whole,
and an EXR that says how it was made."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import gpiscl
from unprivileged import permissions_enforced
from gpiscl.host.io.images import read_exr, read_exr_attributes, write_png
from gpiscl.host.io.output_files import plan, write_atomically
from gpiscl.host.errors import SceneError
from gpiscl.scenes import furnace_sphere

ROOT = Path(__file__).resolve().parents[1]


def gpiscl_cli(*args, cwd=None):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(permissions_enforced([sys.executable, "-m", "gpiscl", *args]),
                          capture_output=True, text=True, cwd=cwd or ROOT, env=env, timeout=600)


def one_line_error(r, *fragments):
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in r.stderr
    for f in fragments:
        assert f in lines[0], lines[0]


def test_the_extension_picks_the_files():
    p = plan("out/a.b.exr")
    assert p == {"exr": Path("out/a.b.exr"), "png": Path("out/a.b.png"),
                 "scene": Path("out/a.b.scene.json")}
    p = plan("pic.PNG")
    assert p["exr"] is None and p["png"] == Path("pic.PNG") and p["scene"] == Path("pic.scene.json")
    for bad in ("name", "victim.json", "x.jpg", "dir/.exr"):
        with pytest.raises(SceneError, match="--output.*extension"):
            plan(bad)


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "s.json"
    data = furnace_sphere(albedo=0.5)
    data["camera"]["resolution"] = [8, 6]
    data["render"]["spp"] = 2
    path.write_text(json.dumps(data))
    return path


def test_png_output_writes_a_png_and_no_exr(tmp_path, scene_file):
    r = gpiscl_cli("render", str(scene_file), "-o", str(tmp_path / "pic.png"))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "pic.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "pic.scene.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pic.png", "pic.scene.json", "s.json"]


def test_bad_outputs_are_refused_before_rendering(tmp_path, scene_file):
    (tmp_path / "notadir").write_text("x")
    (tmp_path / "adir.exr").mkdir()
    cases = [("victim.json", "extension"), ("noext", "extension"),
             ("notadir/out.exr", "is a file"), ("adir.exr", "is a folder")]
    for out, why in cases:
        r = gpiscl_cli("render", str(scene_file), "-o", str(tmp_path / out))
        one_line_error(r, "--output", why)
    # the scene file itself (its resolved scene would be written over it)
    victim = tmp_path / "v.scene.json"
    victim.write_text(scene_file.read_text())
    r = gpiscl_cli("render", str(victim), "-o", str(tmp_path / "v.exr"))
    one_line_error(r, "--output", "input of this render")
    assert json.loads(victim.read_text())["render"]["spp"] == 2
    r = gpiscl_cli("uq", str(scene_file), "-o", str(tmp_path / "u.png"))
    one_line_error(r, "--output", ".exr")


def test_unwritable_folder_is_refused_before_rendering(tmp_path, scene_file):
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o500)
    r = gpiscl_cli("render", str(scene_file), "-o", str(ro / "x.exr"))
    one_line_error(r, "--output", "permission denied")


def test_exr_header_says_how_it_was_made(tmp_path, scene_file):
    out = tmp_path / "img.exr"
    r = gpiscl_cli("render", str(scene_file), "-o", str(out), "--seed", "4294967295")
    assert r.returncode == 0, r.stderr
    a = read_exr_attributes(out)
    assert a["gpiscl:version"] == gpiscl.__version__
    # this checkout's commit (issue 30 item 9), '+' when its files differ from it
    head = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                          cwd=Path(gpiscl.__file__).parent).stdout.strip()
    assert a["gpiscl:commit"].rstrip("+") == head and len(head) == 40
    assert a["gpiscl:scene"] == str(scene_file)
    assert a["gpiscl:seed"] == "4294967295"
    assert a["gpiscl:spp"] == 2.0 and a["gpiscl:spp_requested"] == 2
    assert a["gpiscl:paths"] == str(8 * 6 * 2) and a["gpiscl:render_seconds"] > 0
    assert a["gpiscl:stopped"] == "no"
    np.testing.assert_array_equal(read_exr(out)["samples"], 2.0)


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "taken.png"
    target.mkdir()                                  # os.replace onto a folder fails
    (target / "keep").write_text("x")
    with pytest.raises(SceneError, match="taken.png: cannot write"):
        write_atomically(target, lambda tmp: write_png(tmp, np.zeros((2, 2, 3), np.uint8)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken.png"]
    assert (target / "keep").read_text() == "x"


def test_a_full_disk_leaves_no_temporary_files(tmp_path):
    """RLIMIT_FSIZE makes every write past 4 KiB fail with EFBIG (Python ignores SIGXFSZ),
    as a full disk would: neither the SDF cache nor an output may leave a temporary file.
    (Only the bake and the writers run under it: PoCL's compiler writes files too.)"""
    import resource
    import trimesh
    trimesh.creation.icosphere(subdivisions=2).export(tmp_path / "ball.obj")
    code = (
        "import sys, numpy as np\n"
        "from gpiscl.host.compile.sdf_bake import mesh_mean\n"
        "from gpiscl.host.io.images import write_exr\n"
        "from gpiscl.host.io.output_files import write_atomically\n"
        "from gpiscl.host.errors import SceneError\n"
        "grid, hit = mesh_mean(sys.argv[1], 16)\n"
        "try:\n"
        "    write_atomically(sys.argv[2], lambda t: write_exr(t, np.random.rand(64, 64, 3)))\n"
        "except SceneError as e:\n"
        "    print('error:', e, file=sys.stderr)\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT), GPISCL_CACHE=str(tmp_path / "cache"))
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "ball.obj"),
                        str(tmp_path / "img.exr")], capture_output=True, text=True, cwd=ROOT,
                       env=env, preexec_fn=lambda: resource.setrlimit(
                           resource.RLIMIT_FSIZE, (4096, 4096)))
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert "cannot cache the SDF bake" in r.stderr
    assert "img.exr: cannot write" in r.stderr.splitlines()[-1], r.stderr
    left = [p.name for p in tmp_path.rglob("*") if p.is_file() and ".tmp" in p.name]
    assert left == [] and not (tmp_path / "img.exr").exists()
