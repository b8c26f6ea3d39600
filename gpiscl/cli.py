"""The `gpiscl` console script (setup.cfg entry point): the same as `python -m gpiscl`."""
import sys


def console():
    # the signal handlers first, before the heavy imports of the command line (gpiscl/signals.py)
    from . import signals
    signals.install()
    from .__main__ import main
    sys.exit(main())
