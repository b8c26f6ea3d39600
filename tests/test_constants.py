"""Host and device numbers have one source: layout/constants.py and layout/random_slots.py
emit them, the kernels only use their names."""
import re
from pathlib import Path

import pytest

from gpiscl.host.layout import constants, function_space_records, gp_records, random_slots
from gpiscl.host.layout import records
from gpiscl.host.render.program_sources import KERNEL_DIR

SOURCES = sorted(p for p in KERNEL_DIR.rglob("*") if p.suffix in (".h", ".cl"))
_COMMENT_OR_STRING = re.compile(r'/\*.*?\*/|//[^\n]*|"(?:\\.|[^"\\])*"', re.S)
_NUMBER = re.compile(r"(?<![\w.])(0[xX][0-9a-fA-F]+|(?:\d+\.\d*|\.\d+|\d+)(?:[eE][+-]?\d+)?)"
                     r"[uUlLfF]*(?![\w.])")
_DEFINE = re.compile(r"^\s*#\s*define\s+(\w+)", re.M)

# Literals equal to a host constant that mean something else (checked by hand, 2026-12):
ANYWHERE = {0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 8.0}   # indices, small counts, formula coefficients
IN_FILE = {
    (16.0, "fs_march.h"): "a squared distance cut-off, 4 length scales",
    (16.0, "fs_markov.h"): "series coefficients and a loop over 4-term groups",
    (24.0, "fs_markov.h"): "1 / 4!",
    (16.0, "ws_features.h"): "vector widths and byte shifts",
    (24.0, "ws_features.h"): "a byte shift",
    (10.0, "ws_features.h"): "Philox's 10 rounds; lane indices",
    (1024.0, "ws_features.h"): "WS_CACHE_FEATURES, a cache size",
    (0.001, "gp_mean.h"): "a float pad in index units",
    (32.0, "gpis_proxy.h"): "OCC_MAX_STEPS, the occupancy marches' own budget",
    (66.0, "gpis_fields.h"): "a colour-field kind",
    (1.5, "fs_march.h"): "the growth ladder's middle factor",
    (1.5, "gp_kernel.h"): "the non-stationary prefactor's power 3/2",
    (1.5, "matern32.h"): "Matern's nu = 3/2",
    (6.0, "fs_markov.h"): "1 / 3!",
    (6.0, "gp_mean.h"): "the cubic B-spline weights' 1 / 6",
    (6.0, "thin_plate.h"): "the thin-plate kernel's derivative coefficients",
    (6.0, "ws_features.h"): "a lane index",
    (6.0, "ws_posterior.h"): "six jet components",
}


def _code(path: Path) -> str:
    """The file without comments and strings, line breaks kept."""
    return _COMMENT_OR_STRING.sub(lambda m: "\n" * m.group(0).count("\n"), path.read_text())


def _host_values() -> dict:
    values = {float(c.value): c.name for c in constants.CONSTANTS}
    for plan in (random_slots.NORMAL_SLOTS, random_slots.UNIFORM_BLOCKS):
        for r in plan.ranges:
            values.setdefault(float(r.first), r.c_name)
            values.setdefault(float(r.count), f"{r.c_name}_COUNT")
    return values


def _literal(text: str) -> float:
    return float(int(text, 16)) if text.lower().startswith("0x") else float(text)


def test_no_kernel_literal_restates_a_host_constant():
    host, found = _host_values(), []
    for path in SOURCES:
        for line_no, line in enumerate(_code(path).split("\n"), 1):
            for m in _NUMBER.finditer(line):
                v = _literal(m.group(1))
                if v in host and v not in ANYWHERE and (v, path.name) not in IN_FILE:
                    found.append(f"{path.name}:{line_no}: {m.group(0)} ({host[v]})")
    assert not found, "literals that should be the constant's name:\n" + "\n".join(found)


def test_the_scan_sees_a_restated_constant(tmp_path):
    # the scan above would report the step rule's node written out by hand
    path = tmp_path / "x.h"
    path.write_text("/* 0.3550510257216822 */ double u = 0.3550510257216822 * h;\n")
    values = [_literal(m.group(1)) for m in _NUMBER.finditer(_code(path))]
    assert values == [constants.FS_RULE_NODE1]


def _generated_names() -> set:
    text = (records.c_header() + function_space_records.c_declarations()
            + gp_records.c_declarations())
    return set(_DEFINE.findall(text))


def test_no_header_defines_a_generated_name():
    generated = _generated_names()
    restated = [f"{p.name}: {name}" for p in SOURCES for name in _DEFINE.findall(_code(p))
                if name in generated]
    assert not restated, "defined in Python and again in a header:\n" + "\n".join(restated)


def test_every_constant_is_emitted_once():
    names = [c.name for c in constants.CONSTANTS]
    assert len(names) == len(set(names))
    text = records.c_header()
    for name in names:
        assert len(re.findall(rf"#define {name} ", text)) == 1, name


@pytest.mark.parametrize("c", constants.CONSTANTS, ids=lambda c: c.name)
def test_float_literals_read_back_exactly(c):
    if c.ctype == "double":
        assert float(c.c_literal()) == c.value
    else:
        text = c.c_literal().rstrip("u")
        assert int(text, 0) == c.value


def test_slot_plans_are_disjoint_and_a_clash_is_found():
    assert random_slots.overlaps(random_slots.NORMAL_SLOTS, random_slots.UNIFORM_BLOCKS) == []
    # normal slots 2048.. share Philox blocks with the uniform blocks from 1024
    clash = random_slots.SlotPlan("normal", 2, (("late", "X", 2049, 2),))
    found = {frozenset(pair) for pair in random_slots.overlaps(clash, random_slots.UNIFORM_BLOCKS)}
    assert found == {frozenset(("normal.late", "uniform.grid")),
                     frozenset(("normal.late", "uniform.start"))}


def test_markov_refinement_fits_its_slots():
    # fs_markov.h: 4 slots a point for Matern 5/2, and a 2 l_d step needs the minimum
    assert random_slots.NORMAL_SLOTS["refine"].count // 4 >= constants.FS_MIN_BISECT
