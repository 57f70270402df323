"""The library's use of a finished run: load a checkpoint, predict for a new object.

    python benches/library_speed.py [--record]

Prints the median over repeats of `load_experiment("checkpoints/default.pt")` (imports already done), of the same in
a fresh interpreter (imports included: what a user's script pays once), and of `Experiment.predict` for one object
(4 agents, one per order; it runs on one torch thread), beside the peers: the load as it was before (the agents
re-trained their property maps, which the checkpoint then overwrote) and the agents' predict on torch's default
threads (what `Experiment.predict` ran on before). The last line is `load_s=X predict_ms=Y`. Printed, never asserted.
`--record` writes the output into BENCHMARKS.md.
"""

import argparse
import datetime
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from aesop_torch.malloc import keep_freed_memory  # noqa: E402

import torch  # noqa: E402

from aesop_torch import Agent  # noqa: E402
from cli_args import record_flag  # noqa: E402
from train.learning.experiment import Experiment, load_experiment, stack_measurements  # noqa: E402
from record import run_main  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current (--record)
from train.learning.sim_pool import cores  # noqa: E402

CKPT = ROOT / "checkpoints" / "default.pt"
GREEN_HEAVY_CYLINDER = {"rgb": [0.1, 0.7, 0.2], "extent_cm": [11.5, 6.36, 6.36], "fill": 0.785, "mass_g": 420.0}
COLD = ("import time, sys; t = time.perf_counter(); sys.path.insert(0, {root!r}); "
        "from train.learning.experiment import load_experiment; load_experiment({ckpt!r}); print(time.perf_counter() - t)")


def median_s(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    record_flag(ap)
    ap.parse_args()
    keep_freed_memory()   # freed tensors reused, for the peers in this process too (aesop_torch/malloc.py)
    load_experiment(CKPT)   # warm-up: first-call costs out of the figure
    load_s = median_s(lambda: load_experiment(CKPT), 15)
    cold = [float(subprocess.run([sys.executable, "-c", COLD.format(root=str(ROOT), ckpt=str(CKPT))],
                                 capture_output=True, text=True, check=True).stdout) for _ in range(3)]
    exp = load_experiment(CKPT)
    objects = [GREEN_HEAVY_CYLINDER] + [exp.probes[n]["measurement"] for n in exp.probe_names]
    exp.predict(objects[0])
    per_object = [median_s(lambda m=m: exp.predict(m), 30) for m in objects]
    predict_ms = 1e3 * statistics.median(per_object)
    # the peer: what predict ran before it took one thread, the agents' predict on torch's default threads
    batched = [stack_measurements([m] * len(exp.orders)) for m in objects]
    default_threads_ms = 1e3 * statistics.median([median_s(lambda b=b: exp.agent.predict(b), 30) for b in batched])

    state = torch.load(CKPT, weights_only=True)["experiment"]

    def old_load():   # the peer: agents built with developmental training, then overwritten by the checkpoint
        e = Experiment.from_state_dict(state)
        e.agent = Agent(e.config, batch=len(e.orders))
        e.agent.load_state_dict(state["agent"])
    old_s = median_s(old_load, 5)

    print(f"{datetime.date.today()}, {cores()} cores, torch {torch.__version__}")
    print(f"{CKPT.relative_to(ROOT)}: {len(exp.orders)} orders, {exp.n_episodes} episodes, "
          f"{torch.get_num_threads()} torch thread(s)")
    print(f"load_experiment         {load_s * 1e3:8.1f} ms  (median of 15; peer, maps re-trained then overwritten: "
          f"{old_s * 1e3:.1f} ms)")
    print(f"  in a fresh process    {statistics.median(cold) * 1e3:8.1f} ms  (imports included, median of 3)")
    print(f"predict, one object     {predict_ms:8.2f} ms  (median over {len(objects)} objects of the median of 30; "
          f"{len(exp.orders)} agents at once, 1 torch thread; on {torch.get_num_threads()} threads as before: "
          f"{default_threads_ms:.2f} ms)")
    print(f"load_s={load_s:.4f} predict_ms={predict_ms:.3f}")


if __name__ == "__main__":
    run_main("library_speed", main)
