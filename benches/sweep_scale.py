"""What Ray costs a sweep: the same cells on a local Ray instance with 1 and 2 workers, and in a plain loop.

    python benches/sweep_scale.py [--cells 200] [--repeats 3] [--record]

The cells (train/sweep.py): the paper model on generated sets of 8 objects (make_objects --pairs, seeds 0..,
8 probes) in 8 orders, the probe error after every episode, the simulated robot's noise; about 1 s each on one
core of the 2-core machine this was written on. Each is run and its Parquet file written (train.sweeps.store.write_cell,
into a temporary directory), three ways:

- plain: a loop in this process (`train.sweeps.cell.run_cell`, one torch thread), no Ray;
- plain 2: the same loop in 2 forked processes, each over every other cell, no Ray: the most 2 processes get
  out of this machine's cores (shared caches and memory bandwidth, or vCPUs that are one core's hyperthreads),
  the ceiling of any 2-worker speedup here;
- ray 1 and ray 2: `train.sweeps.cluster.run_sweep` on a local Ray instance of 1 and of 2 CPUs, started for the repeat
  (`ray.init`, timed apart) and shut down after it. The wall time is from the first cell handed to Ray to the
  last written, so it includes the workers' start-up (importing torch) but not ray.init. Each cell's Parquet
  file is encoded on its worker (`train.sweeps.store.encode_cell`); the driver writes the bytes.

Printed, each the median over --repeats repeats: the wall time and cells/s of each way, ray.init's time, and

- overhead per cell (ms) = (Ray's wall time x workers - the plain loop's wall time) / cells: what a cell costs on
  Ray beyond its own work, in core-time (scheduling, serialising the rows, the workers' start-up shared out);
- the speedup of 2 workers over 1 = Ray's wall time with 1 worker / with 2, beside the plain loop's over plain 2;
- where the CPU goes, per cell: the plain loop's; on Ray, the workers' (their start-up included), the driver's
  and Ray's own daemons' (raylet, gcs_server, the monitors and agents, which share the 2 cores with the workers),
  read from /proc for this process and its descendants.

On a machine whose cores are busy with other work the figures mean little: the load average is printed. Last line:
`ray_speedup_2=S overhead_ms=O` (O with 1 worker, where the workers do not share the cores with the driver).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cli_args import count, record_flag  # noqa: E402
from record import run_main  # noqa: E402


def cells_of(n: int) -> list[dict]:
    """n cells: the paper model on sets of 8 in 8 orders (seeds 0..n-1), checks at every episode."""
    from train.sweeps.spec import resolve
    doc = {"conditions": [{"name": "paper", "model": "paper"}],
           "sets": [{"name": "sets of 8", "generate": {"seeds": [0, n], "train": 8, "probe": 8, "pairs": True},
                     "orders": 8}]}
    return resolve(doc, ROOT)[1]


class _Quiet:
    def update(self):
        pass

    def write(self, text):
        print(text, file=sys.stderr)


def plain(cells: list[dict], out: Path) -> float:
    from train.sweeps.cell import run_cell
    from train.sweeps.store import write_cell
    t0 = time.perf_counter()
    for c in cells:
        write_cell(out, c["id"], run_cell(c["spec"], c["objects"]))
    return time.perf_counter() - t0


def plain_2(cells: list[dict], out: Path) -> float:
    """The plain loop in 2 forked processes, each over every other cell, no Ray: what 2 processes on this machine's
    cores can do at best (the ceiling of a 2-worker speedup), from the first cell to the last written."""
    import multiprocessing
    ctx = multiprocessing.get_context("fork")
    t0 = time.perf_counter()
    procs = [ctx.Process(target=plain, args=(cells[i::2], out)) for i in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join()
    if any(p.exitcode for p in procs):
        raise SystemExit("sweep_scale.py: a plain process failed")
    return time.perf_counter() - t0


def _cpu_seconds() -> dict:
    """CPU seconds (user + system) so far of this process and its descendants (Ray's daemons and workers, started
    by ray.init here), by group: driver, workers (ray::... task processes), ray (raylet, gcs_server, monitors,
    agents)."""
    tick = os.sysconf("SC_CLK_TCK")
    procs = {}
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/stat") as f:
                st = f.read()
        except OSError:
            continue
        name, rest = st[st.index("(") + 1:st.rindex(")")], st[st.rindex(")") + 2:].split()
        procs[int(pid)] = (name, int(rest[1]), (int(rest[11]) + int(rest[12])) / tick)
    me, out = os.getpid(), {"driver": 0.0, "workers": 0.0, "ray": 0.0}
    for pid, (name, ppid, cpu) in procs.items():
        p, seen = pid, 0
        while p not in (me, 0, 1) and p in procs and seen < 50:
            p, seen = procs[p][1], seen + 1
        if p != me:
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read().decode(errors="replace")
        except OSError:
            cmd = ""
        group = ("driver" if pid == me else "workers" if cmd.startswith("ray::") and "Agent" not in cmd
                 else "ray")
        out[group] += cpu
    return out


def on_ray(cells: list[dict], out: Path, workers: int) -> tuple[float, float, dict]:
    """(ray.init's time, the cells' wall time, the CPU seconds each group spent meanwhile) on a fresh local instance
    of `workers` CPUs."""
    import ray

    from train.sweeps.cluster import run_sweep, start_ray
    t0 = time.perf_counter()
    start_ray(None, workers)
    t1 = time.perf_counter()
    try:
        before = _cpu_seconds()
        failed = run_sweep(cells, out, _Quiet())
        t2 = time.perf_counter()
        after = _cpu_seconds()   # before shutdown: its processes' times end with them
    finally:
        ray.shutdown()
    if failed:
        raise SystemExit(f"sweep_scale.py: {len(failed)} cell(s) failed on Ray: {failed[0][1]}")
    return t1 - t0, t2 - t1, {k: after[k] - before[k] for k in after}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cells", type=count, default=200, help="cells of about 1 s each")
    ap.add_argument("--repeats", type=count, default=3, help="repeats of each way (the median is printed)")
    record_flag(ap)
    a = ap.parse_args()
    import torch

    from train.common.progress import Step
    torch.set_num_threads(1)
    cells = cells_of(a.cells)
    print(f"{a.cells} cells (the paper model, a generated set of 8 objects in 8 orders, probes after every "
          f"episode), {a.repeats} repeat(s); load average before: {os.getloadavg()[0]:.2f}", flush=True)
    runs: dict = {"plain": [], "plain 2": [], "ray 1": [], "ray 2": [], "init 1": [], "init 2": [], "cpu plain": []}
    cpu: dict = {1: [], 2: []}
    ways = ("plain", "plain 2", "ray 1", "ray 2")
    with Step("repeats x ways", len(ways) * a.repeats, unit="run", stream=sys.stderr) as bar:
        for _ in range(a.repeats):
            for way in ways:
                out = Path(tempfile.mkdtemp(prefix="sweep_scale."))
                try:
                    (out / "cells").mkdir()
                    if way == "plain":
                        c0 = time.process_time()
                        runs[way].append(plain(cells, out))
                        runs["cpu plain"].append(time.process_time() - c0)
                    elif way == "plain 2":
                        runs[way].append(plain_2(cells, out))
                    else:
                        w = int(way[-1])
                        init, wall, spent = on_ray(cells, out, w)
                        runs[way].append(wall)
                        runs[f"init {w}"].append(init)
                        cpu[w].append(spent)
                    assert len(list((out / "cells").glob("*.parquet"))) == a.cells
                finally:
                    shutil.rmtree(out, ignore_errors=True)
                bar.update(1, way)
    med = {k: statistics.median(v) for k, v in runs.items()}
    print(f"\n{'way':<8}{'wall s':>9}{'cells/s':>9}{'s/cell':>8}{'ray.init s':>12}{'overhead ms/cell':>18}")
    print(f"{'plain':<8}{med['plain']:>9.1f}{a.cells / med['plain']:>9.2f}{med['plain'] / a.cells:>8.3f}")
    print(f"{'plain 2':<8}{med['plain 2']:>9.1f}{a.cells / med['plain 2']:>9.2f}{med['plain 2'] / a.cells:>8.3f}"
          f"{'':>12}{(med['plain 2'] * 2 - med['plain']) / a.cells * 1000:>18.1f}   (2 forked plain loops, no Ray)")
    overhead = {}
    for w in (1, 2):
        wall = med[f"ray {w}"]
        overhead[w] = (wall * w - med["plain"]) / a.cells * 1000
        print(f"{f'ray {w}':<8}{wall:>9.1f}{a.cells / wall:>9.2f}{wall / a.cells:>8.3f}{med[f'init {w}']:>12.1f}"
              f"{overhead[w]:>18.1f}")
    print(f"\nCPU ms per cell (median over repeats): the plain loop {1000 * med['cpu plain'] / a.cells:.0f}")
    for w in (1, 2):
        m = {k: statistics.median(c[k] for c in cpu[w]) for k in cpu[w][0]}
        print(f"  ray {w}: workers {1000 * m['workers'] / a.cells:.0f} (their start-up included), driver "
              f"{1000 * m['driver'] / a.cells:.1f}, Ray's daemons {1000 * m['ray'] / a.cells:.1f} (raylet, gcs, "
              f"monitors, agents)")
    speedup = med["ray 1"] / med["ray 2"]
    print(f"speedup of 2 workers over 1: {speedup:.2f}x; over the plain loop: {med['plain'] / med['ray 2']:.2f}x; "
          f"2 plain processes over 1 (no Ray: the machine's ceiling): {med['plain'] / med['plain 2']:.2f}x. "
          f"overhead: (wall time x workers - the plain loop's) / cells; load average after: "
          f"{os.getloadavg()[0]:.2f}")
    print(f"ray_speedup_2={speedup:.2f} overhead_ms={overhead[1]:.1f}")


if __name__ == "__main__":
    run_main("sweep_scale", main)
