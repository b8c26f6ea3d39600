"""E10 (issue 29): the first batches of a slow scene were not bounded in time: sized from
cheap sky rows, one landed on a 65536-feature GPIS and took 12.6 s against `--time-limit 2`,
and stop signals waited as long. Batches are now shrunk to what their pixels cost
(batching.PixelCosts: measured by earlier batches, probed ahead in the first pass), and the
time limit ends a batch between bounces as stop() does. Issue 30 item 7: outside a
terminal the render prints a plain progress line every 10 s, paths/s counts the render
alone, and a slow compile says so once."""
import io
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gpiscl.api import render_result
from gpiscl.host.render import device as device_module
from gpiscl.host.render import integrator as integrator_module
from gpiscl.host.render.batching import TARGET_SECONDS, BatchSizer, PixelCosts
from gpiscl.host.render.progress import ProgressLines, duration

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def e10_scene(features=65536, resolution=64, spp=1000000):
    """E10's scene: sky above, a floor, and a GPIS of many features in the middle rows."""
    return {"camera": {"position": [0, 0.3, 4], "look_at": [0, 0, 0],
                       "resolution": [resolution, resolution]},
            "render": {"spp": spp},
            "shapes": [{"type": "rectangle", "center": [0, -1, 0], "u": [6, 0, 0],
                        "v": [0, 0, -6], "bsdf": {"type": "diffuse", "albedo": 0.5}},
                       {"type": "gpis", "proxy": {"type": "sphere", "radius": 1.4},
                        "mean": {"type": "sphere", "radius": 0.8},
                        "kernel": {"type": "squared_exponential", "sigma": 0.05,
                                   "length_scale": 0.15},
                        "sampler": {"type": "weight_space", "features": features}}],
            "lights": [{"type": "environment", "radiance": 0.6},
                       {"type": "directional", "direction": [0.3, 1, 0.4],
                        "irradiance": 2.0}]}


# ---- PixelCosts, without a device

def test_pixel_costs_shrink_a_batch_to_what_its_pixels_cost():
    costs = PixelCosts(1000, target=0.5)
    costs.record(0, 100, 0.01)              # pixels 0-99: 0.1 ms a path
    assert costs.limit(0, 100) == 100
    # unmeasured pixels cost what the nearest measured ones do: the last batch's
    assert costs.limit(100, 900) == 900
    costs.probed(990, 0.0101)               # the cheapest probe: all of it overhead
    costs.probed(500, 0.1101)               # an object: 0.1 s a path less the overhead
    n = costs.limit(100, 900)
    # cheap up to midway to the object's probe (nearer to it: its cost), then 4 of those
    assert n == 204, n
    assert costs.limit(500, 100) == 5       # 0.5 s of 0.1 s paths: the rest is launches
    # a batch over several passes of the image is bounded by a pass's cost
    assert costs.limit(0, 10**6) < 10**6


