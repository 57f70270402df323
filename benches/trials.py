"""Goal trials after exploration: does the learned model pick what reaches the ball in the fewest drops?

    python benches/trials.py [--seeds 20] [--orders 8] [--sets 100] [--stands 4] [--first-seed 0] [--record]

1. The crows' object tasks (sim/tasks/crows.json: sinking vs floating of the same size, solid vs hollow of the same
   look, large vs small sinker; Jelbert et al. 2014): for each seed (the maps' development and the senses' noise)
   the default train objects are explored in `--orders` random orders, then every trial of the file is played from
   the state after the exploration. Printed per task: the fraction of first choices that are right (an object a
   planner knowing Archimedes may drop first and still reach the ball in the fewest drops), beside a random chooser
   (exactly: the fraction of right objects on the stand) and "heaviest first" (by the true masses), and the mean
   drops beyond the planner's fewest.
2. Generated trials: sets of `sim.make_objects` (seeds first-seed.., `--pairs`, random jars), each explored in
   `--orders` orders; `--stands` stands of 3 objects drawn from its train and probe objects, among them enough to
   reach the ball. Printed: the fraction of trials whose drops equal the planner's fewest, mean drops of the agent,
   the planner, a random chooser (exact mean) and heaviest first.
Outcomes without physics (sim.trial.closed_form_drop: the objects' displacements, with the simulated robot's noise
from sim.sensor_model, add up in the jar; the ball is reachable after sim.trial.reach_cm3). Each trial starts from
the state after the exploration, learning on within it. Nothing of the model was chosen on these seeds.
Last line: `first_choice_correct_min=F generated_fewest=F agent_drops=D random_drops=D`. `--record` writes the
output into BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from aesop_torch.malloc import keep_freed_memory  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from sim.make_objects import generate  # noqa: E402
from sim.objects import ObjectSet, archimedes_cm3, load_objects, parse_objects  # noqa: E402
from sim.sensor_model import SensorModel  # noqa: E402
from sim.trial import (closed_form_drop, drops_to_goal, heaviest_first, optimal_first, random_drops_mean,  # noqa: E402
                       reach_cm3)
from train.learning.experiment import Experiment, closed_form_outcomes, draw_orders  # noqa: E402
from train.common.progress import Step  # noqa: E402
from train.learning.goal_trials import roomy_copy, run_trials  # noqa: E402
from cli_args import count, record_flag, seed  # noqa: E402
from record import run_main  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current (--record)

CROWS = ROOT / "sim" / "tasks" / "crows.json"


def explored(objects: ObjectSet, orders: int, seed: int):
    """(experiment after exploring the train objects in `orders` random orders, outcomes of every object)."""
    every = ObjectSet(objects.jar, objects.train + objects.probe + objects.pool)
    outcomes, _ = closed_form_outcomes(every, sensor=SensorModel(), seed=seed)
    _, probes = closed_form_outcomes(objects, sensor=SensorModel(), seed=seed)
    exp = Experiment([o.name for o in objects.train], [o.name for o in objects.probe],
                     draw_orders(len(objects.train), str(orders), seed), seed=seed)
    exp.outcomes, exp.probes = {n: outcomes[n] for n in exp.train_names}, probes
    while not exp.done:
        exp.step(lambda name, b, t: outcomes[name])
    return exp, outcomes


def play(exp, outcomes: dict, objects: ObjectSet, stand: tuple, seed: int) -> list[dict]:
    """One trial with every order's agent, from the state after the exploration: the B records."""
    need = reach_cm3(objects.jar)
    arch = {n: archimedes_cm3(objects.get(n), objects.jar) for n in stand}
    meas = {n: outcomes[n]["measurement"] for n in stand}
    agent = roomy_copy(exp.agent, len(stand))
    return [r[0] for r in run_trials(agent, [stand], meas, closed_form_drop(outcomes, need), objects.jar, arch,
                                     seed=seed)]


def crows(seeds: range, orders: int) -> dict:
    objects = load_objects(CROWS)
    tasks = [t.get("_task", "?") for t in json.loads(CROWS.read_text())["trials"]]
    need = reach_cm3(objects.jar)
    stats = {t: {"agent": [], "random": [], "heaviest": [], "excess": []} for t in dict.fromkeys(tasks)}
    with Step("crows' tasks: seeds", len(seeds), "seed", stream=sys.stderr) as bar:
        for seed in seeds:
            exp, outcomes = explored(objects, orders, seed)
            for task, stand in zip(tasks, objects.trials):
                vol = [archimedes_cm3(objects.get(n), objects.jar) for n in stand]
                ok = optimal_first(vol, need)
                s = stats[task]
                for r in play(exp, outcomes, objects, stand, seed):
                    s["agent"].append(ok[stand.index(r["chosen"][0])])
                    s["excess"].append(r["excess_drops"])
                s["random"].append(sum(ok) / len(ok))
                s["heaviest"].append(ok[heaviest_first([objects.get(n).mass_g for n in stand])])
            bar.update(1)
    return stats


