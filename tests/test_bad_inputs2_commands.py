"""The second round of bad inputs, the command-line and API cases: a time limit or a
memory size past its bound, a file name too long, uq partial sums that lie about their
resolution or provenance, local:1000 workers, a Scene edited after loading. Each refusal is
one line naming the file (or the option), the key path and the reason, exit code 2, before
any work and with nothing written."""
import json

import numpy as np
import pytest

import gpiscl
from gpiscl import api
from gpiscl.cli import main
from gpiscl.host.errors import SceneError
from gpiscl.host.scene.arguments import check
from gpiscl.host.uq.files import load_partial, run_meta, with_digest
from gpiscl.host.uq.sums import UqSums
from gpiscl.scenes import furnace_sphere

SCENE = {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "resolution": [8, 8]},
         "lights": [{"type": "environment"}], "render": {"spp": 1},
         "shapes": [{"type": "sphere", "radius": 1}]}


def refused(capsys, argv, *fragments):
    """main(argv) exits 2 with one line holding every fragment."""
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert all(f in err for f in fragments), err
    return err


def scene_file(tmp_path, doc=SCENE):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc))
    return path


# ---- E04 and E15: bounds of --time-limit and --max-memory, the same from every front end

def test_a_time_limit_beyond_31_years_is_refused_not_an_overflow(tmp_path, capsys):
    scene = scene_file(tmp_path)
    refused(capsys, ["render", str(scene), "-o", str(tmp_path / "out.exr"), "--time-limit",
                     "1e308"], "<command line>: --time-limit: must be <= 1000000000 (got 1e+308)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]
    assert check(time_limit=1e9) == {"time_limit": 1e9}


def test_max_memory_has_the_apis_bound_when_spelled_as_a_string(tmp_path, capsys):
    """Through a float, 2**62 + 1 rounded to 2**62 and passed."""
    scene = scene_file(tmp_path)
    refused(capsys, ["render", str(scene), "-o", str(tmp_path / "out.exr"), "--max-memory",
                     str(2**62 + 1)], "--max-memory: must be <= 4611686018427387904")
    for spelled in (str(2**62 + 1), 2**62 + 1):
        with pytest.raises(SceneError, match="must be <= 4611686018427387904"):
            check(max_memory=spelled)
    assert check(max_memory=str(2**62)) == {"max_memory": 2**62}
    assert check(max_memory="1.5k") == {"max_memory": 1536}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]


# ---- E06: a 300-character output name

