"""The README's frame strip of one goal trial, simulated.

    python benches/trial_strip.py [CHECKPOINT] [--trial 3] [--out PNG] [--record]

Loads a run (default: checkpoints/default.pt, the default run's final state), plays one trial of
sim/default_objects.json with its first order's agent in the simulated world (the jar not reset between drops), and
draws a few camera frames of each drop into a PNG, captioned with what the agent expected and what the jar showed:
`--out PNG`, by default benches/trial_strip.png (tracked: the README shows it) with --record and the system's
temporary directory (/tmp/trial_strip.png) without it, so no tracked file is rewritten unless asked. About a minute
(recording renders every frame three times).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cli_args import count, record_flag  # noqa: E402

PNG = Path(__file__).with_name("trial_strip.png")   # tracked: rewritten only with --record


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoint", nargs="?", default=str(ROOT / "checkpoints" / "default.pt"))
    ap.add_argument("--trial", type=count, default=3, help="which trial of the default objects file (1-based)")
    ap.add_argument("--out", type=Path, help=f"the PNG (default: {PNG.relative_to(ROOT)} with --record, else "
                                             f"{Path(tempfile.gettempdir()) / PNG.name})")
    record_flag(ap, str(PNG.relative_to(ROOT)))
    a = ap.parse_args(argv)
    png = a.out or (PNG if a.record else Path(tempfile.gettempdir()) / PNG.name)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.objects import DEFAULT_OBJECTS_FILE, ObjectSet, load_objects
    from train.learning.experiment import load_experiment
    from train.learning.sim_pool import Physics
    from train.learning.goal_trials import play_trials

    objects = load_objects(DEFAULT_OBJECTS_FILE)
    if a.trial > len(objects.trials):
        ap.error(f"argument --trial: the default objects file has {len(objects.trials)} trials, got {a.trial}")
    one = ObjectSet(objects.jar, objects.train, objects.probe, objects.pool, [objects.trials[a.trial - 1]])
    exp = load_experiment(a.checkpoint)
    physics = Physics(one, seed=exp.seed, workers=1)
    try:
        rec = play_trials(exp, one, physics)[0][0]
        # the agent's drops again, filmed: every sequence starts from a fresh jar, so they are the same drops
        (outs,) = physics.run([("trial", tuple(rec["chosen"]), True)])
    finally:
        physics.close()
    per_drop = 4
    fig, axes = plt.subplots(len(outs), per_drop, figsize=(2.2 * per_drop, 1.9 * len(outs) + 0.4), squeeze=False)
    for k, (o, name) in enumerate(zip(outs, rec["chosen"])):
        frames = o.frames
        picks = [0, len(frames) // 3, 2 * len(frames) // 3, len(frames) - 1]
        for j, f in enumerate(picks):
            ax = axes[k, j]
            ax.imshow(frames[f])
            ax.axis("off")
            if j == 0:
                ax.set_title(f"drop {k + 1}: {name}", fontsize=7, loc="left")
            if j == per_drop - 1:
                ax.set_title(f"expected {rec['expected_cm3'][k]:.0f}, observed {o.observed_cm3:.0f} cm^3:\nball "
                             f"{'reachable' if o.goal_reached_after else 'out of reach'}", fontsize=6, loc="right")
    fig.suptitle(f"goal trial {a.trial}: stand {', '.join(rec['stand'])}\n{rec['drops']} drop(s), planner's fewest "
                 f"{rec['fewest_drops']}, random chooser {rec['random_drops_mean']:.2f} on average", fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    print(f"{png}: {rec['chosen']} observed {rec['observed_cm3']} goal {rec['goal_reached']}")


if __name__ == "__main__":
    main()
