"""Paths ended by max_depth in the scatter stage are counted with the other failures
(RenderStats.depth_cut_paths) and named in the summary."""
from gpiscl import render_result


def scene(max_depth, inside):
    """Camera inside a closed diffuse sphere (every path scatters until max_depth), or
    outside it with nothing behind (every path escapes after at most one bounce)."""
    pos = [0, 0, 0] if inside else [0, 0, 20]
    return {"camera": {"position": pos, "look_at": [0, 0, -1], "up": [0, 1, 0], "fov": 30,
                       "resolution": [8, 8]},
            "render": {"spp": 2, "seed": 1, "max_depth": max_depth, "nee": False,
                       "russian_roulette": {"start_depth": 1000}},
            "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 5.0,
                        "bsdf": {"type": "diffuse", "albedo": 0.5}}],
            "lights": [{"type": "environment", "radiance": 1.0}]}


def test_paths_cut_at_max_depth_are_counted(device):
    res = render_result(scene(3, inside=True), device=device)
    assert res.stats.paths == 128
    assert res.stats.depth_cut_paths == 128, res.stats.summary()
    assert "128 ended by max_depth" in res.stats.summary()


def test_paths_that_escape_are_not(device):
    res = render_result(scene(3, inside=False), device=device)
    assert res.stats.depth_cut_paths == 0, res.stats.summary()
    assert "ended by max_depth" not in res.stats.summary()
