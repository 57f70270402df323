"""A sweep from its flags to its exit code: the sweep file and DIR checked, what DIR holds surveyed (and, on
--resume, the code that wrote it compared with this checkout's), Ray started, the cells run and written, the run
recorded in DIR/sweep.json, and how it ended said in one line (docs/sweeps.md "How a sweep ends").

Exit codes: 0 done, 2 bad input (before Ray starts and before anything is written), 1 a cell or a write failed,
130 / 143 / 129 Ctrl-C / SIGTERM / SIGHUP.
"""

from __future__ import annotations

import os
import shlex
import signal
import socket
import sys
import time

from train.common.exits import Ended, ending_signals, fresh_line, how, sigint_ignored
from train.sweeps import provenance
from train.sweeps.cluster import (
    JoinError,
    Progress,
    describe,
    run_sweep,
    silence_stderr,
    start_ray,
    stop_ray,
)
from train.sweeps.process_tree import ProcessTree
from train.sweeps.spec import FORMAT, PROG, SweepError, load_sweep
from train.sweeps.store import (
    check_commits,
    check_out,
    needs_pyarrow,
    survey,
    write_configs,
    write_record,
)


def main(parse_args, argv: list[str], on_cell=None, console: bool = False) -> int:
    """The sweep that parse_args(argv) names (parse_args: the script's flags; SweepError for bad ones).
    on_cell(cell): called after each cell is written (tests). console: the command line's own sweep (its stderr is
    silenced after its last line, while Ray tears down)."""
    with ending_signals() as reinstall:
        return _main(parse_args, argv, on_cell, reinstall, console)


def command_line(argv: list[str], console: bool) -> str:
    """The sweep's command as typed (recorded in DIR/sweep.json and the report): the console command or script
    named as it was run, for a call from Python the script's."""
    first = sys.argv[0] if console and sys.argv and sys.argv[0] else PROG
    if os.path.basename(first).startswith("aesop-"):   # a console command's absolute path: its name
        first = os.path.basename(first)
    return shlex.join([first, *argv])


def _start(a) -> bool:
    """start_ray, a SIGTERM during ray.init (Ray's handler: sys.exit(15)) turned into Ended."""
    try:
        return start_ray(a.address, a.workers)
    except SystemExit as e:
        if e.code == signal.SIGTERM:
            raise Ended(signal.SIGTERM) from None
        raise


