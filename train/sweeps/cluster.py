"""Ray: the cells as Ray tasks, a local instance started (or a cluster joined) and ended, the progress line, and
every process the sweep started gone when it ends (docs/sweeps.md "Ray").

A few cells per CPU are handed to Ray at a time; the driver writes each finished cell's bytes, encoded on its
worker. A cell that raises is one line and the others go on.
"""

from __future__ import annotations

import contextlib
import os
import socket
import sys
import tempfile
import time
from pathlib import Path

from train.sweeps.cell import run_cell, world_key, world_outcomes
from train.sweeps.provenance import utc_now
from train.sweeps.spec import PROG
from train.sweeps.store import cell_metadata, encode_cell, write_cell

ROOT = Path(__file__).resolve().parents[2]


def _remote_functions():
    """The Ray tasks (made on first use: importing this module does not import ray)."""
    import ray

    @ray.remote(num_cpus=1, max_retries=2)   # retried only if a worker dies (e.g. a node lost)
    def world_task(cell, objects):
        import torch
        torch.set_num_threads(1)
        return world_outcomes(cell, objects)

    @ray.remote(num_cpus=1, max_retries=2)   # retried only if a worker dies (e.g. a node lost)
    def cell_task(cell, objects, world, commit):
        import torch
        torch.set_num_threads(1)
        started, t0 = utc_now(), time.perf_counter()
        table = run_cell(cell, objects, world, commit)
        info = {"host": socket.gethostname(), "wall_s": round(time.perf_counter() - t0, 3), "started": started,
                "ended": utc_now()}
        # the Parquet file's bytes, encoded here on the worker: the driver, which shares the cores with the
        # workers on a small machine, only writes them (and Ray moves a few kB instead of the rows)
        return encode_cell(table, cell_metadata(cell, commit, info)), info

    return world_task, cell_task


def describe(c: dict) -> str:
    """A cell as its lines name it: condition / set group and set / seed."""
    s = c["spec"]
    return f"{s['condition']['name']} / {s['set_group']} {s['set']} / seed {s['seed']}"


