"""How a run ends when it does not finish: the one line on stderr and its exit code.

Bad input is a UsageError: one line, exit code 2. Ctrl-C is a KeyboardInterrupt, SIGTERM and SIGHUP (a `kill`,
`timeout`, a closed terminal) an Ended, a KeyboardInterrupt too, so every handler of one handles them: one line, exit
code 128 + the signal's number (130, 143, 129). A write error: one line, exit code 1 (os_error says it).

The runner's clean-up after the first signal must not be cut short by a second (sigint_ignored), and the end of a
worker pool must not be cut short by the first (signals_held: a pool left half-ended waits for ever in its
finaliser). Nor may an import: a KeyboardInterrupt raised inside one is turned into an ImportError by a C extension
that imports another (pybullet's numpy: "numpy._core.multiarray failed to import", a traceback) or swallowed by an
`except ImportError` (the signal lost), so while ending_signals runs, a signal that comes during an import of the
main thread takes effect once that import is done (its handler sees importlib's frames on the stack, holds it and
looks again 20 ms later: SIGALRM, _retry; no cost to the ~40,000 imports of cached modules a run makes). From the runner's first line (early_signals) to
its main(), a signal waits for main() (raise_pending). Torch-free: the runner imports this before its first line.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

ENDING = (signal.SIGTERM, signal.SIGHUP)   # the signals that end a run as Ctrl-C does
# the process whose handlers raise Ended (a forked child inherits them: see _ended); "defer": the handler records a
# signal in "pending" instead of raising it (before main()); one that comes during an import waits there too
# "signal": the last one they raised (a library's C++ wait, Ray's, may turn it into a plain KeyboardInterrupt)
_RUNNER = {"pid": None, "defer": False, "pending": None, "signal": None}
# importlib's frames: a signal whose handler finds one of them on the main thread's stack came during an import
_IMPORT_FILES = frozenset(("<frozen importlib._bootstrap>", "<frozen importlib._bootstrap_external>"))
RETRY_S = 0.02   # a signal held during an import is raised this long after, if the import is done (SIGALRM)


class UsageError(Exception):
    """Bad input: reported as one line and exit code 2."""


class Ended(KeyboardInterrupt):
    """SIGTERM or SIGHUP (a `kill`, `timeout`, a closed terminal): the run ends as on Ctrl-C, a KeyboardInterrupt to
    every handler of one, with exit code 128 + the signal's number."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _interruption(signum: int) -> KeyboardInterrupt:
    _RUNNER["signal"] = signum
    return KeyboardInterrupt() if signum == signal.SIGINT else Ended(signum)


def _importing(frame) -> bool:
    """Whether the main thread's stack, from `frame` down, is inside an import (importlib's own frames)."""
    while frame is not None:
        if frame.f_code.co_filename in _IMPORT_FILES:
            return True
        frame = frame.f_back
    return False


def _hold(signum: int) -> None:
    if _RUNNER["pending"] is None:   # the first one decides the exit code, as it would have
        _RUNNER["pending"] = signum


def _ended(signum, frame):
    if os.getpid() != _RUNNER["pid"]:   # a process forked before it reset its handlers: a pool's worker's way
        if signum == signal.SIGINT:     # (ignores Ctrl-C, dies of the others silently)
            signal.signal(signum, signal.SIG_IGN)
        else:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
        return
    if _RUNNER["defer"]:
        _hold(signum)
        return
    if _importing(frame if frame is not None else sys._getframe(1)):
        _hold(signum)
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)   # _retry: raised once the import is done
        return
    raise _interruption(signum)


def _retry(signum, frame):
    """SIGALRM while ending_signals runs: the signal held during an import, raised if that import is done, and if
    nothing holds that signal meanwhile (signals_held, sigint_ignored: then once they are done)."""
    pending = _RUNNER["pending"]
    if pending is None or os.getpid() != _RUNNER["pid"] or _RUNNER["defer"]:
        return
    if _importing(frame) or signal.getsignal(pending) is not _ended:
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)
        return
    raise_pending()


def raise_pending() -> None:
    """Raise the signal that came while signals were deferred (before main(), during an import), if one did."""
    signum, _RUNNER["pending"] = _RUNNER["pending"], None
    if signum is not None:
        raise _interruption(signum)


def early_signals() -> None:
    """The runner's first line (`python train/run.py`, before its imports): Ctrl-C, SIGTERM and SIGHUP from here
    to main() are recorded, not raised (an interrupted import is a traceback), and main() raises the first one where
    it says its one line. One ignored (nohup, a background job's Ctrl-C) stays ignored. Only before the interpreter
    reaches this line (its start, tens of milliseconds) does a signal end the process at its default."""
    if threading.current_thread() is not threading.main_thread():
        return
    _RUNNER["pid"], _RUNNER["defer"] = os.getpid(), True
    for sig in (signal.SIGINT, *ENDING):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, _ended)


