"""The runner's access to the simulated world: drops, inspections and goal-trial drop sequences, on worker processes.

Every drop and every inspection starts from the scene as built (sim/world.py restores it) and seeds its sensor noise
from (seed, object name), so an object's outcome is the same bit for bit whichever process simulates it and whatever
it simulated before; a goal trial's sequence of drops starts from a fresh jar the same way (sim/trial.py). That
makes the physics embarrassingly parallel: the profile of a default run showed the drops and inspections (13
independent simulations) taking 9 of its 12 s, so they run on every core at once, and so do the goal trials' drop
sequences (each round's new ones at once). Each worker has one world for all its jobs.

`start` builds the world and forks the workers, each with its copy of it, while the runner goes on to build its
experiment; `submit` hands them jobs without waiting, so the runner opens its logs while they simulate; `ahead`
starts one job whose result may be wanted later (a goal trial's drops the runner expects, simulated while the agents
learn). The pool lives until `close`.

On Linux the workers are forked from the runner: a fresh interpreter ("spawn") spends ~1.5 s importing torch,
pybullet and pytorch-kinematics before its first simulation, 4-5 s on a busy machine; a forked one has them already
(`start` imports the simulator and builds the world just before it forks: once, not once per worker). It is safe
here: the one pybullet client the runner holds at the fork is that world's, a DIRECT one (in-process: no thread, no
socket, no shared memory; a GUI simulates in-process, without workers), so each worker's copy is a world of its own
(tests/test_speed_paths.py: the same outcomes as a world built in place); and a worker's torch runs on one thread
(`_init_forked`), so it never waits on a thread pool it did not inherit (checked with the parent's pool busy on two
threads and a tensorboard writer thread alive at the fork: same outcomes, no hang). Elsewhere: spawn.

Every world is built from the Physics' `world` config (sim.world.WorldConfig; None: the default). A world that
cannot be built (a config the scene does not admit) fails every job with one WorldBuildError: raised by a pool's
initializer, it would have its workers respawned for ever.

Ctrl-C belongs to the runner: the workers ignore SIGINT (they are started with it ignored, so not even their start-up
imports can print a traceback), and the runner ends the pool, says one line and keeps its last checkpoint. SIGTERM and
SIGHUP end a worker at once and silently (their default), whatever handler the runner had when it forked it; a worker
whose runner dies (even by SIGKILL) is killed by the kernel (Linux: PR_SET_PDEATHSIG), so none lingers or prints.

A worker that dies (killed, out of memory) is not replaced: the job it held would never be answered, and the runner
would wait for ever. Every wait on a pool's result looks at its processes every WATCH_S seconds and raises WorkerDied,
naming the process, when one has died. A pool ends whatever state its dead processes left its locks in, however it
ends (`end_pool`, or its finaliser when it is dropped or the interpreter exits): its processes are killed and its
locks freed first. Starting and ending a pool hold Ctrl-C, SIGTERM and SIGHUP until they are done
(train/common/exits.py signals_held): a pool cut off halfway would leave idle processes holding its task queue's lock.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import importlib
import multiprocessing as mp
import multiprocessing.pool
import os
import signal
import sys
import threading

from sim.errors import WorldBuildError
from train.common.collector import imports_done
from train.common.exits import signals_held

_WORLD = None  # one World per worker process (or why it could not be built: WorldBuildError)
START_METHOD = "fork" if sys.platform.startswith("linux") else "spawn"   # see the module docstring
WATCH_S = 0.25   # how often a wait on a pool looks whether its processes are alive
RESULTS_JOIN_S = 2.0   # how long an ending pool waits for its result thread: one that reads a result a killed
                       # process half wrote waits for bytes that never come (a daemon thread: left, it holds no exit)
PR_SET_PDEATHSIG = 1   # linux/prctl.h


class WorkerDied(RuntimeError):
    """A pool's process died while the caller waited on it: `what` (e.g. "a physics worker"), `pid` and `how`
    ("killed by SIGKILL", "exit code 1"); the message is one line."""

    def __init__(self, what: str, pid: int, exitcode: int):
        try:
            how = f"killed by {signal.Signals(-exitcode).name}" if exitcode < 0 else f"exit code {exitcode}"
        except ValueError:
            how = f"killed by signal {-exitcode}"
        self.what, self.pid, self.exitcode, self.how = what, pid, exitcode, how
        super().__init__(f"{what} (pid {pid}) died ({how})")


def _init(objects, seed: int, config=None) -> None:
    """A spawned worker's start: its world built here."""
    global _WORLD
    import torch

    torch.set_num_threads(1)  # one process per core
    _WORLD = _build(objects, seed, config)


