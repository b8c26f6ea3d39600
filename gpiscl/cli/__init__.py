"""The command line, a shell over the Python API (gpiscl/api.py): `python -m gpiscl` and
the `gpiscl` console script (setup.cfg). Each command is one module with add_parser(sub)
and run(args) -> exit code; adding one is a module and a line in COMMANDS. A mistake is
one line and exit code 2; a stop signal, one line and 128 + its number (gpiscl/signals.py).
"""
from __future__ import annotations

import importlib
import sys

from .. import signals
from ..host.errors import DeviceError, SceneError

# in the order --help lists them; imported by main, after console() installed the signal
# handlers (gpiscl/signals.py)
COMMANDS = ("render", "devices", "uq", "sample", "density", "convert_tungsten",
            "convert_vdb")


def main(argv=None) -> int:
    parsed = None
    try:
        from . import args
        modules = [importlib.import_module(f"{__name__}.{name}") for name in COMMANDS]
        parsed = args.build(modules).parse_args(argv)
        return parsed.run(parsed)
    except (SceneError, DeviceError) as exc:
        if isinstance(exc, SceneError) and parsed is not None:
            exc = args.as_cli(exc, parsed.spelled)   # as the command line names options
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except BaseException:
        # a stop signal during start-up: Interrupted itself, or what it became on the way
        # out of a C extension (an ImportError, a pyopencl error)
        stopped_by = signals.received()
        if stopped_by is None:
            raise
        signals.acknowledge()
        print(signals.startup_message(stopped_by), file=sys.stderr)
        return signals.exit_code(stopped_by)


def console():
    """The `gpiscl` console script (setup.cfg entry point): the same as python -m gpiscl."""
    signals.install()   # before the commands' slow imports (pyopencl, numpy)
    sys.exit(main())
