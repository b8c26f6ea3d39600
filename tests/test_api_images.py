"""The API writes the array render() returns, and its preview curve is public (tonemap),
so a user's own image gets the PNG a render gets."""
import zlib

import numpy as np
import pytest

import gpiscl
from gpiscl.host.io.images import read_exr


def png_pixels(path, w, h) -> np.ndarray:
    """The RGB of an unfiltered 8-bit PNG as write_png writes it (one IDAT chunk)."""
    data = path.read_bytes()
    at = data.index(b"IDAT")
    size = int.from_bytes(data[at - 4:at], "big")
    raw = np.frombuffer(zlib.decompress(data[at + 4:at + 4 + size]), np.uint8)
    return raw.reshape(h, 1 + 3 * w)[:, 1:].reshape(h, w, 3)


def test_write_image_takes_the_array_render_returns(tmp_path):
    rgb = np.random.default_rng(0).uniform(0, 2, (3, 5, 3)).astype(np.float32)
    paths = gpiscl.write_image(tmp_path / "mine.exr", rgb, exposure=-1)
    assert paths["scene"] is None and not (tmp_path / "mine.scene.json").exists()
    ch = read_exr(paths["exr"])
    np.testing.assert_array_equal(np.stack([ch[c] for c in "RGB"], -1), rgb)
    np.testing.assert_array_equal(png_pixels(paths["png"], 5, 3), gpiscl.tonemap(rgb, -1))
    paths = gpiscl.write_image(tmp_path / "only.png", rgb)
    assert paths["exr"] is None and (tmp_path / "only.png").exists()


def test_tonemap_is_the_preview_curve():
    x = np.array([[[0.0, 0.5, 1.0], [4.0, 0.0031308, 0.25]]])
    out = gpiscl.tonemap(x)
    assert out.dtype == np.uint8 and out.shape == (1, 2, 3)
    assert out[0, 0].tolist() == [0, 188, 255] and out[0, 1, 0] == 255
    assert gpiscl.tonemap(x, exposure=1)[0, 1, 2] == out[0, 0, 1]   # 2 * 0.25 = 0.5
    assert gpiscl.tonemap(x, curve="filmic")[0, 1, 0] < 255        # rolls off, no clip


@pytest.mark.parametrize("call,key", [
    (lambda: gpiscl.tonemap(np.zeros((2, 2, 3)), curve="aces"), "curve"),
    (lambda: gpiscl.tonemap(np.zeros((2, 2))), "image"),
    (lambda: gpiscl.write_image("x.exr", np.zeros((2, 2, 4))), "result"),
    (lambda: gpiscl.write_image("x.exr", "abc"), "result"),
])
def test_a_bad_image_or_curve_is_a_scene_error_naming_it(call, key):
    with pytest.raises(gpiscl.SceneError) as info:
        call()
    assert info.value.key == key
