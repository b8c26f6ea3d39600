"""No function-space hit is ever killed for a normal facing away from the ray: the slope
along the ray is drawn from its law at a down-crossing (fs_march.h), negative by
construction, under every memory model and micro-BSDF (the old global model drew it
unconditioned on the crossing: about one path in 10^4 was killed)."""
import numpy as np
import pytest

from gpiscl.testing.scenes import MEMORIES, function_space_sampler, gpis_scene, render_checked

ENV = [{"type": "environment", "radiance": 1.0}]


@pytest.mark.parametrize("memory", MEMORIES)
def test_rough_conductor_paths_are_never_killed(device, memory):
    metal = {"type": "rough_conductor", "material": "Au", "roughness": 0.3}
    scene = gpis_scene(function_space_sampler(memory), "diffuse", 1.0, ENV, spp=16)
    scene["shapes"][0]["bsdf"] = metal
    res = render_checked(scene, device)
    assert res.stats.killed_paths == 0, res.stats.summary()
    assert res.stats.rays > 1.5 * res.stats.paths


def test_global_mirror_furnace_at_many_hits(device):
    """~3 10^4 GPIS hits under global memory (the old rate would kill ~3 paths): exactly
    1 per path, nothing killed."""
    scene = gpis_scene(function_space_sampler("global"), "mirror", 1.0, ENV, spp=128)
    res = render_checked(scene, device)
    assert res.stats.killed_paths == 0, res.stats.summary()
    assert res.stats.rays > 1.8 * res.stats.paths
    np.testing.assert_allclose(res.image.mean, 1.0, rtol=1e-6)