def _init_forked() -> None:
    """A forked worker's start: the world its parent built just before the fork (Physics.start) is its own copy."""
    import torch

    torch.set_num_threads(1)  # one process per core


def _build(objects, seed: int, config=None):
    """The World, or why it could not be built (WorldBuildError: raised by every job, not by a pool's initializer,
    which would have its workers respawned for ever)."""
    from sim.world import World
    try:
        return World(objects, config=config, seed=seed)
    except Exception as e:  # noqa: BLE001  reported by the jobs
        lines = str(e).strip().splitlines()
        return WorldBuildError(f"the world could not be built: {type(e).__name__}: {lines[0] if lines else ''}")


def _task(job: tuple):
    if isinstance(_WORLD, WorldBuildError):
        raise _WORLD
    return _simulate(_WORLD, job)


def _simulate(world, job: tuple):
    kind, what, record = job
    if kind == "inspect":
        return world.inspect(what)
    if kind == "trial":   # a goal trial's drops, `what` in order, from a fresh jar: the outcome of each
        from sim.trial import simulate_sequence
        return simulate_sequence(world, what, record or None)
    return world.run_episode(what, record=record)


def by_name(target: str, args: tuple):
    """target(*args) for target "module:function", its module imported by the process that runs it (the runner's
    drawer draws Figure 2 so, train/runner/figure_process.py: the runner never imports matplotlib)."""
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)(*args)


def cores() -> int:
    """The cores this process may run on (its affinity mask, not the machine's count)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _die_with(parent: int) -> None:
    """In a worker: SIGTERM and SIGHUP at their defaults (a forked worker inherits the runner's handlers, which would
    raise here and print a traceback), and killed by the kernel when the process that forked it dies (Linux; the
    kernel ties this to the forking thread: a pool lives as long as the thread that made it)."""
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        if os.getppid() != parent:   # it died before the prctl took
            os._exit(0)


def _start(parent: int, initializer, initargs: tuple) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # already ignored since the fork (or exec)
    _die_with(parent)
    if initializer is not None:
        initializer(*initargs)
    imports_done()   # forked while the runner's collector was off (its start): on again here, after the imports


class _NotReplaced:
    """What the pool's thread gets in place of a process that died: nothing runs, nothing to wait for."""

    name, daemon, exitcode, pid = "", True, None, None

    def start(self):
        pass

    def terminate(self):
        pass

    def kill(self):
        pass

    def join(self, timeout=None):   # Pool.join waits on every entry of its list, stand-ins included
        pass

    def is_alive(self) -> bool:
        return False


class QuietPool(multiprocessing.pool.Pool):
    """A Pool whose dead processes are not replaced and whose waits notice them (see the module docstring)."""

    what = "a worker process"

    def __init__(self, *args, **kwargs):
        started = []

        def process(ctx, *a, **kw):
            """Pool.Process, for the processes the pool starts with only: a replacement would not answer the job
            its predecessor took with it (and one forked while the runner ends could miss the end)."""
            return _NotReplaced() if started else ctx.Process(*a, **kw)

        self.Process = process   # the pool's thread respawns through the Process it was given at start
        super().__init__(*args, **kwargs)
        started.append(True)

    @classmethod
    def _terminate_pool(cls, taskqueue, inqueue, outqueue, pool, *rest):
        """Pool's finaliser (terminate(), or the pool dropped, or the interpreter's exit), its processes killed and
        its queues' locks freed first: Pool's own waits on the task queue's lock, which an idle process holds while
        it waits for a job, for ever once that process was killed (a run ended by a signal while it ended its pool
        hung so after its one line)."""
        _kill_all(pool, inqueue, outqueue)
        change_notifier, worker_handler, task_handler, result_handler, cache = rest
        super()._terminate_pool(taskqueue, inqueue, outqueue, pool, change_notifier, worker_handler, task_handler,
                                _BoundedJoin(result_handler), cache)

    def join(self):
        """Pool.join, the result thread waited for RESULTS_JOIN_S at most (see _BoundedJoin)."""
        handler, self._result_handler = self._result_handler, _BoundedJoin(self._result_handler)
        try:
            super().join()
        finally:
            self._result_handler = handler

    def watch(self) -> None:
        """Raise WorkerDied if one of the pool's processes has died."""
        for p in self.processes:
            if p.exitcode is not None:
                raise WorkerDied(self.what, p.pid, p.exitcode)

    def imap(self, func, iterable, chunksize=1):
        """Pool.imap (the jobs handed over now), its results waited for while the pool's processes are alive."""
        return _watched_iter(self, super().imap(func, iterable, chunksize))

    def apply_async(self, func, args=(), kwds={}, callback=None, error_callback=None):   # noqa: B006  Pool's own
        return _Watched(self, super().apply_async(func, args, kwds, callback, error_callback))


