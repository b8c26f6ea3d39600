import struct
import zlib

import numpy as np
import pytest

from gpiscl.host.io.images import (read_exr, read_exr_rgb, tonemap_srgb8, write_exr,
                                 write_png)


def test_exr_round_trip_is_bit_exact(tmp_path):
    rng = np.random.default_rng(1)
    rgb = rng.standard_normal((7, 5, 3)).astype(np.float32) * 1e3
    rgb[0, 0] = [np.inf, -0.0, 1e-40]  # inf, signed zero and a denormal survive too
    stderr = rng.random((7, 5)).astype(np.float32)
    path = tmp_path / "a.exr"
    write_exr(path, rgb, {"stderr": stderr})
    channels = read_exr(path)
    assert set(channels) == {"R", "G", "B", "stderr"}
    assert all(c.dtype == np.float32 for c in channels.values())
    back = read_exr_rgb(path)
    assert back.shape == rgb.shape
    assert back.tobytes() == rgb.tobytes()
    assert channels["stderr"].tobytes() == stderr.tobytes()


def test_read_exr_rgb_requires_rgb(tmp_path):
    import OpenEXR
    path = tmp_path / "z.exr"
    OpenEXR.File({"type": OpenEXR.scanlineimage}, {"Z": np.zeros((2, 3), np.float32)}).write(
        str(path))
    with pytest.raises(ValueError, match="lacks channel"):
        read_exr_rgb(path)


def _decode_png(data: bytes):
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, chunks = 8, []
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        tag, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])
        assert crc == zlib.crc32(tag + body) & 0xFFFFFFFF
        chunks.append((tag, body))
        pos += 12 + length
    assert [t for t, _ in chunks][0] == b"IHDR" and chunks[-1][0] == b"IEND"
    w, h, depth, colour, comp, filt, interlace = struct.unpack(">IIBBBBB", chunks[0][1])
    assert (depth, colour, comp, filt, interlace) == (8, 2, 0, 0, 0)
    raw = zlib.decompress(b"".join(b for t, b in chunks if t == b"IDAT"))
    rows = np.frombuffer(raw, np.uint8).reshape(h, 1 + 3 * w)
    assert np.all(rows[:, 0] == 0)
    return rows[:, 1:].reshape(h, w, 3)


def test_png_decodes_to_written_pixels(tmp_path):
    img = np.random.default_rng(2).integers(0, 256, (6, 9, 3), dtype=np.uint8)
    path = tmp_path / "a.png"
    write_png(path, img)
    np.testing.assert_array_equal(_decode_png(path.read_bytes()), img)


def test_tonemap_srgb8():
    x = np.array([[[0.0, 1.0, 0.5], [2.0, 1e9, -1.0]]], np.float32)
    out = tonemap_srgb8(x)
    assert out.dtype == np.uint8 and out.shape == x.shape
    # 0.5 -> 1.055 * 0.5**(1/2.4) - 0.055 = 0.73536 -> 187.52
    np.testing.assert_array_equal(out, [[[0, 255, 188], [255, 255, 0]]])
    # one stop of exposure doubles the radiance
    np.testing.assert_array_equal(tonemap_srgb8(x / 2, exposure=1.0), out)
    # the linear toe of the sRGB curve: 0.002 -> 12.92 * 0.002 * 255 = 6.59
    assert tonemap_srgb8(np.full((1, 1, 3), 0.002))[0, 0, 0] == 7


def test_filmic_tonemap():
    """Hejl and Burgess-Dawson's curve: black stays black, 1.0 maps to its closed form,
    it rises monotonically and rolls highlights off below white instead of clipping."""
    x = np.array([[[0.0, 0.004, 1.0], [0.5, 4.0, 1e3]]])
    out = tonemap_srgb8(x, curve="filmic").astype(int)
    y1 = 0.996 * (6.2 * 0.996 + 0.5) / (0.996 * (6.2 * 0.996 + 1.7) + 0.06)
    assert out[0, 0, 0] == 0 and out[0, 0, 1] == 0 and out[0, 0, 2] == round(255 * y1)
    ramp = tonemap_srgb8(np.geomspace(1e-3, 1e3, 200).reshape(1, -1, 1).repeat(3, 2),
                         curve="filmic")[0, :, 0].astype(int)
    assert np.all(np.diff(ramp) >= 0) and ramp[-1] == 255
    assert tonemap_srgb8(np.full((1, 1, 3), 4.0), curve="filmic")[0, 0, 0] < 255
    np.testing.assert_array_equal(tonemap_srgb8(x / 2, 1.0, "filmic"), out)