def test_a_batch_spreads_its_time_as_the_probes_found_the_costs():
    costs = PixelCosts(100, target=0.5)
    costs.probed(10, 0.001)
    costs.probed(60, 0.101)
    costs.record(0, 100, 1.0)               # the real batch took 1 s: the scale
    cells = costs.cells
    assert costs.cost[60 * cells // 100] > 50 * costs.cost[10 * cells // 100]
    # less the launches every batch pays (the cheapest probe's 1 ms)
    assert sum(costs.cost) == pytest.approx(1.0 - 0.001)


def test_progress_lines_say_spp_eta_and_paths_per_second():
    out = io.StringIO()
    lines = ProgressLines("rendering", 64, "spp", 100, "paths", out, every=0.0)
    lines(0)                                # the clock starts
    time.sleep(0.05)
    lines(250)
    text = out.getvalue()
    assert text.count("\n") == 1 and "\r" not in text, text
    assert text.startswith("rendering: 2.5/64 spp (4 %), 0 s, ETA "), text
    assert text.rstrip().endswith("paths/s"), text
    assert duration(3 * 86400 + 7200) == "3 d 2 h" and duration(125) == "2 min 05 s"


def test_a_slow_compile_says_so_once_and_a_fast_one_not(monkeypatch):
    monkeypatch.setattr(device_module, "SLOW_COMPILE_SECONDS", 0.05)
    monkeypatch.setitem(device_module._notice, "said", False)
    out = io.StringIO()
    with device_module.slow_compile_notice():
        time.sleep(0.2)                     # off: nothing
    with device_module.announcing_compiles(out):
        with device_module.slow_compile_notice():
            pass                            # a cache hit
        assert out.getvalue() == ""
        with device_module.slow_compile_notice():
            time.sleep(0.2)
        with device_module.slow_compile_notice():
            time.sleep(0.2)                 # once per process
    assert out.getvalue() == device_module.COMPILE_NOTICE + "\n"
    # while the build's stderr is redirected, to the real one's descriptor
    monkeypatch.setitem(device_module._notice, "said", False)
    r, w = os.pipe()
    with device_module.announcing_compiles(io.StringIO()):
        with device_module.slow_compile_notice(w):
            time.sleep(0.2)
    os.close(w)
    assert os.read(r, 200).decode() == device_module.COMPILE_NOTICE + "\n"


# ---- on the device

def test_probes_and_cost_sized_batches_leave_the_image_bit_identical(device, monkeypatch):
    scene = e10_scene(features=256, resolution=24, spp=3)
    plain = render_result(scene, device=device, batch_size=97)
    monkeypatch.setattr(integrator_module, "COSTS_AFTER_SECONDS", 0.0)   # always on
    monkeypatch.setattr(integrator_module, "TRUSTED_SECONDS", 0.0)
    monkeypatch.setattr(integrator_module, "COSTLY_RATE", float("inf"))
    probed = []
    real = integrator_module.WavefrontIntegrator._dropped

    def counting(self, trace):
        probed.append(1)
        return real(self, trace)
    monkeypatch.setattr(integrator_module.WavefrontIntegrator, "_dropped", counting)
    costed = render_result(scene, device=device)
    assert len(probed) > 2                  # the warm-up and probes ran
    for name in ("sum", "sum_sq", "count"):
        assert np.array_equal(getattr(plain.image, name), getattr(costed.image, name)), name
    a, b = plain.stats, costed.stats
    assert (a.paths, a.rays, a.shadow_rays, a.nan_paths, a.killed_paths) == \
           (b.paths, b.rays, b.shadow_rays, b.nan_paths, b.killed_paths)


def test_a_e10_scene_keeps_its_time_limit_and_stops_within_a_second_or_two(device):
    """E10: --time-limit 2 stopped after 12.6 s, and stop signals took up to 9 s."""
    batches = []
    res = render_result(e10_scene(), device=device, time_limit=2.0,
                        progress=lambda n: batches.append(time.perf_counter()))
    # was 12.6 s; 8 s: a batch sized on an idle core can take 3x as long once the other
    # test worker and PoCL's threads share the two cores (5.9 s seen in a cold suite)
    assert res.stats.time_limited and res.stats.seconds < 8.0, res.stats.summary()
    assert np.diff(batches).max() < 3.0, np.diff(batches)   # was 13.9 s (E10); slack for a shared machine
    asked = []
    t_stop = [None]

    def stop():
        asked.append(time.perf_counter())
        return t_stop[0] is not None and time.perf_counter() >= t_stop[0]

    def progress(n):
        if n == 0:
            t_stop[0] = time.perf_counter() + 3.0    # 3 s after the clock starts
    res = render_result(e10_scene(), device=device, stop=stop, progress=progress)
    assert res.stats.interrupted
    # was 5.7-9 s (E10). A stop waits for the bounce in flight, and a batch sized on the
    # sky rows can land on the GPIS rows: one bounce took 2-3 s idle and 4.1-4.9 s with
    # other work on the two cores (docs/design/batches.md, 'When cost-per-pixel sizing
    # is on'); turning the probes on for every GPIS first pass fixed it (0.12 s) but
    # doubled short renders (wedge_volume 1.2 -> 4.4 s at 4 spp)
    assert asked[-1] - t_stop[0] < 5.5, asked[-1] - t_stop[0]


def test_the_command_line_prints_progress_lines_into_a_pipe(tmp_path):
    """Issue 30 item 7: outside a terminal a long render printed nothing until the end."""
    scene = tmp_path / "slow.json"
    scene.write_text(json.dumps(e10_scene()))
    r = subprocess.run([sys.executable, "-m", "gpiscl", "render", str(scene), "-o",
                        str(tmp_path / "out.exr"), "--time-limit", "13"],
                       capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert "Traceback" not in r.stderr and "\r" not in r.stderr, r.stderr
    progress = [line for line in lines if line.startswith("rendering: ")]
    # one every 10 s, written when a batch ends: 13 s leaves room for a batch that a
    # loaded machine stretches past the 10-s mark (an 11-s limit saw none: the batch
    # running at 10 s ran into the limit)
    assert len(progress) == 1, r.stderr
    assert re.fullmatch(r"rendering: [0-9.e-]+/1000000 spp \(0 %\), 1[0-2] s, ETA .+, "
                        r"[0-9.e+]+ paths/s", progress[0]), progress[0]
    summary = next(line for line in lines if line.startswith("paths: "))
    assert float(summary.split("time: ")[1].split(" s")[0]) < 14.5, summary


def test_a_fixed_cost_per_batch_does_not_keep_batches_small():
    """On a GPU every batch, a one-path probe too, costs its launches' latency whatever its
    size (the H200 run of 2026-12-04: 1490 launches of ~100 paths, 3.5e3 paths/s): that
    latency must not be taken for the paths' cost, in probes or in batches, or the first
    pass never leaves small batches."""
    latency, per_path, pixels = 0.03, 1e-7, 1 << 16
    costs, sizer = PixelCosts(pixels), BatchSizer(1 << 18)
    done = 0
    for _ in range(30):
        n = sizer.next(1000 * pixels - done)
        for _ in range(2):      # probes ahead, as integrator._shrunk takes them
            pixel = costs.probe_point(done, n)
            if not costs.known(pixel):
                costs.probed(pixel, latency + per_path)
        n = costs.limit(done, n)
        seconds = latency + n * per_path
        sizer.record(n, seconds)
        costs.record(done, n, seconds)
        done += n
    assert n >= 0.5 * min(1 << 18, (TARGET_SECONDS - latency) / per_path), n
