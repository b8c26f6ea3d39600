"""gpiscl density's medium counterpart for non-constant means and kernel fields
(figures/density.py scene_density, render/flight_samples.py pack_scene_object): the
classical_medium flights it draws for a scene object follow the closed form P(T > t) =
exp(-optical depth) of gp/classical.optical_depth (docs/design/classical-limits.md,
Sec. 2.1 and 4), its CSV carries the counterpart's rows, and bad input is one line.
Tolerances: KS at 1e-3 and a binomial z for the transmittance, Bonferroni over the cases."""
import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from gpiscl.cli import main
from gpiscl.host.errors import SceneError
from gpiscl.host.figures.density import (MEMORIES, Ray, ks_with_misses, scene_density,
                                         scene_object, write_density_tables)
from gpiscl.host.figures.samples import resolve_target
from gpiscl.host.gp import classical as C
from gpiscl.host.render.flight_samples import pack_model, pack_scene_object
from gpiscl.testing.stats import z_threshold

ROOT = Path(__file__).resolve().parent.parent

N = 20000
SEED = 5
SPHERE = {"type": "sphere", "center": [0, 0, 0], "radius": 0.5}
SE = {"type": "squared_exponential", "sigma": 0.3, "length_scale": 0.2}
LINEAR_SIGMA = {"type": "linear", "value": 1.0, "gradient": [0.8, 0, 0], "origin": [0, 0, 0]}
LINEAR_L = {"type": "linear", "value": 1.0, "gradient": [0.3, 0, 0], "origin": [0, 0, 0]}
GRID_SIGMA = 1.0 + 0.5 * np.random.default_rng(3).random((6, 6, 6))

# (name, kernel keys besides SE's, ray y): grazing rays along +x through the sphere
# mean's shell, transmittance 0.2-0.65 (so both the hits and the misses count)
CASES = [("sphere", {}, 0.65),
         ("sphere_linear_sigma", {"sigma_field": LINEAR_SIGMA}, 0.65),
         ("sphere_grid_sigma", {"sigma_field": {"type": "grid", "file": "sigma.npz"}}, 0.62),
         ("sphere_linear_l", {"length_scale_field": LINEAR_L}, 0.65),
         # sigma 0.0005: 0.375 sigma stretches took ~10^4 to the sphere (every flight past
         # FS_TRACK_CAP); outside they now grow with the mean (FS_CL_FAR)
         ("sphere_small_sigma", {"sigma": 0.0005}, 0.5002)]


def write_scene(folder, kernel_keys: dict, mean=SPHERE) -> str:
    np.savez(folder / "sigma.npz", values=GRID_SIGMA, origin=np.array([-1.0, -1.0, -1.0]),
             voxel_size=np.float64(0.4))
    scene = {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0]},
             "shapes": [{"type": "gpis", "clip": True,
                         "proxy": {"type": "box", "min": [-1, -1, -1], "max": [1, 1, 1]},
                         "mean": mean, "kernel": dict(SE, **kernel_keys),
                         "sampler": {"type": "function_space"}}],
             "lights": [{"type": "environment", "radiance": 1.0}]}
    path = folder / "scene.json"
    path.write_text(json.dumps(scene))
    return str(path)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test01_counterpart_flights_follow_the_optical_depth(device, tmp_path, case):
    """density's classical_medium first flights along a fixed ray: the share that leaves
    the ray is exp(-tau(L)) within binomial noise, and the distances follow 1 -
    exp(-tau(t)) (one-sample KS, a miss counted as a flight beyond the ray's end), tau the
    numpy quadrature of Eqs. 2-3 with the scene's own mean and kernel fields."""
    name, keys, y = case
    scene = write_scene(tmp_path, keys)
    ray = Ray(np.array([-1.0, y, 0.0]), np.array([1.0, 0.0, 0.0]), 2.0)
    data, _ = scene_density(scene, 0, ray, paths=N, bounces=1, seed=SEED, device=device,
                            memories=("classical_medium",))
    t = data["runs"]["classical_medium"][:, 0, 0]
    target = resolve_target(scene, 0)
    hits = np.sort(t[t >= 0])
    end = C.optical_depth(target.kernel, target.mean, ray.origin, ray.direction, ray.length)
    p = math.exp(-float(end))
    z = ((N - len(hits)) / N - p) / math.sqrt(p * (1 - p) / N)
    cdf = -np.expm1(-C.optical_depth(target.kernel, target.mean, ray.origin, ray.direction,
                                     np.append(hits, ray.length))[:-1])
    i = np.arange(1, len(hits) + 1)
    ks = float(max(np.max(i / N - cdf), np.max(cdf - (i - 1) / N), abs(len(hits) / N - 1 + p)))
    crit = C.ks_critical(N, 1e-3 / len(CASES))
    print(f"{name}: transmittance {1 - len(hits) / N:.4f} vs {p:.4f} (z {z:.2f}), "
          f"KS {ks:.4f} (critical {crit:.4f})")
    assert 0.1 < p < 0.9
    assert abs(z) < z_threshold(len(CASES))
    assert ks < crit
    row = next(r for r in data["summary"] if r["memory"] == "classical_medium")
    assert row["failed"] == 0
    assert row["ks_counterpart"] == pytest.approx(ks, abs=1e-4)
    assert row["counterpart_transmittance"] == pytest.approx(p, rel=1e-6)


