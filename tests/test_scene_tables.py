"""compile/gpis.py: each GPIS object's share of the scene tables lands where its GpisObject
says (docs/design/scene-tables.md): mesh planes in proxy_planes, colour and emission fields
in field_nodes (record 0: none), mean programs alone in mean_nodes."""
from pathlib import Path

import numpy as np

from gpiscl import load_scene
from gpiscl.host.compile.scene import compile_scene
from gpiscl.host.kinds.colour_fields import COLOUR_FIELDS
from gpiscl.host.layout.gp_records import MEAN_KINDS
from gpiscl.host.scene.proxies import analyse

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def test_mesh_proxy_planes_are_the_proxy_analysis():
    data = load_scene(SCENES / "wedge_volume.json").data
    gpis = compile_scene(data).gpis
    proxy = next(s for s in data["shapes"] if s["type"] == "gpis")["proxy"]
    planes = analyse(proxy)[0]
    o = gpis.objects[0]
    got = gpis.proxy_planes[o["proxy_first"]:o["proxy_first"] + o["proxy_count"]]
    assert len(planes) == o["proxy_count"] > 3
    np.testing.assert_array_equal(got, planes.astype(np.float32))
    assert list(gpis.posterior_rows) == [0] and len(gpis.posterior_obs) == 0


def test_colour_fields_have_their_own_table():
    gpis = compile_scene(load_scene(SCENES / "ws_color_emission.json").data).gpis
    kinds = gpis.field_nodes["kind"]
    assert kinds[0] == 0 and gpis.field_nodes[0].tobytes() == bytes(gpis.field_nodes.itemsize)
    box, torus = gpis.objects
    assert (box["emission_field"], torus["color_field"]) == (0, 0)
    assert kinds[box["color_field"]] == COLOUR_FIELDS.id("checker")
    assert kinds[torus["emission_field"]] == COLOUR_FIELDS.id("gradient")
    # the mean-node array holds the two mean programs and nothing else
    programs = [gpis.mean_nodes[o["mean_first"]:o["mean_first"] + o["mean_count"]]
                for o in gpis.objects]
    assert sum(map(len, programs)) == len(gpis.mean_nodes)
    mean_ids = set(MEAN_KINDS.values())
    assert all(set(p["kind"]) <= mean_ids for p in programs)
