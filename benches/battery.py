"""The Aesop battery: does the agent learn the animal studies' apparatus tasks from its own episodes?

    python benches/battery.py [--seeds 2] [--orders 4] [--first-seed 0] [--trials 20] [--tasks T ...]
                              [--ablate rules|prior] [--aim gap|rise] [--out DIR] [--record]

Per task (sim/tasks/<task>.json, read by sim.apparatus.load_task): for each seed and each of `--orders` exploration
orders an agent (each model: paper, extended) drops the task's train objects into every tube, then plays `--trials`
trials: it predicts each (tube, object) option's outcome by recall, chooses the one whose predicted rise leaves the
reward least short of reach (--aim gap; --aim rise: the largest rise), acts (sim.apparatus.outcome as the world),
observes the reward tube's rise and learns (train/battery.py). Every agent is a subject; choices are pooled per
window (trial 1, 1-5, 1-20) and tested against chance (1 / options) with an exact one-sided binomial test:
p < 0.05 over trials 1-20 = passed. Beside it, the published results with their citations ("n/a (not found)"
where a figure could not be read on this machine). A PNG of learning curves per task goes to --out.
Nothing was tuned on these seeds. Last line: `tasks_passed_paper=N/8 tasks_passed_extended=N/8 crows=4/6`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cli_args import at_least, count, record_flag, seed  # noqa: E402
from record import run_main  # noqa: E402

TASKS = ("water_vs_sand", "sinking_vs_floating", "solid_vs_hollow", "high_vs_low_water", "narrow_vs_wide", "u_tube",
         "large_vs_small", "water_vs_sawdust")
JELBERT = "Jelbert et al. 2014, PLoS ONE 9:e92895"
BIRD = "Bird & Emery 2009, Curr Biol 19:1410"
CHEKE_JAYS = "Cheke, Bird & Clayton 2011, Anim Cogn 14:441"
NA = "n/a (not found)"
# per task: (crows, rooks, jays, children), each "passed"/"failed" with its citation, or NA
PUBLISHED = {
    "water_vs_sand": (f"passed ({JELBERT})", NA, NA, f"{NA} (Cheke, Loissel & Clayton 2012, PLoS ONE 7:e40574)"),
    "sinking_vs_floating": (f"passed ({JELBERT})", NA, NA, NA),
    "solid_vs_hollow": (f"passed ({JELBERT})", NA, NA, f"{NA} (Miller et al. 2017, PeerJ 5:e3484)"),
    "high_vs_low_water": (f"passed ({JELBERT})", NA, NA, f"{NA} (Miller et al. 2017, PeerJ 5:e3484)"),
    "narrow_vs_wide": (f"failed ({JELBERT})", NA, NA, f"{NA} (Miller et al. 2017, PeerJ 5:e3484)"),
    "u_tube": (f"failed ({JELBERT})", NA, f"failed ({CHEKE_JAYS})",
               f"{NA} (Cheke, Loissel & Clayton 2012; a modified U-tube: Logan et al. 2014, PLoS ONE 9:e103049)"),
    "large_vs_small": (NA, f"passed ({BIRD})", NA, NA),
    "water_vs_sawdust": (NA, f"passed ({BIRD})", NA, NA),
}
MODELS = ("paper", "extended")


def curves_png(results: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    tasks = list(results)
    cols = 4
    rows = (len(tasks) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3 * rows), squeeze=False)
    for ax, task in zip(axes.flat, tasks):
        for model, r in results[task].items():
            n = len(r["right"][0])
            ax.plot(range(1, n + 1), [sum(s[t] for s in r["right"]) / len(r["right"]) for t in range(n)],
                    marker=".", label=model)
        ax.axhline(next(iter(results[task].values()))["chance"], color="grey", ls="--", label="chance")
        ax.set_title(task, fontsize=9)
        ax.set_ylim(-0.05, 1.05)
        ax.set_xlabel("trial")
        ax.set_ylabel("fraction correct")
    for ax in list(axes.flat)[len(tasks):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=90)
    plt.close(fig)
    tmp.replace(path)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=count, default=2, help="seeds (each: the maps' development and the orders)")
    ap.add_argument("--orders", type=count, default=4, help="exploration orders per seed (each agent a subject)")
    ap.add_argument("--first-seed", type=seed, default=0)
    ap.add_argument("--trials", type=at_least(5), default=20, help="trials per subject (the studies: 20)")
    ap.add_argument("--tasks", nargs="+", choices=TASKS, default=list(TASKS), help="tasks to run (default all 8)")
    ap.add_argument("--ablate", choices=["rules", "prior"], action="append", default=[],
                    help="switch a part off (repeatable): rules (no rule fires), prior (the extended model's readout "
                         "without its physics priors; the paper model has none and runs as it is)")
    ap.add_argument("--aim", choices=("gap", "rise"), default="gap",
                    help="what a choice aims at: gap (the predicted rise against how far below reach the reward is "
                         "seen) or rise (the largest predicted rise, the gap unseen: its ablation)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/battery"), help="where the learning curves' PNG goes")
    record_flag(ap)
    a = ap.parse_args(argv)
    try:
        from sim.apparatus import load_task
    except ImportError as e:
        ap.exit(2, f"battery: sim/apparatus.py cannot be imported ({e})\n")
    try:
        tasks = {t: load_task(ROOT / "sim" / "tasks" / f"{t}.json") for t in a.tasks}
    except (OSError, ValueError) as e:
        ap.exit(2, f"battery: {e}\n")
    try:
        a.out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        ap.exit(2, f"battery: --out {a.out}: {e}\n")
    from train.battery import run_task
    t0 = time.perf_counter()
    seeds = list(range(a.first_seed, a.first_seed + a.seeds))
    ablate = tuple(a.ablate)

    def ablated(model):   # the prior is the extended model's alone
        return tuple(x for x in ablate if x != "prior" or model == "extended")

    results = {t: {m: run_task(task, m, seeds, a.orders, ablated(m), a.trials, aim=a.aim) for m in MODELS}
               for t, task in tasks.items()}
    off = "".join(f", {x} off" + (" (extended)" if x == "prior" else "") for x in dict.fromkeys(ablate))
    print(f"Aesop battery: {a.seeds} seeds x {a.orders} orders = {a.seeds * a.orders} subjects per model, "
          f"{a.trials} trials each{off}, aiming at the {a.aim}; pooled over subjects, "
          f"exact one-sided binomial test against chance, p < 0.05 over trials 1-{a.trials} = passed")
    head = f"{'task':<21}{'chance':>7}  " + "  ".join(
        f"{m + ': result':>16}{'t1 %':>6}{'1-5 %':>7}{'1-20 %':>7}{'p':>9}{'subj.':>6}" for m in MODELS)
    print(head)
    passed = {m: 0 for m in MODELS}
    for t, by_model in results.items():
        cells = []
        for m in MODELS:
            r = by_model[m]
            s = r["scores"]
            whole = s["1-20"]
            alone = sum(score_one(x, r["chance"]) for x in r["right"])
            passed[m] += whole.passed
            cells.append(f"{'passed' if whole.passed else 'failed':>16}{s['trial 1'].percent:>6.0f}"
                         f"{s['1-5'].percent:>7.0f}{whole.percent:>7.0f}{whole.p:>9.2g}{alone:>4}/{len(r['right'])}")
        print(f"{t:<21}{next(iter(by_model.values()))['chance']:>7.2f}  " + "  ".join(cells))
    print("(subj.: subjects passing alone over their own trials; options and the correct ones per task below)")
    for t, by_model in results.items():
        r = by_model["paper"]
        print(f"  {t}: options {', '.join(r['options'])}; correct {[r['options'][i] for i in r['correct']]}")
    print("\npublished (crows | rooks | jays | children):")
    for t in results:
        print(f"  {t}: " + " | ".join(PUBLISHED[t]))
    png = a.out / "battery_curves.png"
    curves_png(results, png)
    print(f"learning curves: {png}; {time.perf_counter() - t0:.0f} s")
    n = len(results)
    print(f"tasks_passed_paper={passed['paper']}/{n} tasks_passed_extended={passed['extended']}/{n} crows=4/6")


def score_one(right: list[bool], chance: float) -> bool:
    from train.battery import binomial_tail
    return binomial_tail(sum(right), len(right), chance) < 0.05


if __name__ == "__main__":
    run_main("battery", main)
