"""Throughput of train.population (every order at once) and the wall time of `train/run.py --orders all`.

    python benches/population.py [--skip-run]

Part 1 runs populations of 1, 100 and 10,000 random orders and all 40,320 orders of the default 8 objects through
`run_population`, with closed-form outcomes (Archimedes, measurements from the object specs: no physics), and prints
order-episodes per second (orders x 8 episodes / wall, final probe predictions included), the agent-steps the trie
actually ran, and where the time went. Part 2 runs `python train/run.py --orders all --out <tmpdir>` end to end
(physics of 8 drops and 5 probe inspections, 64 orders in detail, the population, summary and figure) in a
subprocess and prints its wall time and peak memory. Last line: `all_orders_wall_s=X` (0 with --skip-run).
Printed, never asserted: speed depends on the machine and on what else runs on it.
"""

import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from aesop_torch.agent import AgentConfig  # noqa: E402
from sim.objects import DEFAULT_OBJECTS_FILE, load_objects  # noqa: E402
from train.experiment import closed_form_outcomes, draw_orders  # noqa: E402
from train.population import run_population  # noqa: E402
from train.progress import Step  # noqa: E402
from record import recorded  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current

POPULATIONS = ("1", "100", "10000", "all")


def closed_form_world():
    objs = load_objects(DEFAULT_OBJECTS_FILE)
    outcomes, probes = closed_form_outcomes(objs)
    return [s.name for s in objs.train], [p.name for p in objs.probe], outcomes, probes


def main():
    train, probe_names, outcomes, probes = closed_form_world()
    n = len(train)
    print(f"{'orders':>7} {'wall s':>7} {'order-episodes/s':>17} {'agent-steps':>12} {'steps s':>8} {'probes s':>9} "
          f"{'agree':>7}  most common")
    for which in POPULATIONS:
        orders = draw_orders(n, which, seed=0)
        t0 = time.perf_counter()
        with Step(f"{len(orders)} order(s)", len(orders), unit="order", stream=sys.stderr, announce=False) as bar:
            pop = run_population(train, probe_names, orders, outcomes, probes, AgentConfig(), progress=bar.to)
        wall = time.perf_counter() - t0
        t = pop["timing_s"]
        print(f"{len(orders):>7} {wall:>7.2f} {len(orders) * n / wall:>17.0f} {pop['agent_steps']:>12} "
              f"{t['steps']:>8.2f} {t['probes']:>9.2f} {pop['agree_fraction']:>7.4f}  {pop['most_common_knowledge']}")
    print(f"peak memory of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.2f} GB")

    if "--skip-run" in sys.argv[1:]:
        print("all_orders_wall_s=0")
        return
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, str(ROOT / "train" / "run.py"), "--orders", "all", "--out", str(Path(tmp) / "run")]
        t0 = time.perf_counter()
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
    if done.returncode != 0:
        print(done.stdout[-2000:], done.stderr[-2000:], sep="\n")
        raise SystemExit(f"train/run.py --orders all failed with exit code {done.returncode}")
    for line in done.stdout.splitlines():
        if line.startswith(("simulating", "population:", "order_independent")):
            print(f"  run.py: {line}")
    print(f"train/run.py --orders all: {wall:.1f} s wall, peak memory "
          f"{resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6:.2f} GB")
    print(f"all_orders_wall_s={wall:.1f}")


if __name__ == "__main__":
    with recorded("population", enabled="--skip-run" not in sys.argv[1:]):   # only whole runs are recorded
        main()
