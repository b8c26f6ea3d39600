"""A seeded fuzz test over mutated example scenes: whatever a scene file says, the command
line either renders a finite image (exit 0) or refuses with exactly one line (exit 2), and
never raises (a traceback).

Each case copies a shipped scene and replaces one to three values, anywhere in it, with
something hostile (NaN, infinities, huge and tiny numbers, negative counts, wrong types,
missing keys, paths outside the project); main() runs in this process at 4x4 pixels and
1 spp, so the few hundred cases take well under a minute.
"""
import copy
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gpiscl.cli import main
from gpiscl.host.io.images import read_exr

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "scenes").glob("*.json"))
CASES = 300
HOSTILE = [0, -1, 1, 0.5, -0.5, 1e-300, 1e300, -1e300, 1e19, -1e19, 3.5e38, float("nan"),
           float("inf"), -float("inf"), 2**31, 2**63, -(2**31), True, False, None, "", "x",
           "../../../etc/passwd", "/dev/zero", [], {}, [1, 2], [0, 0, 0], [1e30, 0, 0],
           {"type": "sphere"}, {"type": "union"}]


def nodes(doc, path=()):
    """Every (container, key) pair of a JSON document."""
    if isinstance(doc, dict):
        items = doc.items()
    elif isinstance(doc, list):
        items = enumerate(doc)
    else:
        return
    for k, v in list(items):
        yield doc, k
        yield from nodes(v, path + (k,))


def mutate(doc, rng):
    doc = copy.deepcopy(doc)
    for _ in range(rng.integers(1, 4)):
        spots = list(nodes(doc))
        parent, key = spots[rng.integers(len(spots))]
        old = parent[key]
        roll = rng.random()
        if roll < 0.15 and isinstance(parent, dict):
            del parent[key]
        elif roll < 0.35 and isinstance(old, (int, float)) and not isinstance(old, bool):
            parent[key] = old * float(rng.choice([-1, 0, 1e-30, 1e6, 1e30]))
        else:
            parent[key] = copy.deepcopy(HOSTILE[rng.integers(len(HOSTILE))])
    return doc


# a NaN or overflow warning means a bad value got past the checks
@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_mutated_scenes_render_or_fail_in_one_line(tmp_path, capsys):
    rng = np.random.default_rng(12)
    originals = {p: json.loads(p.read_text()) for p in SCENES}
    # a copy of scenes/ (600 KB of assets), so relative asset paths resolve and the
    # checkout is never written to
    work = tmp_path / "scenes"
    shutil.copytree(ROOT / "scenes", work)
    outcomes = {0: 0, 2: 0}
    for case in range(CASES):
        source = SCENES[rng.integers(len(SCENES))]
        doc = mutate(originals[source], rng)
        path = work / f"fuzz_{case}.json"
        out = tmp_path / f"{case}.exr"
        path.write_text(json.dumps(doc))
        capsys.readouterr()
        code = main(["render", str(path), "-o", str(out), "--resolution", "4x4",
                     "--spp", "1", "--time-limit", "5"])
        err = capsys.readouterr().err
        what = f"case {case} from {source.name}: {json.dumps(doc)[:2000]}\n{err}"
        assert code in (0, 2), what
        outcomes[code] += 1
        if code == 2:
            lines = err.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("error: "), what
        else:
            rgb = np.stack([read_exr(out)[c] for c in "RGB"], -1)
            assert rgb.shape == (4, 4, 3) and np.isfinite(rgb).all(), what
            assert " non-finite (recorded as 0)" not in err or "failed paths: 0 " in err, what
    # both outcomes occur: the mutations are neither all fatal nor all harmless
    assert outcomes[0] >= CASES // 20 and outcomes[2] >= CASES // 5, outcomes
    print(outcomes)
