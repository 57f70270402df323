"""The Aesop battery as a learning experiment: subjects meet each task's apparatus on trial 1 and learn from it.

    python benches/battery.py [--seeds 2] [--subjects 3] [--first-seed 100] [--models extended paper]
                              [--kinds naive experienced] [--tasks T ...] [--ablate rules] [--aim gap|rise]
                              [--trials 20] [--jar-objects 64] [--workers 2] [--quick] [--out DIR] [--record]

Per task (sim/tasks/<task>.json) and per kind of subject (train/battery/tasks.py): naive subjects have the studies'
pre-training only (stones into a single jar-like tube of water), experienced ones a jar life of --jar-objects
generated objects first. Every subject meets the test apparatus and objects on trial 1, chooses by a softmax over
each option's value (its predicted rise less the reward's gap), the apparatus mirrored on half the trials, and
learns from every outcome. Subjects: --subjects per seed, each seed developing its own maps; the transfer model
(MODEL) always runs with its rules off too (--ablate rules: every model does).

Printed per model, rules and kind: per task trial 1 (% right, 95 % Wilson interval), the learning slope per trial
from a logistic model with an intercept per subject and its 95 % interval (Ghirlanda & Lind 2017; "sep." where
perfect separation leaves it infinite and an exact test decides), the subjects passing their own exact binomial
test, P(right | previous right) / P(right | previous wrong) (Hennefield et al. 2018), and the spread of the
subjects' share right. Beside it the animals' results with their citations. Learning curves (trial by trial, the
95 % interval over subjects as a band) go to --out, or with --record to benches/battery_curves.png (tracked) with
the output in BENCHMARKS.md. Last line:
`transfer_trial1_<M>= transfer_trial1_<M>_rules_off= transfer_trial1_paper= learned_tasks_naive_<M>=N/8
crows_agreement=K/6`: the experienced subjects' trial-1 rate over the object tasks, the naive subjects' tasks with
a slope above 0 at 95 %, and the tasks where the experienced subjects of M pass or fail as the crows did (Jelbert et
al. 2014), out of those both did. The protocol's numbers were chosen on seeds 1000 and up, never the bench's.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from train.common import exits  # noqa: E402  signals: one line, exit code 128 + the signal, the workers ended
if __name__ == "__main__":
    exits.early_signals()

from cli_args import at_least, count, record_flag, seed  # noqa: E402
from record import run_main  # noqa: E402

# the transfer model of the last line: "extended" until the contextual model (AgentConfig.named("contextual"))
# replaces it; switch it here
MODEL = "contextual"
TASKS = ("water_vs_sand", "sinking_vs_floating", "solid_vs_hollow", "high_vs_low_water", "narrow_vs_wide", "u_tube",
         "large_vs_small", "water_vs_sawdust")
OBJECT_TASKS = ("sinking_vs_floating", "solid_vs_hollow", "large_vs_small")
PNG = ROOT / "benches" / "battery_curves.png"

JELBERT = "Jelbert et al. 2014, PLoS ONE 9:e92895"
LOGAN = "Logan et al. 2014, PLoS ONE 9:e103049"
MILLER16 = "Miller et al. 2016, PLoS ONE 11:e0168056"
BIRD = "Bird & Emery 2009, Curr Biol 19:1410"
JAYS = "Cheke, Bird & Clayton 2011, Anim Cogn 14:441"
CHILDREN = "Cheke, Loissel & Clayton 2012, PLoS ONE 7:e40574"
MILLER17 = "Miller et al. 2017, PeerJ 5:e3484"
NOT_TESTED = "not tested"
NOT_CHECKED = "not checked"
# per task: the crows' result ("passed" / "failed": what the agreement compares), then each species' cell. Only what
# the papers' abstracts state; "not tested" where no paper here ran the task on that species
CROWS = {"water_vs_sand": "passed", "sinking_vs_floating": "passed", "solid_vs_hollow": "passed",
         "high_vs_low_water": "passed", "narrow_vs_wide": "failed", "u_tube": "failed",
         "large_vs_small": NOT_TESTED, "water_vs_sawdust": NOT_TESTED}
PUBLISHED = {   # task: (crows, rooks, jays, children)
    "water_vs_sand": (f"passed ({JELBERT})", NOT_TESTED,
                      f"passed: stones into liquid over a solid substrate ({JAYS})", NOT_CHECKED),
    "sinking_vs_floating": (f"passed ({JELBERT}); trained to prefer the floating object, chose it on the first trials "
                            f"and learned ({MILLER16})", NOT_TESTED, f"passed ({JAYS})",
                            f"passed: 5-7 y learned, 8-10 y from trial 1 ({CHILDREN}); passed ({MILLER16})"),
    "solid_vs_hollow": (f"passed ({JELBERT}); trained to prefer the hollow object, chose it on the first trials and "
                        f"learned ({MILLER16})", NOT_TESTED, NOT_TESTED, f"passed ({MILLER16})"),
    "high_vs_low_water": (f"passed ({JELBERT})", NOT_TESTED, NOT_TESTED,
                          f"passed on trial 1, 5-9 y, no feedback ({MILLER17})"),
    "narrow_vs_wide": (f"failed ({JELBERT})", NOT_TESTED, NOT_TESTED, NOT_CHECKED),
    "u_tube": (f"failed ({JELBERT}); modified U-tube failed as a group, one bird passed ({LOGAN})", NOT_TESTED,
               f"failed ({JAYS})", f"8-10 y passed from trial 1, 5-7 y as the birds ({CHILDREN})"),
    "large_vs_small": (NOT_TESTED, f"passed ({BIRD})", NOT_TESTED,
                       f"passed on trial 1, 5-9 y, no feedback ({MILLER17})"),
    "water_vs_sawdust": (NOT_TESTED, f"passed ({BIRD})", NOT_TESTED, f"passed: 4-7 y learned ({CHILDREN})"),
}


def conditions(models, kinds, ablate_all: bool) -> list[tuple]:
    """(model, ablate, kind) to run: every model with its rules, the transfer model (or with --ablate rules every
    model) without them too, each for every kind."""
    out = []
    for m in models:
        for ab in ((), ("rules",)) if (ablate_all or m == models[0]) else ((),):
            out += [(m, ab, k) for k in kinds]
    return out


def _job(args):
    """One (model, ablate, kind, seed): its subjects made once (jar life, pre-training), then every task from them."""
    import torch
    torch.set_num_threads(1)
    from sim.apparatus import load_task
    from train.battery.tasks import Protocol, make_subjects, run_task
    model, ablate, kind, s, subjects, task_names, aim, jar_objects, trials = args
    protocol = Protocol(jar_objects=jar_objects, trials=trials)
    ready = {s: make_subjects(model, kind, s, subjects, ablate, protocol)}
    out = {}
    for t in task_names:
        task = load_task(ROOT / "sim" / "tasks" / f"{t}.json")
        r = run_task(task, model, [s], subjects, ablate, aim=aim, kind=kind, protocol=protocol, ready=ready)
        r["peeks"] = peeks(r["log"], task)
        del r["log"], r["scores"]
        out[t] = r
    return (model, ablate, kind, s), out


def peeks(log, task) -> int:
    """Episodes before trial 1 with the test apparatus or a test object (the protocol says none)."""
    names = {o.name for o in task.objects}
    return sum(1 for subject in log for phase, where, what in subject
               if phase != "trial" and (where == task.name or what in names))


def curves_png(curves: dict, tasks, path: Path) -> None:
    """Per task the share of subjects right on each trial, a line per (model, rules, kind), its 95 % Wilson band."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from statsmodels.stats.proportion import proportion_confint
    cols = 4
    rows = (len(tasks) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax, task in zip(axes.flat, tasks):
        for label, (right, chance) in curves[task].items():
            n = len(right)
            x = list(range(1, len(right[0]) + 1))
            k = [sum(r[t] for r in right) for t in range(len(x))]
            lo, hi = proportion_confint(k, n, method="wilson")
            line, = ax.plot(x, [v / n for v in k], marker=".", lw=1, label=label)
            ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.12)
        ax.axhline(chance, color="grey", ls="--", lw=0.8)
        ax.set_title(task, fontsize=9)
        ax.set_ylim(-0.05, 1.05)
        ax.set_xlabel("trial")
        ax.set_ylabel("share of subjects right")
    for ax in list(axes.flat)[len(tasks):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6)
    fig.tight_layout()
    tmp = path.with_name(path.stem + ".tmp.png")
    fig.savefig(tmp, dpi=80)
    plt.close(fig)
    tmp.replace(path)


