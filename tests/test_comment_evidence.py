"""Measurement figures stay out of the package's comments: code comments keep the contract
and the why, the numbers that justify them live in docs/design/*.md beside the tool that
reproduces them (tools/count_comment_evidence.py defines what counts and lists the lines)."""
import importlib.util
from pathlib import Path

TOOL = Path(__file__).resolve().parents[1] / "tools" / "count_comment_evidence.py"
spec = importlib.util.spec_from_file_location("count_comment_evidence", TOOL)
evidence = importlib.util.module_from_spec(spec)
spec.loader.exec_module(evidence)


def test_few_comment_lines_carry_measurements():
    total, found = evidence.survey()
    count = sum(map(len, found.values()))
    worst = sorted(found.items(), key=lambda kv: -len(kv[1]))[:5]
    assert 1000 * count < 5 * total, (
        f"{count} of {total} comment lines carry measurement figures; move them to "
        "docs/design/*.md (python tools/count_comment_evidence.py lists them): "
        + "; ".join(f"{name} {len(hits)}" for name, hits in worst))


def test_the_pattern_tells_evidence_from_contracts():
    hit = evidence.EVIDENCE.search
    for line in ("4 lanes were 6-10% faster", "1.05x", "x1.16", "~1000x", "took 12 s",
                 "(measured)", "erfcf, measured: 18", "~100+ MB", "2.7 GB for 8k",
                 "331 paths/s", "paths per CPU s, same run", "peak RSS", "~30 ms a batch"):
        assert hit(line), line
    for line in ("exact for degree 4", "<= 1e-6 relative", "a 16x16 render", "the leading 2 x 2",
                 "0x1f", "within 15%", "up to 4 KB", "accurate to <1%", "every 10 s",
                 "the spectral measure", "the measured throughput", "measured from +y",
                 "4 spp", "2^18 paths", "batches sized to ~0.5 s", "x1 = x0 + t d"):
        assert not hit(line), line
    assert not hit(evidence.QUOTED.sub("", "e.g. `12.5/64 spp (20 %), 41 s`"))


def test_comment_lines_are_found_in_python_and_c():
    py = '"""Doc\nline two."""\nx = 1  # trailing\ny = "# not a comment"\n# whole\n'
    assert sorted(evidence.python_comment_lines(py)) == [1, 2, 3, 5]
    c = "int a; /* one\n * two */ int b;\n// three\nchar *s;\n"
    assert sorted(evidence.c_comment_lines(c)) == [1, 2, 3]
