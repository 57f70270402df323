"""The README's frame strip of one goal trial, simulated: python benches/trial_strip.py [CHECKPOINT] [--trial 3]

Loads a run (default: checkpoints/default.pt, the default run's final state), plays one trial of
sim/default_objects.json with its first order's agent in the simulated world (the jar not reset between drops), and
draws a few camera frames of each drop into benches/trial_strip.png, captioned with what the agent expected and
what the jar showed. About a minute (recording renders every frame three times).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PNG = Path(__file__).with_name("trial_strip.png")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoint", nargs="?", default=str(ROOT / "checkpoints" / "default.pt"))
    ap.add_argument("--trial", type=int, default=3, help="which trial of the default objects file (1-based)")
    a = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.objects import DEFAULT_OBJECTS_FILE, ObjectSet, load_objects
    from train.experiment import load_experiment
    from train.physics import Physics
    from train.trials import play_trials

    objects = load_objects(DEFAULT_OBJECTS_FILE)
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
    fig.savefig(PNG, dpi=90)
    print(f"{PNG.relative_to(ROOT)}: {rec['chosen']} observed {rec['observed_cm3']} goal {rec['goal_reached']}")


if __name__ == "__main__":
    main()