def label(model, ablate, kind) -> str:
    return f"{model}{', rules off' if ablate else ''}, {kind}"


def slope_text(s: dict) -> str:
    if s["ci"] is not None:
        return f"{s['slope']:+.2f} [{s['ci'][0]:+.2f}, {s['ci'][1]:+.2f}]"
    if s["slope"] in (float("inf"), float("-inf")):
        return f"sep.{'+' if s['slope'] > 0 else '-'} p={s['p']:.2g}"
    return "n.e. (all alike)"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=count, default=2, help="seeds, each developing its maps for its subjects")
    ap.add_argument("--subjects", type=count, default=3, help="subjects per seed (each its own seed for its jar "
                                                              "life, positions and choices)")
    ap.add_argument("--first-seed", type=seed, default=100)
    ap.add_argument("--models", nargs="+", default=[MODEL, "paper"],
                    help=f"models, the first the transfer model of the last line (default {MODEL} paper)")
    ap.add_argument("--kinds", nargs="+", choices=("naive", "experienced"), default=["naive", "experienced"])
    ap.add_argument("--tasks", nargs="+", choices=TASKS, default=list(TASKS), help="tasks to run (default all 8)")
    ap.add_argument("--ablate", choices=["rules"], action="append", default=[],
                    help="rules: every model also runs with its rules off (the transfer model always does)")
    ap.add_argument("--aim", choices=("gap", "rise"), default="gap",
                    help="an option's value: its predicted rise less the reward's gap (gap), or the rise alone (rise: "
                         "the gap unseen, its ablation)")
    ap.add_argument("--trials", type=at_least(2), default=20,
                    help="trials per task (the studies' 20; fewer only for a smoke test)")
    ap.add_argument("--jar-objects", type=at_least(6), default=64, help="the experienced subjects' jar life")
    ap.add_argument("--workers", type=count, default=2, help="processes")
    ap.add_argument("--quick", action="store_true",
                    help="a smoke test: 1 seed, 1 subject, the transfer model alone, 8 jar objects")
    ap.add_argument("--out", type=Path, default=Path("/tmp/battery"), help="where the learning curves' PNG goes "
                                                                           "(without --record)")
    record_flag(ap)
    a = ap.parse_args(argv)
    if a.record and (a.quick or a.trials != 20):
        ap.exit(2, "battery: --quick and --trials are for smoke tests, not recorded (drop --record)\n")
    from aesop_torch.agent_config import MODELS
    bad = [m for m in a.models if m not in MODELS]
    if bad:
        ap.exit(2, f"battery: --models {' '.join(bad)}: no such model (known: {', '.join(MODELS)})\n")
    if a.quick:
        a.seeds, a.subjects, a.models, a.jar_objects = 1, 1, a.models[:1], 8
    try:
        from sim.apparatus import load_task
        tasks = {t: load_task(ROOT / "sim" / "tasks" / f"{t}.json") for t in a.tasks}
    except (OSError, ValueError) as e:
        ap.exit(2, f"battery: {e}\n")
    png = PNG if a.record else a.out / "battery_curves.png"
    try:
        png.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        ap.exit(2, f"battery: --out {a.out}: {e}\n")
    from train.battery.tasks import agreement, analyse
    t0 = time.perf_counter()
    seeds = list(range(a.first_seed, a.first_seed + a.seeds))
    conds = conditions(a.models, a.kinds, bool(a.ablate))
    jobs = [(m, ab, k, s, a.subjects, list(tasks), a.aim, a.jar_objects, a.trials) for m, ab, k in conds
            for s in seeds]
    if a.workers > 1 and len(jobs) > 1:
        from train.learning.sim_pool import end_pool, quiet_pool   # workers ignore Ctrl-C, die with this process
        pool = quiet_pool(min(a.workers, len(jobs)), None, what="a battery worker")
        try:
            done = dict(pool.imap_unordered(_job, jobs))
        finally:
            end_pool(pool)
    else:
        done = dict(map(_job, jobs))
    merged = {}
    for m, ab, k in conds:
        for t in tasks:
            right = [r for s in seeds for r in done[(m, ab, k, s)][t]["right"]]
            swapped = [x for s in seeds for x in done[(m, ab, k, s)][t]["swapped"]]
            first = done[(m, ab, k, seeds[0])][t]
            merged[(m, ab, k, t)] = dict(analyse(right, first["chance"]), right=right, swapped=swapped,
                                         peeks=sum(done[(m, ab, k, s)][t]["peeks"] for s in seeds),
                                         options=first["options"], correct=first["correct"])
    n_subj = a.seeds * a.subjects
    aim = "" if a.aim == "gap" else " (--aim rise: rise alone)"
    print(f"Aesop battery: {a.seeds} seeds x {a.subjects} subjects = {n_subj} subjects per model and kind, "
          f"{a.trials} trials each, a softmax over (predicted rise - the reward's gap){aim}, "
          f"positions counterbalanced; experienced: a jar life of {a.jar_objects} objects first")
    print("t1: % right on trial 1 [95 % Wilson]; slope: per trial, logit with an intercept per subject [95 %] (sep.: "
          "perfect separation, exact p; n.e.: all alike); pass: subjects passing their own binomial test; "
          "after R/W: % right after a right / after a wrong choice; spread: min-max of the subjects' share right")
    for m, ab, k in conds:
        print(f"\n{label(m, ab, k)}")
        print(f"  {'task':<20}{'t1 %':>6}{'[95 %]':>12}  {'slope [95 %]':<26}{'pass':>6}{'after R/W':>11}"
              f"{'spread':>11}  result")
        for t in tasks:
            r = merged[(m, ab, k, t)]
            t1 = r["trial1"]
            af = r["after"]
            ci = f"[{100 * t1['ci'][0]:.0f}, {100 * t1['ci'][1]:.0f}]"
            after = f"{100 * af['after_right']:.0f}/{100 * af['after_wrong']:.0f}"
            spread = f"{100 * r['spread']['min']:.0f}-{100 * r['spread']['max']:.0f}"
            print(f"  {t:<20}{100 * t1['rate']:>6.0f}{ci:>12}  {slope_text(r['slope']):<26}"
                  f"{r['subjects_passed']:>3}/{len(r['subjects']):<2}{after:>11}{spread:>11}  "
                  f"{'passed' if r['passed'] else 'failed'}")
    swapped = [x for r in merged.values() for subject in r["swapped"] for x in subject]
    print(f"\npositions: the apparatus mirrored on {100 * sum(swapped) / len(swapped):.1f} % of {len(swapped)} trials; "
          f"episodes with the test apparatus or a test object before trial 1: "
          f"{sum(r['peeks'] for r in merged.values())}")
    for t in tasks:
        r = merged[(conds[0][0], (), conds[0][2], t)]
        print(f"  {t}: options {', '.join(r['options'])}; correct {[r['options'][i] for i in r['correct']]}")
    print("\npublished (crows | rooks | jays | children):")
    for t in tasks:
        print(f"  {t}: " + " | ".join(PUBLISHED[t]))
    curves = {t: {label(m, ab, k): (merged[(m, ab, k, t)]["right"], merged[(m, ab, k, t)]["chance"])
                  for m, ab, k in conds} for t in tasks}
    curves_png(curves, list(tasks), png)
    import resource
    cpu = sum(getattr(resource.getrusage(w), f) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
              for f in ("ru_utime", "ru_stime"))
    print(f"learning curves: {png.relative_to(ROOT) if png == PNG else png}; {time.perf_counter() - t0:.0f} s "
          f"({cpu:.0f} s of CPU over all processes)")

    M = a.models[0]

    def transfer(model, ablate):
        keys = [(model, ablate, "experienced", t) for t in OBJECT_TASKS if (model, ablate, "experienced", t) in merged]
        if not keys:
            return "n/a"
        k = sum(merged[x]["trial1"]["k"] for x in keys)
        n = sum(merged[x]["trial1"]["n"] for x in keys)
        return f"{k / n:.2f}"
    learned = (f"{sum(merged[(M, (), 'naive', t)]['slope']['learned'] for t in tasks)}/{len(tasks)}"
               if "naive" in a.kinds else "n/a")
    kind = "experienced" if "experienced" in a.kinds else "naive"
    agree, both = agreement({t: merged[(M, (), kind, t)]["passed"] for t in tasks}, CROWS)
    print(f"transfer_trial1_{M}={transfer(M, ())} transfer_trial1_{M}_rules_off={transfer(M, ('rules',))} "
          f"transfer_trial1_paper={transfer('paper', ())} learned_tasks_naive_{M}={learned} "
          f"crows_agreement={agree}/{both}")


if __name__ == "__main__":
    with exits.ending_signals():
        try:
            exits.raise_pending()
            run_main("battery", main)
        except KeyboardInterrupt as e:
            by, code = exits.how(e)
            print(f"{exits.fresh_line()}battery: interrupted{by}", file=sys.stderr)
            sys.exit(code)
