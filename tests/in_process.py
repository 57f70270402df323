"""train/run.py's main() in the test's own process, answered as subprocess.run would: no interpreter start and no
torch import per run (seconds each on a busy 2-core machine). For what a run does, not for what its process does
(exit by signal, orphans, a closed stdout): those tests keep the script's own process."""

import io
import types
from contextlib import redirect_stderr, redirect_stdout


def run_main(*args) -> types.SimpleNamespace:
    """`python train/run.py *args` as a call: its exit code, stdout and stderr (returncode, stdout, stderr)."""
    from train import run
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = run.main([str(a) for a in args])
    return types.SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


def wait_until_unlocked(out, seconds: float = 60) -> None:
    """Wait until no process holds --out's lock (DIR/.lock, flock): a SIGKILLed run's workers hold it until they
    see their parent gone and exit (tests/test_run_ending.py), a moment after the kill. A script's next run started
    a second later; a call in this process starts at once and would find the run still in use."""
    import fcntl
    import time
    from pathlib import Path
    deadline = time.monotonic() + seconds
    with open(Path(out) / ".lock", "rb") as f:
        while True:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                assert time.monotonic() < deadline, f"{out}'s lock still held {seconds} s after the kill"
                time.sleep(0.05)
                continue
            fcntl.flock(f, fcntl.LOCK_UN)
            return
