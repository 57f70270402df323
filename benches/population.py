"""Throughput of train.learning.population (every order at once) beside the plain trie, and the wall time of
`train/run.py --orders all` for 8 and 9 objects.

    python benches/population.py [--skip-run] [--repeats R] [--record]

Part 1 runs populations of 1, 100, 10,000 random orders and all 40,320 orders of the default 8 objects through
`run_population`, with closed-form outcomes (Archimedes, measurements from the object specs: no physics): ours
(prefix sharing, merged states) and its peer, the plain trie (`merge=False`: every trie node stepped, as the
population did before states were merged), alternately, R times each (default 3), medians. It prints order-episodes
per second (orders x 8 episodes / wall, final probe predictions included), the agent-steps each ran, the ratio, and
whether both gave the same knowledge and rounded probe errors for every order (curves=False: final results only),
then all orders once more with curves=True (the probe error after every episode, as the runner asks for Figure 2)
and its wall time beside ours. Part 2 runs
`python train/run.py --orders all --out <tmpdir>` end to end (physics of the drops and probe inspections, 64 orders
in detail, the population, summary and figure, goal trials) in a subprocess for the default file and for the
default file with a ninth train object (a blue heavy sphere: 9! = 362,880 orders), and prints the wall times and peak
memory. Last line: `all_orders_wall_s=X nine_objects_wall_s=Y` (0 with --skip-run).
Printed, never asserted: speed depends on the machine and on what else runs on it. `--record` writes the output into
BENCHMARKS.md (whole runs only: not with --skip-run).
"""

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from aesop_torch.malloc import keep_freed_memory  # noqa: E402

from aesop_torch.agent import AgentConfig  # noqa: E402
from sim.objects import DEFAULT_OBJECTS_FILE, load_objects  # noqa: E402
from train.learning.experiment import closed_form_outcomes, draw_orders  # noqa: E402
from train.learning.population import run_population  # noqa: E402
from cli_args import count, record_flag  # noqa: E402
from record import run_main  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current (--record)

POPULATIONS = ("1", "100", "10000", "all")
NINTH = {"name": "blue_heavy_sphere", "shape": "sphere", "color": "blue", "dims_cm": [5.5], "mass_g": 350}


def closed_form_world():
    objs = load_objects(DEFAULT_OBJECTS_FILE)
    outcomes, probes = closed_form_outcomes(objs)
    return [s.name for s in objs.train], [p.name for p in objs.probe], outcomes, probes


def population_section(repeats: int) -> None:
    train, probe_names, outcomes, probes = closed_form_world()
    n = len(train)
    print(f"populations of the default set, ours (merged states) and the plain trie alternately, medians of {repeats}")
    print(f"{'orders':>7} {'wall s':>7} {'order-ep/s':>11} {'steps':>7} {'plain wall s':>13} {'order-ep/s':>11} "
          f"{'steps':>7} {'speed-up':>9}  same results")
    for which in POPULATIONS:
        orders = draw_orders(n, which, seed=0)
        walls, runs = {True: [], False: []}, {}
        for _ in range(repeats):
            for merge in (True, False):
                t0 = time.perf_counter()
                runs[merge] = run_population(train, probe_names, orders, outcomes, probes, AgentConfig(), merge=merge,
                                             curves=False)
                walls[merge].append(time.perf_counter() - t0)
        ours, plain = statistics.median(walls[True]), statistics.median(walls[False])
        same = all(runs[True][k] == runs[False][k] for k in ("final_knowledge", "final_probe_rel_error"))
        print(f"{len(orders):>7} {ours:>7.2f} {len(orders) * n / ours:>11.0f} {runs[True]['agent_steps']:>7} "
              f"{plain:>13.2f} {len(orders) * n / plain:>11.0f} {runs[False]['agent_steps']:>7} {plain / ours:>8.1f}x  "
              f"{'yes' if same else 'NO'}", flush=True)
    t0 = time.perf_counter()
    run_population(train, probe_names, orders, outcomes, probes, AgentConfig(), curves=True)
    print(f"{len(orders)} orders with curves=True (Figure 2's per-episode errors), once: "
          f"{time.perf_counter() - t0:.2f} s wall (ours above: {ours:.2f} s)", flush=True)
    print(f"peak memory of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.2f} GB")


def timed_run(args: list, tmp: str) -> float:
    cmd = [sys.executable, str(ROOT / "train" / "run.py"), "--orders", "all", *args, "--out", str(Path(tmp) / "run")]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        print(done.stdout[-2000:], done.stderr[-2000:], sep="\n")
        raise SystemExit(f"{' '.join(cmd)} failed with exit code {done.returncode}")
    for line in done.stdout.splitlines():
        if line.startswith(("train/run.py: starting", "simulating", "population:", "order_independent")):
            print(f"  run.py: {line}")
    print(f"train/run.py --orders all {' '.join(args)}: {wall:.1f} s wall, peak memory of the runs so far "
          f"{resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6:.2f} GB", flush=True)
    return wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--skip-run", action="store_true", help="part 1 alone, without the train/run.py runs")
    ap.add_argument("--repeats", type=count, default=3, help="runs of each population, alternately (medians)")
    record_flag(ap, "BENCHMARKS.md (whole runs only)")
    a = ap.parse_args()
    if a.record and a.skip_run:
        ap.error("--record records whole runs only, not --skip-run")
    keep_freed_memory()   # freed tensors reused, for the peers in this process too (aesop_torch/malloc.py)
    population_section(a.repeats)
    if a.skip_run:
        print("all_orders_wall_s=0 nine_objects_wall_s=0")
        return
    with tempfile.TemporaryDirectory() as tmp:
        eight = timed_run([], tmp)
    with tempfile.TemporaryDirectory() as tmp:
        spec = json.loads(Path(DEFAULT_OBJECTS_FILE).read_text())
        spec["train"].append(NINTH)
        nine_file = Path(tmp) / "nine_objects.json"
        nine_file.write_text(json.dumps(spec))
        nine = timed_run(["--objects", str(nine_file)], tmp)
    print(f"all_orders_wall_s={eight:.1f} nine_objects_wall_s={nine:.1f}")


if __name__ == "__main__":
    run_main("population", main)
