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
