"""Measurement figures in the package's comments: how many comment lines carry one, per file.

    python tools/count_comment_evidence.py [--top 15] [--all]

Code comments state the contract and the why; the measurements behind them live in
docs/design/*.md beside the tool that reproduces them, where they can be dated and rerun.
This tool counts what leaks back into gpiscl/: it prints the comment lines, the lines
carrying a measurement figure, their density per 1000 comment lines, and the files with
the most such lines (each line shown). tests/test_comment_evidence.py keeps the density low.

Comment lines: in .py files, every line holding a comment token (whole-line or trailing)
and every line of a module, class or function docstring; in .h/.cl files, every line
spanned by a /* */ or // comment.

A measurement figure is one of (EVIDENCE below, case-insensitive):
  * a percentage:              "12%", "0.5 %"
  * a ratio of speed or cost:  "1.05x", "~6x", "x1.16", "3 times faster"
                               (not "16x16", "0x1f" or "2 x 2": sizes, hex, matrices)
  * a memory size:             "40 MB", "2 GiB", "512 KB"
  * a rate:                    "6,000 paths/s", "paths per CPU s, same run"
  * a reported measurement:    "(measured)", "measured: ...", "measured 5.6e8",
                               "measured on ...", "peak RSS" (not "the measured
                               throughput" or "measured from +y": what code does)
  * an experiment's timing:    "0.53 s", "12 ms", "4 min", "80 us"
A percentage, size or timing right after a bound word ("within 15%", "up to 4 KB",
"every 10 s", "<1%"; BOUND) is a limit the code keeps, not a result, and text in
backticks quotes code or a program's output. A numeric contract ("exact for degree 4",
"<= 1e-6 relative", "1 << 14 paths", "batches sized to ~0.5 s") so matches none of these,
and the tool needs no list of exceptions.
"""
from __future__ import annotations

import argparse
import ast
import io
import re
import sys
import tokenize
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "gpiscl"

# A figure after one of these words is a bound the code keeps, not a result it got.
BOUND = r"(?<!within\s)(?<!within\s~)(?<!up\sto\s)(?<!\sto\s)(?<!\sto\s~)(?<!least\s)(?<!most\s)" \
        r"(?<!below\s)(?<!above\s)(?<!under\s)(?<!every\s)(?<!than\s)(?<![<>=]\s)(?<![<>=])"
EVIDENCE = re.compile(rf"""
      {BOUND}(?<![\w.])\d+(?:\.\d+)?\s?%                  # percentage
    | (?<![\w.])~?\d+(?:\.\d+)?[x\u00d7](?![\w.])          # 1.05x, 3x (not 16x16, 0x1f, 2 x 2)
    | (?<![\w.])[x\u00d7]\d+\.\d+\b                       # x1.16
    | \b\d+(?:\.\d+)?\s?times\s(?:faster|slower|more|fewer|less)\b
    | {BOUND}(?<![\w.])\d+(?:\.\d+)?\+?\s?[KMGT]i?B\b      # memory sizes
    | \d\s?(?:k\s)?paths?\s?(?:per|/)\s?s(?:ec(?:ond)?)?\b  # rates: 6,000 paths/s
    | \bper\s(?:cpu\s)?s(?:ec(?:ond)?)?\b[,;)]             # "paths per CPU s, same run"
    | \(measured | \bmeasured(?=\s*[:),(~\d]|\s+(?:on|at|in|no|with|over)\b)
    | \bpeak\s+rss\b
    | {BOUND}(?<![\w.^])\d+(?:\.\d+)?\s?(?:s|ms|us|\u00b5s|min)\b(?![-/^]) # timings
""", re.I | re.X)
# text in backticks quotes code or a program's output, which is not a claim
QUOTED = re.compile(r"`[^`]*`")
C_COMMENT = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)


def python_comment_lines(text: str) -> dict[int, str]:
    """line number -> text of every comment or docstring line of a Python source."""
    lines = text.splitlines()
    found = {}
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            found[tok.start[0]] = tok.string
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) \
                and node.body and isinstance(node.body[0], ast.Expr) \
                and isinstance(node.body[0].value, ast.Constant) \
                and isinstance(node.body[0].value.value, str):
            doc = node.body[0]
            for n in range(doc.lineno, doc.end_lineno + 1):
                found[n] = lines[n - 1]
    return found


def c_comment_lines(text: str) -> dict[int, str]:
    """line number -> text of every line a C comment spans (the comment's part of it)."""
    found = {}
    for m in C_COMMENT.finditer(text):
        first = text.count("\n", 0, m.start()) + 1
        for offset, part in enumerate(m.group().split("\n")):
            found[first + offset] = found.get(first + offset, "") + part
    return found


def comment_lines(path: Path) -> dict[int, str]:
    text = path.read_text()
    return python_comment_lines(text) if path.suffix == ".py" else c_comment_lines(text)


def package_files(root: Path = PACKAGE):
    return sorted(p for p in root.rglob("*") if p.suffix in (".py", ".h", ".cl"))


def survey(root: Path = PACKAGE):
    """(comment line count, {file: [(line number, text), ...] of evidence lines})."""
    total, evidence = 0, {}
    for path in package_files(root):
        found = comment_lines(path)
        total += len(found)
        hits = [(n, t.strip()) for n, t in sorted(found.items())
                if EVIDENCE.search(QUOTED.sub("", t))]
        if hits:
            evidence[path.relative_to(root.parent).as_posix()] = hits
    return total, evidence


def density(root: Path = PACKAGE) -> float:
    total, evidence = survey(root)
    return 1000.0 * sum(map(len, evidence.values())) / max(total, 1)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=15, help="files to list (most lines first)")
    ap.add_argument("--all", action="store_true", help="list every file with a hit")
    args = ap.parse_args(argv)
    total, evidence = survey()
    count = sum(map(len, evidence.values()))
    print(f"{count} measurement lines in {total} comment lines of gpiscl/: "
          f"{1000.0 * count / max(total, 1):.1f} per 1000")
    ranked = sorted(evidence.items(), key=lambda kv: -len(kv[1]))
    for name, hits in ranked if args.all else ranked[:args.top]:
        print(f"\n{name}: {len(hits)}")
        for n, text in hits:
            found = ", ".join(m.group() for m in EVIDENCE.finditer(QUOTED.sub("", text)))
            print(f"  {n:5d}: {text[:100]}  [{found}]")
    return 0


if __name__ == "__main__":
    sys.exit(main())
