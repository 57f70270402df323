"""A lifetime of episodes: does the novel-object error keep falling as the robot explores more objects?

    python benches/learning_curve.py [--sets 20] [--objects 230] [--first-seed 0] [--model extended|paper] [--record]

Generated sets (`sim.make_objects --pairs`, seeds first-seed..) of 230 train objects and 16 probes, measurements and
outcomes with the simulated robot's noise, each explored in one random order by one agent whose memory is sized
for the whole run. After 8, 16, 32, 64, 128 and 230 explored objects: the median novel-object error
|predicted - Archimedes| / Archimedes (median over probes, then over sets; nothing recalled counts as 100 %),
beside the generalization bench's two peers fed the same episodes (k nearest neighbours, a small MLP), the floor
the senses leave (Archimedes itself applied to the probes as the robot measures them: min(mass, fill x extents),
water at 1 g/cm^3), and how many episodes the agent had stored and recalled per cue. Once the median reaches the
floor it can fall no further, so two more columns say whether learning goes on: how far the agent's error sits
above each probe's own floor (mean over probes, median over sets) and how many probes are more than 2 points
above it. And, since a median over sets can rise while most sets fall (or the reverse), each set's own curve:
how many sets' errors fell and rose since the previous count, and the median over sets of that change. Last line:
`median_error_8=E ... median_error_230=E`. `--record` writes the output into BENCHMARKS.md.

The agent runs as the sweep benches/learning_curve.toml runs it: each life is train/sweep.py's cell
(`train.sweeps.cell.run_cell`: the set's seed draws the noise, the order and the agent) and its figures (error, stored,
recalled, the floor and the error over it, sets fell / rose) are train/report.py's, so `python train/sweep.py
benches/learning_curve.toml` then `python -m train.report` gives them digit for digit (report.csv), and at scale on a
Ray cluster. The peers are no sweep conditions: they run here on the same lives in the same order.

The model's numbers were chosen on sets of seeds 1000 and up; the default seeds here (0..) were never looked at
while choosing them.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from aesop_torch.malloc import keep_freed_memory  # noqa: E402

import torch  # noqa: E402

import pyarrow as pa  # noqa: E402

from generalization import knn, mlp, raw_features, rel_errors  # noqa: E402
from sim.make_objects import generate  # noqa: E402
from sim.objects import parse_objects  # noqa: E402
from sim.sensor_model import SensorModel  # noqa: E402
from train.learning.experiment import closed_form_outcomes, draw_orders, stack_measurements  # noqa: E402
from train.common.progress import Step  # noqa: E402
from train.sweeps import cell as sweep_cell  # noqa: E402
from train.sweeps import spec as sweep_spec  # noqa: E402
from train.sweeps.report import summarise  # noqa: E402
from cli_args import at_least, count, record_flag, seed  # noqa: E402
from record import run_main  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current (--record)

CHECKS = (8, 16, 32, 64, 128, 230)


def peers(seed: int, n_train: int, checks) -> dict:
    """The generalization bench's two peers on one life, fed its episodes in the order its cell learns them (one
    order drawn from the set's seed): {"knn", "mlp"}: {n: the median over probes of the error after n objects}."""
    objs = parse_objects(generate(seed, n_train, 16, pairs=True))
    outcomes, probes = closed_form_outcomes(objs, sensor=SensorModel(), seed=seed)
    names = [o.name for o in objs.train]
    order = torch.tensor(draw_orders(len(names), "1", seed)[0])
    meas = stack_measurements([outcomes[names[i]]["measurement"] for i in order])
    pmeas = stack_measurements([probes[o.name]["measurement"] for o in objs.probe])
    truth = torch.tensor([probes[o.name]["archimedes_cm3"] for o in objs.probe])
    x_all = raw_features(meas)
    y_all = torch.tensor([outcomes[names[i]]["observed_cm3"] for i in order]).log()
    xq = raw_features(pmeas)
    out = {"knn": {}, "mlp": {}}
    for n in checks:
        out["knn"][n] = float(rel_errors(knn(x_all[None, :n], y_all[None, :n], xq).exp(), truth)[0])
        out["mlp"][n] = float(rel_errors(mlp(x_all[None, :n], y_all[None, :n], xq, seed * 1000 + n).exp(), truth)[0])
    return out


