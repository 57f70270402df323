"""Many short runs of Python scripts (`python SCRIPT ARGS...`, e.g. every bench's --help) from one interpreter: it
imports torch once, then forks a child per run that executes the script as __main__ with its own argv, stdout,
stderr and exit code, as its own interpreter would. A bench's --help otherwise costs a fresh interpreter and a torch
import each (about 1.6 s of CPU, 36 of them in tests/test_bench_args.py).

    python tests/forked_scripts.py < [[script, arg, ...], ...]  ->  [[returncode, stdout, stderr], ...] (JSON)
"""

import json
import os
import subprocess
import sys
import tempfile


def run_scripts(runs: list[list[str]], cwd, timeout: float = 300) -> list[subprocess.CompletedProcess]:
    """Each run (a script's path, then its arguments) from one interpreter in `cwd`; CompletedProcess per run."""
    r = subprocess.run([sys.executable, __file__], input=json.dumps([[str(a) for a in run] for run in runs]),
                       capture_output=True, text=True, cwd=cwd, timeout=timeout)
    assert r.returncode == 0, r.stderr
    answers = json.loads(r.stdout)
    return [subprocess.CompletedProcess(run, code, out, err) for run, (code, out, err) in zip(runs, answers)]


def _child(script: str, args: list[str], out_fd: int, err_fd: int) -> None:
    """In the forked child: what `python script args` does, then exit without the parent's teardown."""
    import runpy
    import traceback
    os.dup2(out_fd, 1)
    os.dup2(err_fd, 2)
    sys.stdout = open(1, "w", closefd=False)
    sys.stderr = open(2, "w", closefd=False)
    sys.argv = [script, *args]
    sys.path[0] = os.path.dirname(os.path.abspath(script))   # as the interpreter puts the script's folder first
    code = 0
    try:
        runpy.run_path(script, run_name="__main__")
    except SystemExit as e:
        if e.code is None:
            code = 0
        elif isinstance(e.code, int):
            code = e.code
        else:
            print(e.code, file=sys.stderr)
            code = 1
    except BaseException:
        traceback.print_exc()
        code = 1
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(code)


def _main() -> None:
    import torch  # noqa: F401 (the import every bench makes, once here for every child)
    results = []
    for script, *args in json.load(sys.stdin):
        with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:
                _child(script, args, out.fileno(), err.fileno())
            _, status = os.waitpid(pid, 0)
            out.seek(0)
            err.seek(0)
            results.append([os.waitstatus_to_exitcode(status), out.read().decode(errors="replace"),
                            err.read().decode(errors="replace")])
    json.dump(results, sys.stdout)


if __name__ == "__main__":
    _main()
