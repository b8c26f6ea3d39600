"""What `gpiscl uq` tells a user about its files: every file in its `wrote` line, how the
EXR was made in its header (as a render's EXR does), and why `-o NAME.png` is refused."""
import json
import subprocess
import sys

from gpiscl.host.io.images import read_exr_attributes
from gpiscl.scenes import default_scene
from gpiscl.version import __version__


def gpiscl_cli(*argv):
    return subprocess.run([sys.executable, "-m", "gpiscl", *argv], capture_output=True,
                          text=True, timeout=600)


def test_uq_names_every_file_it_wrote_and_says_how_the_exr_was_made(tmp_path):
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(default_scene()))
    out = tmp_path / "out.exr"
    r = gpiscl_cli("uq", str(scene), "--realizations", "2", "--spp", "2", "--resolution",
                   "4", "--seed", "7", "-o", str(out))
    assert r.returncode == 0, r.stderr
    wrote = r.stderr.splitlines()[-1]
    files = sorted(p.name for p in tmp_path.iterdir() if p.name != "s.json")
    assert files == ["out.exr", "out.png", "out.scene.json", "out.std.png", "out.uq.npz"]
    assert wrote.startswith("wrote ") and sorted(
        w.rsplit("/", 1)[-1] for w in wrote[len("wrote "):].split(", ")) == files, wrote
    a = read_exr_attributes(out)
    assert (a["gpiscl:version"], a["gpiscl:scene"], a["gpiscl:seed"], a["gpiscl:spp"],
            a["gpiscl:realizations"], a["gpiscl:ranges"]) == (__version__, str(scene), "7",
                                                               2, 2, "[[0, 2]]")
    merged = tmp_path / "m" / "merged.exr"
    r = gpiscl_cli("uq", "--merge", str(tmp_path / "out.uq.npz"), "-o", str(merged))
    assert r.returncode == 0 and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith("merged 2 realizations; wrote ") and "merged.std.png" in r.stderr
    assert read_exr_attributes(merged)["gpiscl:ranges"] == "[[0, 2]]"


def test_uq_to_a_png_says_it_needs_an_exr(tmp_path):
    r = gpiscl_cli("uq", "-o", str(tmp_path / "x.png"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith("error: <command line>: --output: uq writes its means and "
                               "variances to an EXR"), r.stderr