def sweep_doc(model: str, sets: int, objects: int, first_seed: int, checks) -> dict:
    """This run's lives as a sweep file: at the defaults, benches/learning_curve.toml (with --model paper, the same
    sets under a condition "paper")."""
    return {"world": "closed_form", "conditions": [{"name": model, "model": model}],
            "sets": [{"name": GROUP, "generate": {"seeds": [first_seed, first_seed + sets], "train": objects,
                                                  "probe": 16, "pairs": True},
                      "orders": 1, "checks": list(checks)}]}


GROUP = "lives"   # benches/learning_curve.toml's set group


def _moves(f: dict) -> str:
    """Sets whose error fell / rose since the previous count, and the median of the change (train/report.py's)."""
    if "fell" not in f:
        return ""
    moved = f"{f['fell']}/{f['rose']}"
    return f"{moved:>15} {f['change']:>+14.4f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sets", type=count, default=20)   # the median of 5 sets moved with any one of them
    ap.add_argument("--objects", type=at_least(8), default=230)
    ap.add_argument("--first-seed", type=seed, default=0)
    ap.add_argument("--model", choices=("paper", "extended"), default="extended", help="the agent's model")
    record_flag(ap)
    a = ap.parse_args()
    keep_freed_memory()   # freed tensors reused, for the peers in this process too (aesop_torch/malloc.py)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    checks = [n for n in CHECKS if n < a.objects] + [a.objects]
    # the agent: train/sweep.py's cells (benches/learning_curve.toml at the defaults), its figures train/report.py's
    _, cells = sweep_spec.resolve(sweep_doc(a.model, a.sets, a.objects, a.first_seed, checks), ROOT)
    tables, lives = [], []
    with Step("objects explored", a.sets * a.objects, unit="object", stream=sys.stderr) as bar:   # not recorded
        for c in cells:
            tables.append(sweep_cell.run_cell(c["spec"], c["objects"]))
            lives.append(peers(c["spec"]["seed"], a.objects, checks))
            bar.update(a.objects)
            t = tables[-1]
            err = dict(zip(t.column("episode").to_pylist(), t.column("probe_rel_error").to_pylist()))
            print(f"set {c['spec']['seed']}: agent " + " ".join(f"{n}:{err[n]:.3f}" for n in checks), flush=True)
    s = summarise(pa.concat_tables(tables))
    errs, figs = s["errors"][a.model, GROUP], s["checks"][a.model, GROUP]
    print(f"\n{a.sets} sets of {a.objects} train + 16 probe objects, one order each: median over probes, then over "
          f"sets")
    print(f"{'explored':>9} {'agent':>8} {'kNN':>8} {'MLP':>8} {'stored':>7} {'recalled/cue':>13} "
          f"{'over floor':>11} {'probes >2 pts over':>19} {'sets fell/rose':>15} {'median change':>14}")
    floor = figs[checks[0]]["floor"]
    med = {who: {n: statistics.median(lf[who][n] for lf in lives) for n in checks} for who in ("knn", "mlp")}
    for n in checks:
        f = figs[n]
        print(f"{n:>9} {errs[n][1]:>8.4f} {med['knn'][n]:>8.3f} {med['mlp'][n]:>8.3f} "
              f"{f['stored']:>7.0f} {f['recalled']:>13.1f} {f['over_floor']:>+11.4f} "
              f"{f['over_2pts']:>19} {_moves(f)}".rstrip())
    print(f"the senses' floor (Archimedes on the measured probes): {floor:.4f}. over floor: a set's mean over its "
          f"probes of the agent's error less the probe's floor (median over sets); probes >2 pts over: of "
          f"{16 * a.sets}, those more than 2 points above their floor (the gross errors, summed over sets); sets "
          f"fell/rose, median change: each set's error against its own at the previous count")
    print(f"{time.perf_counter() - t0:.0f} s")
    print(" ".join(f"median_error_{n}={errs[n][1]:.4f}" for n in checks))   # 4 places: 2 % is a target


if __name__ == "__main__":
    run_main("learning_curve", main)