def generated(seeds: range, orders: int, stands: int) -> dict:
    out = {"fewest": [], "agent": [], "planner": [], "random": [], "heaviest": []}
    with Step("generated sets", len(seeds), "set", stream=sys.stderr) as bar:
        for seed in seeds:
            objects = parse_objects(generate(seed, 8, 8, pairs=True))
            exp, outcomes = explored(objects, orders, seed)
            need = reach_cm3(objects.jar)
            pool = objects.train + objects.probe
            rng = np.random.default_rng([seed, 0x7121A1])
            made = tries = 0
            while made < stands and tries < 200:
                tries += 1
                pick = [pool[i] for i in rng.choice(len(pool), 3, replace=False)]
                vol = [archimedes_cm3(o, objects.jar) for o in pick]
                if need <= 0 or sum(vol) < need:
                    continue   # a stand that cannot reach the ball says nothing about choosing
                made += 1
                stand = tuple(o.name for o in pick)
                best = drops_to_goal(sorted(vol, reverse=True), need)
                for r in play(exp, outcomes, objects, stand, seed):
                    out["fewest"].append(r["drops"] == best)
                    out["agent"].append(r["drops"])
                    out["planner"].append(best)
                    out["random"].append(random_drops_mean(vol, need))
                    order = sorted(range(3), key=lambda i: -pick[i].mass_g)
                    out["heaviest"].append(drops_to_goal([vol[i] for i in order], need))
            bar.update(1)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=count, default=20, help="seeds of the crows' tasks (each: maps, noise, orders)")
    ap.add_argument("--orders", type=count, default=8, help="random orders of the exploration per seed or set")
    ap.add_argument("--sets", type=count, default=100, help="generated object sets")
    ap.add_argument("--stands", type=count, default=4, help="trials drawn per generated set")
    ap.add_argument("--first-seed", type=seed, default=0)
    record_flag(ap)
    a = ap.parse_args(argv)
    keep_freed_memory()   # freed tensors reused, for the peers in this process too (aesop_torch/malloc.py)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    s = crows(range(a.first_seed, a.first_seed + a.seeds), a.orders)
    print(f"crows' tasks (sim/tasks/crows.json) after the default exploration: {a.seeds} seeds x {a.orders} orders, "
          f"3 stands per task")
    print(f"{'task':<24}{'agent':>8}{'random':>8}{'heaviest':>10}{'excess drops':>14}   (fraction of right first "
          f"choices; excess: mean drops beyond the planner's)")
    mean = lambda v: sum(map(float, v)) / len(v)
    for task, v in s.items():
        print(f"{task:<24}{mean(v['agent']):>8.3f}{mean(v['random']):>8.3f}{mean(v['heaviest']):>10.3f}"
              f"{mean(v['excess']):>14.3f}")
    g = generated(range(a.first_seed, a.first_seed + a.sets), a.orders, a.stands)
    n = len(g["fewest"])
    print(f"\ngenerated trials: {a.sets} sets (make_objects --pairs, seeds {a.first_seed}..) x {a.orders} orders x "
          f"{a.stands} stands of 3 = {n} trials")
    print(f"  drops equal the planner's fewest: {mean(g['fewest']):.3f} of trials")
    print(f"  mean drops: agent {mean(g['agent']):.3f}, planner {mean(g['planner']):.3f}, random "
          f"{mean(g['random']):.3f}, heaviest first {mean(g['heaviest']):.3f}")
    worse = statistics.mean(g["agent"]) > statistics.mean(g["random"])
    print(f"  worse than random on average: {worse}; {time.perf_counter() - t0:.0f} s")
    print(f"first_choice_correct_min={min(mean(v['agent']) for v in s.values()):.3f} "
          f"generated_fewest={mean(g['fewest']):.3f} agent_drops={mean(g['agent']):.3f} "
          f"random_drops={mean(g['random']):.3f}")


if __name__ == "__main__":
    run_main("trials", main)
