"""SIGINT, SIGTERM and SIGHUP for the command line: stop soon, keep what was rendered.

Ctrl-C, `kill`, `docker stop`, a batch scheduler's time-out and a closed terminal all mean
"stop": none of them should print a traceback, lose finished samples or leave a half-written
file. The process is in one of three modes:

  start-up  (the default) a signal raises Interrupted, which main() turns into one line and
            the exit code; nothing has been rendered, so nothing is written
  noting    (while rendering) a signal is only noted; the render loop asks requested()
            between bounces, stops, and the partial image is written
  writing   (while writing outputs) a signal is noted and acted on once the files are whole

A blocking call (a device wait, a program build) holds the main thread, where Python runs
its signal handlers, so a watchdog thread also hears every signal through the wakeup fd: in
start-up mode it ends the process if main() has not within GRACE_SECONDS, and a second
signal while rendering ends it at once (the user asked twice; the partial image is given
up). Exit codes follow the shell's 128 + signal number.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
import time
from contextlib import contextmanager

SIGNALS = tuple(s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None))
                if s is not None)
GRACE_SECONDS = 1.0
REPEAT_SECONDS = 0.5    # the same signal again within this is the same request


def exit_code(signum: int) -> int:
    return 128 + int(signum)


def name(signum: int) -> str:
    return signal.Signals(signum).name


class Interrupted(BaseException):
    """A stop signal during start-up. BaseException, like KeyboardInterrupt, so that the
    `except Exception` around file readers does not swallow it."""

    def __init__(self, signum: int):
        super().__init__(name(signum))
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return exit_code(self.signum)


class _State:
    signum = None          # the first stop signal received, if any
    mode = "start-up"
    installed = False
    heard = 0              # signals the watchdog has seen
    acknowledged = False   # main() has reported the stop: the watchdog must not again
    last_signum = None     # the last signal the watchdog counted, and when
    last_time = 0.0


_state = _State()


def requested() -> bool:
    """Whether a stop signal has arrived (the render loop's stop(), polled between
    bounces; it also puts our handlers back, see _reassert)."""
    _reassert()
    return _state.signum is not None


def _reassert() -> None:
    """Install our handlers again. LLVM, inside PoCL's compiler (used first after
    install(): the device probe, program builds, PoCL's per-kernel compiles in the first
    batches), registers its own handlers for SIGINT, SIGTERM and SIGHUP with SA_RESETHAND
    and SA_NODEFER, once per process: a signal resets the disposition to the default
    before LLVM's handler passes it back to ours, so a second one microseconds later
    (`timeout` and `kill -- -PGID` send two) killed the process with nothing written (1
    run in 3 to 10 of test_a_signal_sent_twice_at_once_is_one_stop). LLVM does not
    register again once it believes its handlers are in place, so after the first
    compiles ours stay. Main thread only (render loops poll requested() there)."""
    if _state.installed and threading.current_thread() is threading.main_thread():
        for sig in SIGNALS:
            signal.signal(sig, _handle)


def received():
    """The first stop signal received, or None."""
    return _state.signum


def _handle(signum, _frame):
    if _state.signum is None:
        _state.signum = signum
    if _state.mode == "start-up":
        raise Interrupted(signum)


def _force_exit(message: str, signum: int):
    try:
        os.write(2, f"\n{message}\n".encode())
    finally:
        os._exit(exit_code(signum))


def _force_exit_unless_acknowledged(message: str, signum: int):
    if not _state.acknowledged:
        _force_exit(message, signum)


def acknowledge() -> None:
    """main() has reported the stop and is exiting (interpreter shutdown may take longer
    than GRACE_SECONDS): the watchdog must not end it with a second message."""
    _state.acknowledged = True


def _watchdog(fd: int):
    while True:
        try:
            data = os.read(fd, 64)
        except OSError:
            return
        if not data:
            return
        for signum in data:
            if signum not in SIGNALS:
                continue
            now = time.monotonic()
            # `timeout`, `kill -- -PGID` and terminals send one stop to the process and
            # again to its group: the same signal twice within a moment is one request,
            # not a user insisting (D21 lost whole renders to the duplicate)
            if signum == _state.last_signum and now - _state.last_time < REPEAT_SECONDS:
                continue
            _state.last_signum, _state.last_time = signum, now
            _state.heard += 1
            first = _state.signum if _state.signum is not None else signum
            if _state.mode == "start-up":
                timer = threading.Timer(GRACE_SECONDS, _force_exit_unless_acknowledged,
                                        (startup_message(first), first))
                timer.daemon = True    # a main() that exits in time is not held up by it
                timer.start()
            elif _state.mode == "noting" and _state.heard > 1:
                _force_exit(f"{name(signum)} again: stopped at once, nothing written", first)


def _excepthook(kind, value, tb):
    """An exception that escapes after a stop signal (raised where no main() catches it,
    as in the imports before main runs, or turned into another one, as a C extension's
    ImportError 'initialization failed'): the same one line and exit code."""
    if _state.signum is not None:
        _force_exit(startup_message(_state.signum), _state.signum)
    sys.__excepthook__(kind, value, tb)


def _unraisablehook(unraisable):
    """An exception in a finalizer after a stop signal: an object whose __init__ the
    Interrupted cut short (pyopencl's cache dict, whose __del__ then misses its mutex)
    fails when it is collected. The process is already ending with its one line, so the
    interpreter's traceback of it is not printed."""
    if _state.signum is not None:
        return
    sys.__unraisablehook__(unraisable)


def startup_message(signum: int) -> str:
    return f"interrupted by {name(signum)} during start-up: nothing rendered, nothing written"


def install() -> None:
    """Take over the stop signals for this process (the command line only: a library must
    leave a caller's handlers alone)."""
    if _state.installed:
        return
    for sig in SIGNALS:
        signal.signal(sig, _handle)
    sys.excepthook = _excepthook
    sys.unraisablehook = _unraisablehook
    r, w = os.pipe()
    os.set_blocking(w, False)
    signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    threading.Thread(target=_watchdog, args=(r,), daemon=True, name="gpiscl-signals").start()
    _state.installed = True


@contextmanager
def _mode(mode: str):
    previous, _state.mode = _state.mode, mode
    try:
        yield
    finally:
        _state.mode = previous


@contextmanager
def rendering():
    """Around a render: start-up mode until the started() it yields is called (once the
    scene is compiled), noting from then on; the previous mode after."""
    previous = _state.mode

    def started():
        _reassert()   # the device and its programs were built since install()
        _state.mode = "noting"

    try:
        yield started
    finally:
        _state.mode = previous


def writing():
    """While writing outputs: a signal waits until the files are complete."""
    return _mode("writing")