def test02_ks_with_misses_sees_the_atom():
    """The KS distance counts misses against the transmittance: all flights missing a ray
    of transmittance 0.3 are 0.7 away, and flights drawn from the law itself are close."""
    grid = np.linspace(0.0, 2.0, 2001)
    law = (grid, np.full_like(grid, 0.6), 0.6 * grid)       # exp(-1.2) = 0.30 transmitted
    assert ks_with_misses(np.full(100, -1.0), law) == pytest.approx(1 - math.exp(-1.2))
    rng = np.random.default_rng(1)
    t = rng.exponential(1 / 0.6, 20000)
    assert ks_with_misses(np.where(t < 2.0, t, -1.0), law) < C.ks_critical(20000)


def test03_tables_carry_the_counterpart_for_a_shape_mean(device, tmp_path):
    """summary.csv has a classical_medium row per flight beside the memory models, and
    flights.csv its hits, for a sphere mean with a sigma field (once constant means only).
    The second flights leave the box, where the linear field turns negative: they are
    clipped to the proxy as the renderer's are (unclipped, ~10% of them failed)."""
    scene = write_scene(tmp_path, {"sigma_field": LINEAR_SIGMA})
    data, _ = scene_density(scene, 0, paths=300, bounces=2, seed=SEED, device=device)
    write_density_tables(data, tmp_path / "d")
    rows = list(csv.DictReader(open(tmp_path / "d" / "summary.csv")))
    assert [(r["memory"], r["flight"]) for r in rows] == [
        (m, str(b)) for m in MEMORIES for b in (1, 2)]
    assert all(r["failed"] == "0" for r in rows)
    medium = rows[2 * MEMORIES.index("classical_medium")]
    assert 0 < int(medium["hits"]) and float(medium["ks_counterpart"]) >= 0
    flights = [r for r in csv.DictReader(open(tmp_path / "d" / "flights.csv"))
               if r["memory"] == "classical_medium" and r["flight"] == "1"]
    assert len(flights) == int(medium["hits"])