def test_an_output_name_too_long_for_the_file_system_is_one_line(tmp_path, capsys):
    scene = scene_file(tmp_path)
    refused(capsys, ["render", str(scene), "-o", str(tmp_path / ("n" * 300 + ".exr"))],
            "<command line>: --output: the file name nnnn", "is too long (304 bytes)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]


# ---- E07, E12: uq partial sums checked against their own provenance

def partial(tmp_path, name, first=0, count=2, shape=(8, 8), seed=7, edit=None, meta=None):
    """A partial-sums file as write_uq writes it; edit(arrays) / meta(meta) damage it."""
    rng = np.random.default_rng(first)
    h, w = shape
    sums = UqSums.empty((h, w, 3))
    for _ in range(count):
        sums = sums.merge(UqSums.from_realization(rng.random((h, w, 3)),
                                                  rng.random((h, w, 3)) * 1e-3))
    recorded = with_digest(sums, run_meta({**SCENE, "camera": {"resolution": [w, h]}},
                                          seed, 2, first, count))
    path = tmp_path / f"{name}.uq.npz"
    sums.save(path, recorded)
    if edit or meta:
        z = dict(np.load(path))
        if edit:
            z = edit(z)
        if meta:
            z["meta"] = np.array(json.dumps(meta(json.loads(str(z["meta"])))))
        np.savez(path, **z)
    return str(path)


def test_partial_sums_merge_when_they_belong_together(tmp_path):
    a, b = partial(tmp_path, "a"), partial(tmp_path, "b", first=2)
    sums, meta = load_partial(b)
    assert sums.n == 2 and meta["ranges"] == [(2, 4)]
    merged, _ = api.uq_merge([a, b], tmp_path / "m.exr")
    assert merged.n == 4
    # the merged file is itself a valid partial: its digest covers both ranges
    assert load_partial(tmp_path / "m.uq.npz")[1]["ranges"] == [(0, 2), (2, 4)]


def cut(z):
    return {k: (v[:4, :4] if v.ndim == 3 else v) for k, v in z.items()}


@pytest.mark.parametrize("name,damage,where", [
    # E07: arrays cut to 4x4, the provenance still 8x8
    ("cut", dict(edit=cut), "b.uq.npz: mean: must be a float (8, 8, 3) array, as its "
                            "recorded resolution 8x8 says (got (4, 4, 3) float64)"),
    # E12: a reversed range whose length sum still matches n
    ("reversed", dict(count=4, meta=lambda m: dict(m, ranges=[[4, 2], [10, 14]])),
     "b.uq.npz: meta.ranges[0]: must be [a, b) with 0 <= a < b <= 2**31 (got [4, 2])"),
    ("relabelled", dict(meta=lambda m: dict(m, ranges=[[100, 102]])),
     "b.uq.npz: meta: its sums do not match the digest recorded with them"),
    ("negative m2", dict(edit=lambda z: dict(z, m2=-abs(z["m2"]) - 1)),
     "b.uq.npz: m2: has negative values"),
    ("n = 2^62", dict(edit=lambda z: dict(z, n=np.array(2**62)),
                      meta=lambda m: dict(m, ranges=[[0, 2**62]])),
     "b.uq.npz: meta.ranges[0]: must be [a, b) with 0 <= a < b <= 2**31"),
    ("overlap", dict(meta=lambda m: dict(m, ranges=[[10, 12], [11, 12]])),
     "b.uq.npz: meta.ranges: [10, 12) and [11, 12) overlap"),
    ("no digest", dict(meta=lambda m: {k: v for k, v in m.items() if k != "digest"}),
     "b.uq.npz: meta.digest: missing"),
    ("bool seed", dict(meta=lambda m: dict(m, seed=True)), "b.uq.npz: meta.seed: must be"),
])
def test_uq_merge_refuses_partial_sums_that_contradict_themselves(tmp_path, capsys, name,
                                                                   damage, where):
    a = partial(tmp_path, "a", first=20)
    b = partial(tmp_path, "b", **damage)
    before = sorted(p.name for p in tmp_path.iterdir())
    refused(capsys, ["uq", "--merge", a, b, "-o", str(tmp_path / "m.exr")], where)
    assert sorted(p.name for p in tmp_path.iterdir()) == before   # nothing written


# ---- E11: local:1000 started a thousand worker processes

def test_local_workers_are_capped_at_the_cpus_before_any_work(tmp_path, capsys):
    pytest.importorskip("distributed")
    from gpiscl.host.distributed.cluster import max_local_workers
    most = max_local_workers()
    scene = scene_file(tmp_path)
    refused(capsys, ["render", str(scene), "-o", str(tmp_path / "out.exr"), "--cluster",
                     "local:1000"], f"<command line>: --cluster: local:N needs 1 <= N <= "
                                    f"{most}, the CPUs this process may use (got 'local:1000')")
    refused(capsys, ["uq", str(scene), "-o", str(tmp_path / "uq.exr"), "--cluster",
                     f"local:{most + 1}"], "--cluster: local:N needs")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]


# ---- E13: a Scene edited after loading is validated again, at the key of the edit

@pytest.mark.parametrize("edit,key", [
    (lambda d: d["camera"].__setitem__("resolution", [0, 0]), "camera.resolution[0]"),
    (lambda d: d["render"].__setitem__("spp", -3), "render.spp"),
    (lambda d: d["shapes"][0].__setitem__("radius", "big"), "shapes[0].radius"),
    (lambda d: d["lights"].append({"type": "point"}), "lights[1]"),
])
def test_a_scene_edited_after_loading_is_checked_again(edit, key):
    doc = furnace_sphere()
    scene = gpiscl.load_scene(doc)
    edit(scene.data)
    with pytest.raises(SceneError) as info:
        gpiscl.render(scene, spp=1)     # refused before any device work
    assert info.value.file == "<dict>" and info.value.key.startswith(key), str(info.value)
    with pytest.raises(SceneError):
        scene.with_overrides(spp=2)     # a copy must not launder the edit


def test_a_valid_edit_is_resolved_like_a_loaded_document():
    scene = gpiscl.load_scene(furnace_sphere())
    scene.data["render"]["spp"] = 3
    scene.data["camera"]["resolution"] = (4, 2)      # a tuple: resolved to a list
    again = gpiscl.load_scene(scene)
    assert again is scene and scene.data["render"]["spp"] == 3
    assert scene.data["camera"]["resolution"] == [4, 2]
