"""Every example scene (and the built-in default) renders the image it rendered before the
define-once redesign, bit for bit, on the device the reference was made on.

The reference (tests/data/unchanged_images.npz) holds each scene's mean image, standard
error and sample counts at 8x6 pixels, 4 spp, seed 7, with AOVs (film sums included), made by
`python tests/test_images_unchanged.py` on the commit before the redesign and made again,
in commits that say so, for intended changes (with paired renders that show them within
noise) and for a new CI machine (the device name is stored with it; on 2026-12-07 for
PoCL's haswell target, after checking this device renders the earlier code and the new
bit for bit alike except the two scenes a change meant to alter). On another device kind
(other rounding of exp, another vector width) a path can take another branch, so there
the test asks for agreement within noise: the whole image's summed difference against
its standard error, |z| < 5.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from gpiscl import load_scene, render_result
from gpiscl.scenes import default_scene

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = ROOT / "tests" / "data" / "unchanged_images.npz"
SCENES = sorted((ROOT / "scenes").glob("*.json"))
NAMES = ["default"] + [p.stem for p in SCENES]
AOVS = "depth,normal,albedo,position"


def render(name, device=None):
    scene = default_scene() if name == "default" else load_scene(ROOT / "scenes" / f"{name}.json")
    res = render_result(scene, spp=4, seed=7, resolution=(8, 6), device=device, aov=AOVS)
    img = res.image
    return {"mean": img.mean, "stderr": img.stderr, "count": img.count, "sum": img.sum,
            "sum_sq": img.sum_sq, "aov": img.aov}


@pytest.mark.parametrize("name", NAMES)
def test_example_scene_image_is_unchanged(device, name):
    ref = np.load(REFERENCE)
    got = render(name, device)
    if str(ref["device"]) == device.name:
        for key, value in got.items():
            np.testing.assert_array_equal(value, ref[f"{name}/{key}"], err_msg=f"{name}: {key}")
    else:
        # one z for the whole image: 4-spp per-pixel standard errors are too rough to test
        diff = np.sum(got["mean"] - ref[f"{name}/mean"])
        se = np.sqrt(np.sum(got["stderr"] ** 2 + ref[f"{name}/stderr"] ** 2)) + 1e-12
        assert abs(diff) / se < 5.0, f"{name}: image z {diff / se:.2f} on {device.name}"


if __name__ == "__main__":
    from gpiscl.host.render.device import Device
    dev = Device()
    out = {"device": np.array(dev.name)}
    for name in NAMES:
        for key, value in render(name, dev).items():
            out[f"{name}/{key}"] = value
        print(name, file=sys.stderr)
    np.savez_compressed(REFERENCE, **out)