def test04_scene_packing_is_the_host_models(tmp_path):
    """pack_scene_object (the renderer's compile path) and pack_model (host objects) give
    the same device records for a sphere mean with a grid sigma field: the grid after the
    mean program, at the kernel record's sigma_grid; the flights clip to the box proxy."""
    scene = write_scene(tmp_path, {"sigma_field": {"type": "grid", "file": "sigma.npz"}})
    target = resolve_target(scene, 0)
    packed = pack_scene_object(scene_object(scene, 0)[0], scene, "shapes[0]")
    host = pack_model(target.kernel, target.mean)
    assert packed.mean_count == host.mean_count == 1
    assert int(packed.kernel["sigma_grid"][0]) == packed.mean_count
    assert packed.kernel.tobytes() == host.kernel.tobytes()
    assert packed.nodes.tobytes() == host.nodes.tobytes()
    assert packed.interval((-3.0, 0.5, 0.0), (1.0, 0.0, 0.0), 10.0) == (2.0, 4.0)
    assert packed.interval((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.5) == (0.0, 0.5)
    assert host.interval((-3.0, 0.5, 0.0), (1.0, 0.0, 0.0), 10.0) == (0.0, 10.0)


def test05_bad_input_is_one_line(device, tmp_path, capsys):
    """A missing scene file (exit 2, before matplotlib is needed) and a missing object are
    one-line errors; flights past the tracker's cap (a sharp object along a long ray) are
    one warning line and the summary's `failed` count, not a traceback."""
    assert main(["density", str(tmp_path / "none.json"), "-o", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "SCENE" in err[0] and "none.json" in err[0]
    # a steep plane seen edge-on 4 sigma outside its zero level: stretches of 0.5 mu / lip
    steep = {"type": "plane", "normal": [1, 0, 0], "point": [0, 0, 0], "scale": 1e4}
    scene = write_scene(tmp_path, {}, mean=steep)
    with pytest.raises(SceneError, match="--object"):
        scene_density(scene, 1, paths=20, bounces=1, device=device)
    edge_on = Ray(np.array([4 * SE["sigma"] / 1e4, -1.0, 0.0]), np.array([0.0, 1.0, 0.0]), 2.0)
    data, _ = scene_density(scene, 0, edge_on, paths=20, bounces=1, device=device)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "shapes[0]" in err[0] and "classical_medium 20 of 20" in err[0]
    assert "track_cap" in err[0]
    rows = {r["memory"]: r for r in data["summary"]}
    assert rows["classical_medium"]["failed"] == 20 and rows["classical_medium"]["hits"] == 0
    assert rows["renewal"]["failed"] == 0


def test06_the_command_draws_the_counterpart_for_a_shape_mean(device, tmp_path):
    """With matplotlib (the `plots` extra): `density` on a sphere mean with a sigma field
    writes both PNGs and a summary with the counterpart's rows."""
    pytest.importorskip("matplotlib")
    scene = write_scene(tmp_path, {"sigma_field": LINEAR_SIGMA})
    out = tmp_path / "d"
    assert main(["density", scene, "-o", str(out), "--paths", "300"]) == 0
    for name in ("free_flight.png", "normals.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG"
    rows = list(csv.DictReader(open(out / "summary.csv")))
    assert [r["flight"] for r in rows if r["memory"] == "classical_medium"] == ["1", "2"]


def test07_a_mesh_proxy_clips_the_flights_to_its_faces(device):
    """wedge_volume's object sits in a prism (a mesh proxy): the flights are clipped by the
    renderer's gpis_proxy_clip, the closed-form law over PackedGpis.interval's stretch (its
    host twin), so the two must agree: the medium counterpart's share of first flights
    that leave the stretch is its transmittance within binomial noise, and the distances
    follow the law (one-sample KS). With the law taken over the prism's bounding box (a
    host twin that ignores the faces) the transmittance's z was +17."""
    paths = 4000
    data, _ = scene_density(str(ROOT / "scenes" / "wedge_volume.json"), 0, paths=paths,
                            bounces=1, seed=5, device=device, memories=("classical_medium",))
    row = next(r for r in data["summary"] if r["flight"] == 1)
    T = row["counterpart_transmittance"]
    assert 0.05 < T < 0.95 and row["failed"] == 0, row
    z = (1.0 - row["hits"] / paths - T) / math.sqrt(T * (1.0 - T) / paths)
    assert abs(z) < z_threshold(2), (z, row)
    assert row["ks_counterpart"] < C.ks_critical(paths, 1e-3 / 2), row