class _BoundedJoin:
    """A pool's result thread whose join waits RESULTS_JOIN_S at most. A process killed while it sent a result (a
    signal to the runner's process group, or _kill_all) leaves part of it in the pipe: the thread then waits for the
    rest, the sentinel Pool.terminate sends is read as part of it, and Pool's unbounded join hung the runner after
    its one line (a SIGTERM 0.3 s into the goal trials, under load). The thread is a daemon: left waiting, it holds
    neither the pool's end nor the interpreter's."""

    def __init__(self, thread: threading.Thread):
        object.__setattr__(self, "_thread", thread)

    def __getattr__(self, name):
        return getattr(self._thread, name)

    def __setattr__(self, name, value):   # Pool sets the thread's _state: the thread reads it
        setattr(self._thread, name, value)

    def join(self, timeout=None):
        self._thread.join(RESULTS_JOIN_S if timeout is None else min(timeout, RESULTS_JOIN_S))


def _watched(pool: QuietPool, get):
    """get(timeout), waited for while the pool's processes are alive."""
    while True:
        try:
            return get(WATCH_S)
        except mp.TimeoutError:
            pool.watch()


def _watched_iter(pool: QuietPool, results):
    while True:
        try:
            yield _watched(pool, results.next)
        except StopIteration:
            return


class _Watched:
    """An AsyncResult whose get() notices a dead process of its pool."""

    def __init__(self, pool: QuietPool, result):
        self._pool, self._result = pool, result

    def ready(self) -> bool:
        return self._result.ready()

    def get(self, timeout=None):
        if timeout is not None:
            return self._result.get(timeout)
        return _watched(self._pool, self._result.get)


def quiet_pool(processes: int, initializer, initargs: tuple = (), what: str = "a worker process") -> QuietPool:
    """A QuietPool started with SIGINT ignored, so its processes inherit that (Ctrl-C belongs to the runner); what:
    how WorkerDied names its processes."""
    main = threading.current_thread() is threading.main_thread()   # only it may set handlers
    with signals_held() as held:   # a signal while the pool starts takes effect once it has started
        # a forked process inherits the holding handler, which ignores Ctrl-C in it; else it starts with Ctrl-C
        # ignored (a spawned one keeps only that across its exec)
        ignore = main and not (START_METHOD == "fork" and signal.SIGINT in held)
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if ignore else None
        try:
            pool = QuietPool(processes, initializer=_start, initargs=(os.getpid(), initializer, initargs),
                             context=mp.get_context(START_METHOD))
        finally:
            if ignore:
                signal.signal(signal.SIGINT, previous)
        pool.what, pool.processes = what, list(pool._pool)   # _pool loses the dead; this list keeps them for watch()
    return pool


def _kill_all(processes, inqueue, outqueue) -> None:
    """Kill a pool's processes and free its queues' locks, which a killed process may have held (an idle worker
    holds the task queue's while it waits): with every process dead, nothing else takes them."""
    for p in processes:
        if p.exitcode is None:
            p.kill()
    for p in processes:
        p.join()
    for lock in (getattr(inqueue, "_rlock", None), getattr(outqueue, "_wlock", None)):
        if lock is not None:
            lock.acquire(False)   # held by a dead process or by this call: free either way
            lock.release()


def end_pool(pool) -> None:
    """End a quiet_pool (None: nothing). Every result the caller wants is in (or the run is ending): its processes
    need no orderly shutdown (0.4 s) and are killed, its locks freed (_kill_all), then Pool.terminate. A signal
    meanwhile takes effect once the pool has ended (signals_held)."""
    if pool is None:
        return
    with signals_held():
        _kill_all(getattr(pool, "processes", pool._pool), pool._inqueue, pool._outqueue)
        pool.terminate()
        pool.join()