def how(e: KeyboardInterrupt) -> tuple[str, int]:
    """(" by SIGTERM" or "", exit code) of an interruption: Ctrl-C 130, a signal 128 + its number (an Ended's own, or
    the last one ending_signals raised, where a library turned it into its own KeyboardInterrupt)."""
    signum = getattr(e, "signum", None) or _RUNNER["signal"] or signal.SIGINT
    return ("" if signum == signal.SIGINT else f" by {signal.Signals(signum).name}"), 128 + signum


@contextlib.contextmanager
def ending_signals():
    """SIGTERM and SIGHUP raise Ended, Ctrl-C KeyboardInterrupt, while the block runs; during an import of the main
    thread, once that import is done (SIGALRM is the block's, for that). Only the main thread may set handlers; one
    ignored, as under nohup, stays ignored; the previous handlers afterwards. A signal recorded before the block
    (early_signals) waits for raise_pending, which the block's owner calls where it can say its line. Yields a function
    that sets the handlers again, for after a library put its own in place (ray.init's SIGTERM handler)."""
    main = threading.current_thread() is threading.main_thread()
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, *ENDING)} if main else {}
    previous = {sig: h for sig, h in handlers.items() if h is not None}   # None: set outside Python, left as it is
    defer = _RUNNER["defer"]
    _RUNNER["signal"] = None

    def install():
        for sig, handler in previous.items():
            if handler is not signal.SIG_IGN and sig != signal.SIGALRM:
                signal.signal(sig, _ended)

    try:
        if main:
            _RUNNER["pid"], _RUNNER["defer"] = os.getpid(), False
            previous[signal.SIGALRM] = signal.signal(signal.SIGALRM, _retry)
        install()
        yield install
    finally:
        if main:
            signal.setitimer(signal.ITIMER_REAL, 0)
            _RUNNER["defer"] = defer
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


@contextlib.contextmanager
def sigint_ignored():
    """A second Ctrl-C (or SIGTERM, SIGHUP) must not interrupt the clean-up after the first (only the main thread may
    set handlers)."""
    main = threading.current_thread() is threading.main_thread()
    previous = {sig: signal.signal(sig, signal.SIG_IGN) for sig in (signal.SIGINT, *ENDING)} if main else {}
    try:
        yield
    finally:
        for sig, handler in previous.items():   # None: a handler not set from Python (the default's stand-in)
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


@contextlib.contextmanager
def signals_held():
    """Ctrl-C, SIGTERM and SIGHUP that arrive while the block runs take effect when it ends (their handler runs
    then, once), so the block is never cut off halfway: a worker pool started or ended halfway is left with idle
    processes holding its queue's lock, and its finaliser then waits on that lock for ever. Only where a Python
    handler would raise (the main thread; a handler that ignores or kills is left as it is). A process forked
    inside the block does what a pool's worker does: ignores Ctrl-C, dies of the others. Yields the signals it
    holds."""
    if threading.current_thread() is not threading.main_thread():
        yield frozenset()
        return
    owner, caught = os.getpid(), []

    def hold(signum, frame):
        if os.getpid() != owner:   # a child forked inside the block, before it set its own handlers
            if signum == signal.SIGINT:
                signal.signal(signum, signal.SIG_IGN)
            else:
                signal.signal(signum, signal.SIG_DFL)
                os.kill(os.getpid(), signum)
            return
        caught.append(signum)

    previous = {}
    for sig in (signal.SIGINT, *ENDING):
        handler = signal.getsignal(sig)
        if callable(handler):
            previous[sig] = signal.signal(sig, hold)
    try:
        yield frozenset(previous)   # the signals held
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if caught:
            previous[caught[0]](caught[0], None)


def console() -> None:
    """A closed stdout or stderr (`>&-`): /dev/null in its place. The run goes on without console output (its
    results are files; an error still sets the exit code), and no file the run opens can take fd 1 or 2, where
    pybullet's C output (sim/quiet.py) would write into it."""
    for fd, name in ((1, "stdout"), (2, "stderr")):
        try:
            os.fstat(fd)
            continue
        except OSError:
            pass
        null = os.open(os.devnull, os.O_WRONLY)
        if null != fd:
            os.dup2(null, fd)
            os.close(null)
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, "w", closefd=False))


def fresh_line(stream=None) -> str:
    """A newline where `stream` (default stdout, where the runner's progress goes) is a terminal, where a progress
    bar (or ^C) may have left the cursor mid-line; nothing in a log."""
    return "\n" if (stream or sys.stdout).isatty() else ""


def os_error(e: OSError) -> str:
    where = f" {e.filename}" if e.filename else ""
    return f"cannot write{where}: {e.strerror or e}"


def exit_now(code: int) -> None:
    """End the process with `code` once the runner has returned: everything is written, flushed and closed
    (checkpoints and summary.json fsynced and renamed, the logs closed, the worker processes ended), so the
    interpreter's teardown, a walk over torch's objects and modules that took 0.25 s of the default run's wall time
    (0.03 s this way), is spared; the memory goes back to the system either way."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError, AttributeError):   # a reader that went away (| head)
            stream.flush()
    os._exit(code)
