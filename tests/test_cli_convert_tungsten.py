"""`gpiscl convert-tungsten`: what a render of a Tungsten file tells the user to run
converts it, in a real subprocess, and a bad option is named as the command line spells it."""
import json
import os
import subprocess
import sys
from pathlib import Path

FIXTURE = Path(__file__).resolve().parent / "data" / "tungsten" / "gp-csg-test.json"
ROOT = Path(__file__).resolve().parent.parent


def gpiscl(*args, cwd):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "gpiscl", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, env=env, timeout=600)


def test_the_render_hint_names_a_command_that_converts_the_scene(tmp_path):
    hint = gpiscl("render", FIXTURE, "-o", tmp_path / "x.exr", cwd=tmp_path)
    assert hint.returncode == 2 and "gpiscl convert-tungsten" in hint.stderr
    assert not (tmp_path / "x.exr").exists()
    out = gpiscl("convert-tungsten", FIXTURE, tmp_path / "ours.json", "--environment", "0.5",
                 cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stderr.splitlines()[-1] == f"wrote {tmp_path / 'ours.json'}"
    scene = json.loads((tmp_path / "ours.json").read_text())
    assert any(s["type"] == "gpis" for s in scene["shapes"])


def test_an_unwritable_grid_folder_is_named_as_the_option(tmp_path):
    (tmp_path / "file").write_text("")
    out = gpiscl("convert-tungsten", FIXTURE, tmp_path / "ours.json",
                 "--grid-dir", tmp_path / "file" / "grids", cwd=tmp_path)
    assert out.returncode == 2
    line, = out.stderr.splitlines()
    assert line.startswith("error: <command line>: --grid-dir: cannot create"), line
    assert not (tmp_path / "ours.json").exists()