# ---- Radiance .hdr (RGBE), the authors' environment-map format ---------------------------

def _rgbe_file(width, pixels, flat=True) -> bytes:
    """A Radiance file written by hand: header, resolution line, then flat (not
    run-length encoded) RGBE quadruples, top row first."""
    height = len(pixels) // width
    head = f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {height} +X {width}\n".encode()
    return head + bytes(b for quad in pixels for b in quad)


def test_hdr_reads_a_known_image(tmp_path):
    """Each channel is mantissa * 2^(exponent - 136) (Radiance's RGBE; exponent 0 is
    black), rows top first."""
    from gpiscl.host.io.radiance_hdr import read_hdr_rgb
    quads = [(128, 64, 32, 129), (255, 0, 1, 128), (0, 0, 0, 0),
             (10, 20, 30, 140), (200, 100, 50, 120), (1, 1, 1, 136)]
    path = tmp_path / "known.hdr"
    path.write_bytes(_rgbe_file(3, quads))
    expected = np.array([[0.0 if e == 0 else m * 2.0 ** (e - 136) for m in (r, g, b)]
                         for r, g, b, e in quads])
    rgb = read_hdr_rgb(path)
    assert rgb.shape == (2, 3, 3) and rgb.dtype == np.float32
    np.testing.assert_array_equal(rgb.reshape(-1, 3), expected.astype(np.float32))
    assert rgb[0, 0].tolist() == [1.0, 0.5, 0.25]  # 128 * 2^-7


def test_hdr_round_trip_keeps_representable_values(tmp_path):
    """write_hdr then read_hdr_rgb returns values RGBE holds exactly (a mantissa 128..255
    for the largest channel) bit for bit, including a run-length encoded wide image."""
    from gpiscl.host.io.radiance_hdr import read_hdr_rgb, write_hdr
    rng = np.random.default_rng(3)
    h, w = 5, 40  # 8 <= width < 32768: the writer run-length encodes the scanlines
    e = rng.integers(-6, 6, (h, w, 1))
    top = rng.integers(128, 256, (h, w, 1))
    rest = rng.integers(0, 256, (h, w, 2)) * (top > 0)
    mant = np.concatenate([top, np.minimum(rest, top)], axis=2)
    mant = np.take_along_axis(mant, rng.permuted(np.tile([0, 1, 2], (h, w, 1)), axis=2),
                              axis=2)
    rgb = (mant * 2.0 ** (e - 8)).astype(np.float32)
    rgb[1, 2] = 0.0
    path = tmp_path / "a.hdr"
    write_hdr(path, rgb)
    assert path.read_bytes().startswith(b"#?RADIANCE")
    back = read_hdr_rgb(path)
    assert back.tobytes() == rgb.tobytes()


@pytest.mark.parametrize("content,reason", [(b"", "empty file"),
                                            (b"P6\n2 2\n255\n" + bytes(12), "cannot read")])
def test_unreadable_hdr_is_a_one_line_reason(tmp_path, content, reason):
    from gpiscl.host.io.radiance_hdr import hdr_problem
    path = tmp_path / "bad.hdr"
    path.write_bytes(content)
    problem = hdr_problem(str(path))
    assert reason in problem and "\n" not in problem


def test_write_hdr_refuses_what_rgbe_cannot_hold(tmp_path):
    from gpiscl.host.io.radiance_hdr import write_hdr
    with pytest.raises(ValueError, match="non-negative"):
        write_hdr(tmp_path / "n.hdr", np.full((2, 2, 3), -1.0, np.float32))
