"""fs_march.h's FS_PROFILE work counters (tools/profile_grid_scenes.py): compiled in, they
change nothing the march does (the same image, bit for bit, and the same flights, values
and evaluations), and they add up: every adaptive step's first try has exactly one reason,
every step took at least one try, and every rule evaluation and value drawn ran the mean
program once."""
import copy
from pathlib import Path

import numpy as np
import pytest

from gpiscl.host.compile.scene import compile_scene
from gpiscl.host.layout import records as layouts
from gpiscl.host.render.integrator import WavefrontIntegrator
from gpiscl.host.scene.loading import load_scene

ROOT = Path(__file__).resolve().parent.parent


def render(device, name, monkeypatch, profile):
    if profile:
        monkeypatch.setenv("GPISCL_FS_PROFILE", "1")
    else:
        monkeypatch.delenv("GPISCL_FS_PROFILE", raising=False)
    data = copy.deepcopy(load_scene(ROOT / "scenes" / f"{name}.json").data)
    data["camera"]["resolution"] = [12, 12]
    scene = compile_scene(load_scene(data).data)
    integ = WavefrontIntegrator(device, scene, data["render"], None)
    res = integ.render(2)
    counts = {k: int(integ.counters_host[layouts.COUNTERS[k]])
              for k in layouts.FS_PROFILE_COUNTERS}
    return res, counts


# csg_baked: sigma(x) grid and cubic mean (fs_moments' shared row numbers); knob: a
# stationary prior with sphere tracing hops
@pytest.mark.parametrize("name", ["csg_baked", "knob"])
def test_profile_counters_change_nothing_and_add_up(device, monkeypatch, name):
    plain, zero = render(device, name, monkeypatch, profile=False)
    prof, c = render(device, name, monkeypatch, profile=True)
    assert not any(zero.values())                  # off: no counting code at all
    np.testing.assert_array_equal(prof.image.mean, plain.image.mean)
    for k in ("fs_flights", "fs_samples", "fs_evals"):
        assert getattr(prof.stats, k) == getattr(plain.stats, k)
    assert c["fs_steps"] > 0
    assert c["fs_steps"] == c["fs_cap_mean"] + c["fs_cap_hmax"] + c["fs_cap_grow"] + c["fs_cap_end"]
    # a step the prior mean certifies takes no rule try (fs_mean_step): the knob's by its
    # far balls and monotone stretches, csg_baked's by balls sized under its sigma field
    assert c["fs_tries"] + c["fs_cert_steps"] >= c["fs_steps"] >= c["fs_cert_steps"] > 0
    assert c["fs_near_steps"] <= c["fs_steps"]
    # one run per rule evaluation and per value drawn at a step (root points excluded),
    # plus the starts whose mean was no row's
    assert c["fs_mean_evals"] >= prof.stats.fs_evals + c["fs_steps"]
    assert c["fs_mean_evals"] <= prof.stats.fs_evals + prof.stats.fs_samples + prof.stats.fs_flights
    # the occupancy clip (gpis_proxy.h): every flight came through a proxy entry that the
    # clip kept, most after a march, and every march evaluated the mean at least once;
    # the occupancy cells leave some entries without a march (rays that miss every set cell)
    assert c["fs_occ_entries"] >= prof.stats.fs_flights
    assert c["fs_occ_entries"] > c["fs_occ_marches"] > 0
    assert c["fs_occ_evals"] >= c["fs_occ_marches"]
