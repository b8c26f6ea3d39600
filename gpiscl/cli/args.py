"""The parser. argparse only splits strings into the API's argument types (an int, a
(width, height) pair); host/scene/arguments.py checks the values when the API gets them,
and as_cli() reports such an error as the command line spells the option."""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from ..host.errors import API_SOURCE, CLI_SOURCE, SceneError
from ..host.scene.arguments import NO_REALIZATION
from ..version import __version__


class Parser(argparse.ArgumentParser):
    """Usage mistakes as one line, like every other error (argparse prints the whole
    usage first), exit code 2; and how each argument is spelled (as_cli)."""

    def __init__(self, *a, **kw):
        self.spelled = {}
        super().__init__(*a, **kw)

    def add_argument(self, *names, **kw):
        action = super().add_argument(*names, **kw)
        self.spelled[action.dest] = (max(action.option_strings, key=len)
                                     if action.option_strings else action.metavar or action.dest)
        return action

    def error(self, message):
        self.exit(2, f"error: {self.prog}: {message} (see --help)\n")


def build(commands) -> Parser:
    """The parser of every command: each module's add_parser(sub) -> its parser."""
    # the console script is `gpiscl`; `python -m gpiscl` runs gpiscl/__main__.py
    prog = "gpiscl" if Path(sys.argv[0]).name == "gpiscl" else "python -m gpiscl"
    ap = Parser(prog=prog, description="Render Gaussian Process Implicit Surfaces.")
    ap.add_argument("--version", action="version", version=f"gpiscl {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    for command in commands:
        p = command.add_parser(sub)
        p.set_defaults(run=command.run, spelled=p.spelled)
    return ap


def as_cli(exc: SceneError, spelled: dict) -> SceneError:
    """An error about an API argument as the command line names it: `<arguments>:
    resolution[0]: ...` -> `<command line>: --resolution[0]: ...`, and another argument
    the reason names in backquotes, `cluster`, as --cluster."""
    if exc.file != API_SOURCE:
        return exc
    name = re.match(r"\w*", exc.key)[0]
    key = spelled[name] + exc.key[len(name):] if name in spelled else exc.key
    reason = re.sub(r"`(\w+)`", lambda m: spelled.get(m[1], m[0]), exc.reason)
    return SceneError(CLI_SOURCE, key, reason)


def resolution(text: str):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 512x512 (got {text!r})")


def int_or_none(text: str):
    if text.lower() == NO_REALIZATION:
        return NO_REALIZATION
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer or '{NO_REALIZATION}', got "
                                         f"'{text}'") from None


def int_list(text: str) -> list:
    try:
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected integers separated by commas (got "
                                         f"{text!r})") from None


def add_scene_options(p, cluster_what: str):
    """The options render and uq share."""
    p.add_argument("scene", nargs="?", help="scene JSON file (default: the built-in scene)")
    p.add_argument("--seed", type=int, help="random seed")
    p.add_argument("--resolution", type=resolution, help="WIDTHxHEIGHT")
    p.add_argument("--device", help="OpenCL device: 'P:D' indices or a name fragment")
    p.add_argument("--exposure", type=float, default=0.0, help="PNG preview exposure (stops)")
    p.add_argument("--cluster", metavar="ADDRESS",
                   help=f"render the {cluster_what} on a Dask cluster: a running scheduler "
                   "(tcp://HOST:8786) or local:N (N worker processes for this run); the "
                   "same image bit for bit (needs: pip install 'gpiscl[distributed]')")