def _main(parse_args, argv, on_cell, reinstall, console) -> int:
    owns_ray = False   # this process started (or joined) Ray, and so ends it
    tree = None        # the processes started since (ProcessTree): none outlives the sweep
    progress = None
    out = None
    n_cells = 0
    record, run = None, None   # DIR/sweep.json as written, and this run's entry in it
    try:
        try:
            a = parse_args(argv)
            spec, cells = load_sweep(a.sweep)
            record = check_out(a.out, spec, a.resume)
            needs_pyarrow()
            done, foreign, bad = survey(a.out, cells) if a.resume else (set(), [], [])
            this = provenance.commit()
            mixed = check_commits(a.out, done, this, a.allow_mixed_commits) if a.resume else {}
        except SweepError as e:
            print(f"{PROG}: error: {e}", file=sys.stderr)
            return 2
        for name in foreign:
            print(f"{PROG}: {a.out / 'cells' / name} is no cell of this sweep: not counted (move it out of "
                  f"{a.out / 'cells'})", file=sys.stderr)
        for path, why in bad:
            print(f"{PROG}: {path}: {why}: its cell runs again (the file is kept as {path.name}.rejected)",
                  file=sys.stderr)
        if mixed:
            print(f"{PROG}: --allow-mixed-commits: the cells on disk were written at "
                  f"{', '.join(f'{c} ({n})' for c, n in mixed.items())}, the cells run now at {this}; the report "
                  f"says so", file=sys.stderr)
        todo = [c for c in cells if c["id"] not in done]
        where = f"Ray at {a.address}" if a.address else "a local Ray instance"
        print(f"{PROG}: {len(cells)} cell(s) ({len(spec['conditions'])} condition(s), world {spec['world']}), "
              f"{len(cells) - len(todo)} on disk, {len(todo)} to run on {where} -> {a.out}", flush=True)
        t0 = time.perf_counter()
        failed = []
        if todo:   # Ray first: a cluster that cannot be joined leaves nothing behind
            import ray
            owns_ray = not ray.is_initialized()   # from here on a Ctrl-C during ray.init ends what it started
            tree = ProcessTree() if owns_ray else None
            try:
                _start(a)
            except JoinError as e:
                print(f"{PROG}: error: {e}", file=sys.stderr)
                return 2
            except Exception as e:   # noqa: BLE001  Ray's reasons are many (RuntimeError, OSError, ...)
                print(f"{PROG}: error: cannot start Ray: {(str(e).strip().splitlines() or [type(e).__name__])[0]}",
                      file=sys.stderr)
                return 1
            finally:
                reinstall()   # ray.init set its own SIGTERM handler
        try:
            (a.out / "cells").mkdir(parents=True, exist_ok=True)
            for path, _ in bad:
                os.replace(path, path.with_name(path.name + ".rejected"))
            prov = {"commit": this, "versions": provenance.versions()}
            run = {"started": provenance.utc_now(), "ended": None, "ended_by": None, "resumed": a.resume,
                   "command": command_line(argv, console), "allow_mixed_commits": a.allow_mixed_commits,
                   "host": socket.gethostname(), "ray": a.address or "local", **prov, "cells_run": 0,
                   "cells_failed": 0, "cells": {}}
            if record is None:
                record = {"format": FORMAT, "sweep_file": str(a.sweep), "spec": spec,
                          "cells": [c["id"] for c in cells], "runs": []}
            record.setdefault("runs", []).append(run)
            record["cells"] = [c["id"] for c in cells]
            write_configs(a.out, cells)
            write_record(a.out, record)
            out, n_cells = a.out, len(cells)
            if todo:
                progress = Progress(len(cells), len(cells) - len(todo))
                try:
                    failed = run_sweep(todo, out, progress, on_cell, commit=this, finished=run["cells"])
                finally:
                    progress.close()
        except OSError as e:   # a full disk, DIR removed under the sweep: the cells written so far stay
            with sigint_ignored():
                _finish(out, record, run, "error")
                print(f"{fresh_line(sys.stderr)}{PROG}: error: cannot write {e.filename or a.out}: "
                      f"{e.strerror or e}", file=sys.stderr)
            return 1
        _finish(out, record, run, "failed" if failed else "finished", len(failed))
        if failed:
            print(f"{PROG}: {len(failed)} of {len(cells)} cell(s) failed (the first: {describe(failed[0][0])}: "
                  f"{failed[0][1]}); --resume runs them again", file=sys.stderr)
            return 1
        print(f"done: {len(cells)} cell(s) in {out / 'cells'} ({time.perf_counter() - t0:.0f} s); summary: "
              f"aesop-report {out} (or python -m train.report {out})", flush=True)
        return 0
    except KeyboardInterrupt as e:
        by, code = how(e)
        with sigint_ignored():   # a second Ctrl-C (or SIGTERM, SIGHUP) must not cut the clean-up short
            if progress is not None:
                progress.close()
            if out is None:
                print(f"{fresh_line(sys.stderr)}{PROG}: interrupted{by} before the sweep started", file=sys.stderr)
            else:
                _finish(out, record, run, f"interrupted{by}")
                done = len(list((out / "cells").glob("*.parquet")))
                print(f"{fresh_line(sys.stderr)}{PROG}: interrupted{by}: {done} of {n_cells} cell(s) on disk in "
                      f"{out / 'cells'} (--resume runs the rest)", file=sys.stderr)
            if console:   # the command line's sweep: its one line said, Ray's teardown says nothing more
                silence_stderr()
            _end_ray(owns_ray, tree)
            owns_ray, tree = False, None
        return code
    finally:
        if owns_ray:
            with sigint_ignored():
                _end_ray(True, tree)


def _end_ray(owns: bool, tree: ProcessTree | None) -> None:
    """Ray shut down, then every process started with it ended (a signal during ray.init leaves some that Ray's
    shutdown does not know of)."""
    stop_ray(owns)
    if tree is not None:
        tree.end()


def _finish(out, record: dict | None, run: dict | None, ended_by: str, failed: int = 0) -> None:
    """This run's entry in DIR/sweep.json completed (its end, how it ended, the cells it ran); a write that fails
    here leaves the entry as written at the start (the sweep's own line says what happened)."""
    if out is None or record is None or run is None or run["ended"] is not None:
        return
    run.update(ended=provenance.utc_now(), ended_by=ended_by, cells_run=len(run["cells"]), cells_failed=failed)
    try:
        write_record(out, record)
    except OSError:
        pass
