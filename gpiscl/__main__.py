"""python -m gpiscl: the command line (gpiscl/cli/)."""
if __name__ == "__main__":
    # first, so that a signal during the imports below (pyopencl, numpy: slow) already
    # finds the handlers: one line and exit code 130/143/129, not a traceback
    from . import signals
    signals.install()
    import sys
    from .cli import main
    sys.exit(main())