class Progress:
    """Cells done with an ETA: a tqdm bar on a terminal; in a log, a line at every tenth."""

    def __init__(self, total: int, done: int):
        self.total, self.n, self.start, self.t0 = total, done, done, time.perf_counter()
        self.bar = None
        if sys.stderr.isatty():
            import shutil

            from tqdm import tqdm
            sized = shutil.get_terminal_size((0, 0)).columns > 0   # a pty of unknown size reports 0 columns
            self.bar = tqdm(total=total, initial=done, desc="cells", unit="cell", file=sys.stderr, smoothing=0.1,
                            dynamic_ncols=sized, ncols=None if sized else 100, nrows=None if sized else 40)
        self.next = done + max(1, total // 10)

    def update(self) -> None:
        self.n += 1
        if self.bar is not None:
            self.bar.update(1)
        elif self.n >= self.next or self.n == self.total:
            self.next = self.n + max(1, self.total // 10)
            el = time.perf_counter() - self.t0
            eta = el / (self.n - self.start) * (self.total - self.n)
            print(f"cells: {self.n}/{self.total} [{el:.0f} s, ETA {eta:.0f} s]", file=sys.stderr, flush=True)

    def write(self, text: str) -> None:
        if self.bar is not None:
            self.bar.write(text, file=sys.stderr)
        else:
            print(text, file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class JoinError(Exception):
    """A Ray cluster that cannot be joined (--address): one line, exit code 2."""


AUTH_HINT = ("a cluster started with token authentication (ray start's default in recent Ray) needs "
             "RAY_AUTH_MODE=token and its token (RAY_AUTH_TOKEN or ~/.ray/auth_token) in this sweep's environment")


def start_ray(address: str | None, workers: int | None) -> bool:
    """Join `address` or start a quiet local instance; True when this process started (and so ends) it. Reuses a
    Ray already initialised in this process (then False). JoinError (one line) if the cluster cannot be joined."""
    import logging

    import ray
    if ray.is_initialized():
        return False
    job = ray.job_config.JobConfig(code_search_path=[str(ROOT)])   # the workers import train.sweeps from here
    if address is not None:
        try:
            _reachable(address)
        except ConnectionError as e:
            raise JoinError(f"cannot join Ray at {address}: {e}; check the address (`ray start --head` prints it, "
                            f"`ray status` on its node)") from None
        with _stderr_kept() as said:   # Ray's gRPC retries print a screenful on a refused join: kept, judged here
            try:
                ray.init(address=address, log_to_driver=False, logging_level=logging.ERROR, job_config=job)
            except Exception as e:   # noqa: BLE001  Ray's reasons are many (ConnectionError, AuthenticationError, ...)
                raise JoinError(_join_failure(address, e, said())) from None
            text = said()
        if text:   # joined: what Ray said on the way (its warnings) is passed on as it was
            sys.stderr.write(text)
            sys.stderr.flush()
        return True
    from train.learning.sim_pool import cores
    # "local": a new instance of this process's own, even where a cluster runs (ray.init() would join that)
    ray.init(address="local", num_cpus=workers or cores(), include_dashboard=False, log_to_driver=False,
             logging_level=logging.ERROR, job_config=job)
    return True


def _join_failure(address: str, e: Exception, said: str) -> str:
    """The one line for a failed ray.init(address=...): an authentication failure named as such, with its fix."""
    import ray
    text = f"{type(e).__name__} {e} {said}".lower()
    first = (str(e).strip().splitlines() or [type(e).__name__])[0][:160]
    if isinstance(e, getattr(ray.exceptions, "AuthenticationError", ())) or any(
            w in text for w in ("unauthenticated", "authentication", "auth_token", "auth token")):
        return (f"cannot join Ray at {address}: the cluster requires token authentication: set RAY_AUTH_MODE=token "
                f"(and its token: RAY_AUTH_TOKEN or ~/.ray/auth_token) and run the sweep again")
    return f"cannot join Ray at {address}: {first}; {AUTH_HINT}"


@contextlib.contextmanager
def _stderr_kept():
    """File descriptor 2 (where Ray's C++ core writes) into a temporary file while the block runs, then back; yields
    a function that returns what was written. Python's sys.stderr writes through fd 2 too."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lambda: (sys.stderr.flush(), tmp.seek(0), tmp.read(1 << 20).decode("utf-8", "replace"))[-1]
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)


def _reachable(address: str, timeout: float = 10.0) -> None:
    """ConnectionError (one line) if HOST:PORT does not answer: ray.init would retry it for ever, printing warnings.
    Other forms (auto, ray://...) are left to Ray."""
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit() or "://" in address:
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as e:
        raise ConnectionError(f"it does not answer ({e.strerror or e})") from None


def run_sweep(cells: list[dict], out: Path, progress: Progress, on_cell=None, commit: str = "unknown",
              finished: dict | None = None) -> list[tuple[dict, str]]:
    """Run the cells on Ray (initialised), writing each as it finishes; the failures as (cell, one-line reason).
    A few cells per CPU are handed to Ray at a time (the rest wait here: a Ctrl-C leaves little running, and a
    million-cell sweep does not sit in Ray's queues). on_cell(cell): called after each cell is written (tests).
    commit: recorded in each cell file; finished: filled with {cell id: {host, wall_s, started, ended}}."""
    import ray
    world_task, cell_task = _remote_functions()
    window = max(8, 4 * int(ray.cluster_resources().get("CPU", 1)))
    worlds: dict = {}   # a physics world is simulated once (its task), shared by the cells that see it

    def submit(c):
        world = None
        if c["spec"]["world"] == "physics":
            k = world_key(c["spec"])
            if k not in worlds:
                worlds[k] = world_task.remote(c["spec"], c["objects"])
            world = worlds[k]
        return cell_task.remote(c["spec"], c["objects"], world, commit)

    queue = list(reversed(cells))   # popped from the end: in the given order
    pending: dict = {}
    failed = []
    # Nothing is cancelled on the way out (Ctrl-C, a signal, an error): the driver's end (ray.shutdown, or its exit)
    # ends its tasks, locally and on a cluster; ray.cancel then the reply of a cell already done aborted Ray's core
    # worker ("Tried to complete task that was not pending"), exit 1 and a C++ stack trace instead of the one line.
    while queue or pending:
        while queue and len(pending) < window:
            c = queue.pop()
            pending[submit(c)] = c
        # a timeout, so Python sees a Ctrl-C: a wait without one blocks in Ray's C++ and never returns to it
        done, _ = ray.wait(list(pending), num_returns=1, timeout=0.5)
        for ref in done:
            c = pending.pop(ref)
            try:
                data, info = ray.get(ref)
            except ray.exceptions.RayError as e:
                cause = getattr(e, "cause", None) or e
                why = (str(cause).strip().splitlines() or [type(cause).__name__])[-1]
                failed.append((c, why))
                progress.write(f"{PROG}: cell {c['id']} ({describe(c)}) failed: {why}")
                continue
            write_cell(out, c["id"], data)
            if finished is not None:
                finished[c["id"]] = info
            progress.update()
            if on_cell is not None:
                on_cell(c)
    return failed



def silence_stderr() -> None:
    """fd 2 to /dev/null: Ray's core worker writes to it directly while it tears down after an interruption (a cell
    that finished after the driver let go: 'Failed to push error to driver for task ...'), after the sweep's one
    line. Only for the command line (main() with argv None): a caller's own stderr is left alone."""
    try:
        sys.stderr.flush()
        fd = os.open(os.devnull, os.O_WRONLY)
        os.dup2(fd, 2)
        os.close(fd)
    except OSError:
        pass


def stop_ray(owns: bool) -> None:
    if owns:
        import ray
        try:
            if ray.is_initialized():
                ray.shutdown()
        except Exception:   # noqa: BLE001  a Ray already torn down by the same Ctrl-C: nothing left to end
            pass