class Physics:
    """Drops, inspections and trial sequences for the runner. workers=1 (or a GUI) simulates in this process, when
    the results are asked for."""

    def __init__(self, objects, seed: int = 0, gui: bool = False, workers: int | None = None, world=None):
        """world: the sim.world.WorldConfig every world is built from (None: the default)."""
        self.objects, self.seed, self.gui, self.world_config = objects, seed, gui, world
        self.workers = 1 if gui else (workers or cores())
        self._pool = self._world = None
        self._early = None   # (jobs, their results) handed over by submit_early, for submit to take up

    def start(self) -> None:
        """Start the workers now. Forked (Linux): the world is built here once, and each worker forked with its own
        copy of it (every job starts from the scene as built, restored: a copy built elsewhere is the same scene), not
        built again in each (~0.4 CPU-s apiece, beside the runner building its experiment); this process's copy is
        closed once they are forked. Spawned: each imports the simulator and builds its world while the caller goes
        on."""
        global _WORLD
        if self.workers == 1 or self._pool is not None:
            return
        if START_METHOD != "fork":
            self._pool = quiet_pool(self.workers, _init, (self.objects, self.seed, self.world_config),
                                    what="a physics worker")
            return
        import numpy.ma  # noqa: F401  np.median's first call imports it (~0.06 s), once here rather than in each worker
        import torch

        import sim.episode  # a drop's and an inspection's code, likewise
        import sim.trial  # noqa: F401  a goal trial's

        threads = torch.get_num_threads()
        torch.set_num_threads(1)   # built as a worker would build it
        try:
            _WORLD = _build(self.objects, self.seed, self.world_config)
        finally:
            torch.set_num_threads(threads)
        try:
            imports_done()   # the runner's objects frozen before the fork (train/common/collector.py)
            self._pool = quiet_pool(self.workers, _init_forked, what="a physics worker")
        finally:   # the workers hold their copies (Pool forks them all before it returns): this one is not used
            world, _WORLD = _WORLD, None
            if not isinstance(world, WorldBuildError):
                world.close()

    def submit(self, jobs: list[tuple]):
        """Hand the jobs to the workers without waiting: an iterator of their results in job order (each waited
        for as it is taken). jobs: ("drop", name, record), ("inspect", name, None) or ("trial", names, record).
        The same jobs as submit_early's: the results it started."""
        if self._early is not None and self._early[0] == list(jobs):
            early, self._early = self._early[1], None
            return early
        if self.workers == 1:
            return map(self._here, jobs)   # lazy: each job is simulated when its result is taken
        self.start()
        return self._pool.imap(_task, jobs, chunksize=1)

    def submit_early(self, jobs: list[tuple]) -> None:
        """submit(jobs) now, its results kept for the submit (or run) of the same jobs later: the runner hands over
        its first simulations as soon as the workers are forked, before it has built what it will use them for."""
        self._early = (list(jobs), self.submit(jobs))

    def _here(self, job: tuple):
        if self._world is None:
            from sim.world import World
            try:
                self._world = World(self.objects, config=self.world_config, gui=self.gui, seed=self.seed)
            except Exception as e:  # noqa: BLE001  as in a worker (_init): one error, whichever process builds it
                lines = str(e).strip().splitlines()
                raise WorldBuildError(f"the world could not be built: {type(e).__name__}: "
                                      f"{lines[0] if lines else ''}") from e
        return _simulate(self._world, job)

    def run(self, jobs: list[tuple], progress=None, submitted=None) -> list:
        """The jobs' results in job order, waited for. progress: optional callable(job) called as each result
        arrives. submitted: what submit(jobs) returned, if they were handed over already."""
        results = []
        for j, r in zip(jobs, self.submit(jobs) if submitted is None else submitted):
            results.append(r)
            if progress is not None:
                progress(j)
        return results

    def ahead(self, job: tuple):
        """Start one job on a worker now, its result taken later with get() (the runner's guess at a goal trial's
        drops, simulated while the workers would idle). Only for a pool: in this process it would cost the time it
        saves."""
        if self.workers == 1:
            raise ValueError("Physics.ahead needs worker processes (workers > 1)")
        self.start()
        return self._pool.apply_async(_task, (job,))

    def drops(self, names: list[str], record: bool = False, progress=None) -> list:
        return self.run([("drop", n, record) for n in names], progress)

    def inspections(self, names: list[str]) -> list[dict]:
        return self.run([("inspect", n, None) for n in names])

    def close(self) -> None:
        end_pool(self._pool)
        self._pool = None
        if self._world is not None:
            self._world.close()
            self._world = None
