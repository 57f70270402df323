"""What Ray costs a sweep: the same cells on a local Ray instance with 1 and 2 workers, and in a plain loop.

    python benches/sweep_scale.py [--cells 200] [--repeats 3] [--record]

The cells (train/sweep.py): the paper model on generated sets of 8 objects (make_objects --pairs, seeds 0..,
8 probes) in 8 orders, the probe error after every episode, the simulated robot's noise; about 1 s each on one
core of the 2-core machine this was written on. Each is run and its Parquet file written (train.sweep.write_cell,
into a temporary directory), three ways:

- plain: a loop in this process (`train.sweep.run_cell`, one torch thread), no Ray;
- ray 1 and ray 2: `train.sweep.run_sweep` on a local Ray instance of 1 and of 2 CPUs, started for the repeat
  (`ray.init`, timed apart) and shut down after it. The wall time is from the first cell handed to Ray to the
  last written, so it includes the workers' start-up (importing torch) but not ray.init.

Printed, each the median over --repeats repeats: the wall time and cells/s of each way, ray.init's time, and

- overhead per cell (ms) = (Ray's wall time x workers - the plain loop's wall time) / cells: what a cell costs on
  Ray beyond its own work, in core-time (scheduling, serialising the rows, the workers' start-up shared out);
- the speedup of 2 workers over 1 = Ray's wall time with 1 worker / with 2.

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
    from train.sweep import _resolve
    doc = {"conditions": [{"name": "paper", "model": "paper"}],
           "sets": [{"name": "sets of 8", "generate": {"seeds": [0, n], "train": 8, "probe": 8, "pairs": True},
                     "orders": 8}]}
    return _resolve(doc, ROOT)[1]


class _Quiet:
    def update(self):
        pass

    def write(self, text):
        print(text, file=sys.stderr)


def plain(cells: list[dict], out: Path) -> float:
    from train.sweep import run_cell, write_cell
    t0 = time.perf_counter()
    for c in cells:
        write_cell(out, c["id"], run_cell(c["spec"], c["objects"]))
    return time.perf_counter() - t0


def on_ray(cells: list[dict], out: Path, workers: int) -> tuple[float, float]:
    """(ray.init's time, the cells' wall time) on a fresh local instance of `workers` CPUs."""
    import ray

    from train.sweep import run_sweep, start_ray
    t0 = time.perf_counter()
    start_ray(None, workers)
    t1 = time.perf_counter()
    try:
        failed = run_sweep(cells, out, _Quiet())
        t2 = time.perf_counter()
    finally:
        ray.shutdown()
    if failed:
        raise SystemExit(f"sweep_scale.py: {len(failed)} cell(s) failed on Ray: {failed[0][1]}")
    return t1 - t0, t2 - t1


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cells", type=count, default=200, help="cells of about 1 s each")
    ap.add_argument("--repeats", type=count, default=3, help="repeats of each way (the median is printed)")
    record_flag(ap)
    a = ap.parse_args()
    import torch

    from train.progress import Step
    torch.set_num_threads(1)
    cells = cells_of(a.cells)
    print(f"{a.cells} cells (the paper model, a generated set of 8 objects in 8 orders, probes after every "
          f"episode), {a.repeats} repeat(s); load average before: {os.getloadavg()[0]:.2f}", flush=True)
    runs: dict = {"plain": [], "ray 1": [], "ray 2": [], "init 1": [], "init 2": []}
    with Step("repeats x ways", 3 * a.repeats, unit="run", stream=sys.stderr) as bar:
        for _ in range(a.repeats):
            for way in ("plain", "ray 1", "ray 2"):
                out = Path(tempfile.mkdtemp(prefix="sweep_scale."))
                try:
                    (out / "cells").mkdir()
                    if way == "plain":
                        runs[way].append(plain(cells, out))
                    else:
                        w = int(way[-1])
                        init, wall = on_ray(cells, out, w)
                        runs[way].append(wall)
                        runs[f"init {w}"].append(init)
                    assert len(list((out / "cells").glob("*.parquet"))) == a.cells
                finally:
                    shutil.rmtree(out, ignore_errors=True)
                bar.update(1, way)
    med = {k: statistics.median(v) for k, v in runs.items()}
    print(f"\n{'way':<8}{'wall s':>9}{'cells/s':>9}{'s/cell':>8}{'ray.init s':>12}{'overhead ms/cell':>18}")
    print(f"{'plain':<8}{med['plain']:>9.1f}{a.cells / med['plain']:>9.2f}{med['plain'] / a.cells:>8.3f}")
    overhead = {}
    for w in (1, 2):
        wall = med[f"ray {w}"]
        overhead[w] = (wall * w - med["plain"]) / a.cells * 1000
        print(f"{f'ray {w}':<8}{wall:>9.1f}{a.cells / wall:>9.2f}{wall / a.cells:>8.3f}{med[f'init {w}']:>12.1f}"
              f"{overhead[w]:>18.1f}")
    speedup = med["ray 1"] / med["ray 2"]
    print(f"speedup of 2 workers over 1: {speedup:.2f}x; over the plain loop: {med['plain'] / med['ray 2']:.2f}x. "
          f"overhead: (Ray's wall time x workers - the plain loop's) / cells; load average after: "
          f"{os.getloadavg()[0]:.2f}")
    print(f"ray_speedup_2={speedup:.2f} overhead_ms={overhead[1]:.1f}")


if __name__ == "__main__":
    run_main("sweep_scale", main)
