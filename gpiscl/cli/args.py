"""The parser. argparse only splits strings into the API's argument types (an int, a
(width, height) pair); host/scene/arguments.py checks the values when the API gets them,
and as_cli() reports such an error as the command line spells the option."""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from ..host.errors import API_SOURCE, CLI_SOURCE, SceneError
from ..host.scene.arguments import NO_REALIZATION
from ..api import Scene, load_scene
from ..scenes import default_scene
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
    resolution[0]: ...` -> `<command line>: --resolution[0]: ...`, `settings['camera.fov']`
    as --set camera.fov, and another argument the reason names in backquotes, `cluster`,
    as --cluster."""
    if exc.file != API_SOURCE:
        return exc
    name = re.match(r"\w*", exc.key)[0]
    key = spelled[name] + exc.key[len(name):] if name in spelled else exc.key
    # a dict argument's entry, settings['render.nee'], as it was given: --set render.nee
    key = re.sub(r"^(--[\w-]+)\['(.*?)'\]", r"\1 \2", key)
    reason = re.sub(r"`(\w+)`", lambda m: spelled.get(m[1], m[0]), exc.reason)
    return SceneError(CLI_SOURCE, key, reason)


def resolution(text: str):
    """'640x480' -> (640, 480); '64' -> (64, 64)."""
    try:
        sizes = [int(v) for v in text.lower().split("x")]
    except ValueError:
        sizes = []
    if len(sizes) not in (1, 2):
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT or N for NxN, e.g. 512x512 "
                                         f"(got {text!r})")
    return sizes[0], sizes[-1]


def setting(text: str):
    """'render.nee=false' -> ('render.nee', False): the value is JSON, and a word that is
    not JSON a string (--set render.tonemap=filmic). The scene schema checks both."""
    key, equals, value = text.partition("=")
    if not equals or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, e.g. render.nee=false (got "
                                         f"{text!r})")
    try:
        return key.strip(), json.loads(value)
    except ValueError:
        return key.strip(), value


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
    p.add_argument("--resolution", type=resolution, help="WIDTHxHEIGHT, or N for NxN")
    p.add_argument("--device", help="OpenCL device: 'P:D' indices, a type (cpu, gpu, "
                   "accelerator) or a name fragment")
    p.add_argument("--set", type=setting, action="append", dest="settings",
                   metavar="KEY=VALUE",
                   help="set a scene value by its key path, VALUE as JSON (a bare word is a "
                   "string); repeat for more: --set render.max_depth=4 --set render.nee=false "
                   "--set camera.fov=30 --set 'shapes[0].bsdf.albedo=[1,0,0]'")
    p.add_argument("--exposure", type=float, default=0.0, help="PNG preview exposure (stops)")
    p.add_argument("--cluster", metavar="ADDRESS",
                   help=f"render the {cluster_what} on a Dask cluster: a running scheduler "
                   "(tcp://HOST:8786) or local:N (N worker processes for this run); the "
                   "same image bit for bit (needs: pip install 'gpiscl[distributed]')")


BUILT_IN = "the built-in scene"   # what the banner and the EXR header call it


def scene_of(a) -> Scene:
    """The scene render and uq were given, or the built-in scene (gpiscl/scenes.py)."""
    return load_scene(a.scene) if a.scene else Scene(default_scene(), BUILT_IN)


def settings_of(a) -> dict:
    """The --set options as the API's settings: the last of one key wins."""
    return dict(a.settings or ())
