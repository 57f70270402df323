"""The runner's access to the simulated world: drops and inspections, spread over worker processes.

Every drop and every inspection starts from the scene as built (sim/world.py restores it) and seeds its sensor noise
from (seed, object name), so an object's outcome is the same bit for bit whichever process simulates it and whatever
it simulated before. That makes the physics embarrassingly parallel: the profile of a default run showed the drops
and inspections (13 independent simulations) taking 9 of its 12 s, so they run on every core at once. Each worker
builds its world once.

On Linux the workers are forked from the runner: a fresh interpreter ("spawn") spends ~1.5 s importing torch,
pybullet and pytorch-kinematics before its first simulation, 4-5 s on a busy machine; a forked one has torch
already. It is safe here: the runner holds no pybullet client (a GUI simulates in-process), and a worker's torch runs
on one thread (`_init`), so it never waits on a thread pool it did not inherit (checked with the parent's pool busy
on two threads and a tensorboard writer thread alive at the fork: same outcomes, no hang). Elsewhere: spawn.

Ctrl-C belongs to the runner: the workers ignore SIGINT (they are started with it ignored, so not even their start-up
imports can print a traceback), and the runner ends the pool, says one line and keeps its last checkpoint.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
import threading

_WORLD = None  # one World per worker process
START_METHOD = "fork" if sys.platform.startswith("linux") else "spawn"   # see the module docstring


def _init(objects, seed: int) -> None:
    global _WORLD
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # already ignored since the fork (or exec)
    import torch

    torch.set_num_threads(1)  # one process per core
    from sim.world import World
    _WORLD = World(objects, seed=seed)


def _task(job: tuple):
    kind, name, record = job
    if kind == "inspect":
        return _WORLD.inspect(name)
    return _WORLD.run_episode(name, record=record)


def cores() -> int:
    """The cores this process may run on (its affinity mask, not the machine's count)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


class Physics:
    """Drops and inspections for the runner. workers=1 (or a GUI) simulates in this process."""

    def __init__(self, objects, seed: int = 0, gui: bool = False, workers: int | None = None):
        self.objects, self.seed, self.gui = objects, seed, gui
        self.workers = 1 if gui else (workers or cores())
        self._pool = None

    def run(self, jobs: list[tuple], progress=None) -> list:
        """jobs: ("drop", name, record) or ("inspect", name, None); results in the same order.
        progress: optional callable(job) called as each job's result arrives (in job order)."""
        if not jobs:
            return []
        if self.workers == 1 or len(jobs) == 1:
            global _WORLD
            if _WORLD is None:
                from sim.world import World
                _WORLD = World(self.objects, gui=self.gui, seed=self.seed)
            results = []
            for j in jobs:
                results.append(_task(j))
                if progress is not None:
                    progress(j)
            return results
        if self._pool is None:
            ctx = mp.get_context(START_METHOD)
            main = threading.current_thread() is threading.main_thread()   # only it may set handlers
            previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None   # inherited by the workers
            try:
                self._pool = ctx.Pool(min(self.workers, len(jobs)), initializer=_init,
                                      initargs=(self.objects, self.seed))
            finally:
                if main:
                    signal.signal(signal.SIGINT, previous)
        results = []
        for j, r in zip(jobs, self._pool.imap(_task, jobs, chunksize=1)):
            results.append(r)
            if progress is not None:
                progress(j)
        return results

    def drops(self, names: list[str], record: bool = False, progress=None) -> list:
        return self.run([("drop", n, record) for n in names], progress)

    def inspections(self, names: list[str]) -> list[dict]:
        return self.run([("inspect", n, None) for n in names])

    def close(self) -> None:
        global _WORLD
        if self._pool is not None:
            self._pool.terminate()   # every result is in: the idle workers need no orderly shutdown (0.4 s)
            self._pool.join()
            self._pool = None
        if _WORLD is not None:
            _WORLD.close()
            _WORLD = None
