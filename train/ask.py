"""Ask a trained run what words bring to mind: python train/ask.py CHECKPOINT "heavy red cylinder"

From memory alone, no object in view (Agent.imagine): the words drive the object hub through the word map, the
stored object they name retro-activates the colour, shape, size and weight maps, and that object is anticipated
like a seen one. Prints, per order's agent, the expected colour, shape, size and weight with the map unit each
retro-activates, and the expected displacement; the last line is `expected_cm3=<value>` (the median over the orders
that know the words), or `expected_cm3=unknown` when the words name no object the agents know. A word outside the
vocabulary, or a checkpoint that is not a run's, is refused in one line (exit code 2): unknown words are not guessed.
"""

from __future__ import annotations

import sys
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2 or argv[0].startswith("-"):
        print('usage: python train/ask.py CHECKPOINT "words" (e.g. "light blue cube")', file=sys.stderr)
        return 2
    path, words = argv
    from train.checkpoint import CheckpointError
    from train.experiment import load_experiment
    if not Path(path).is_file():
        print(f"train/ask.py: error: no checkpoint file at {path}", file=sys.stderr)
        return 2
    try:
        exp = load_experiment(path)
        answer = exp.imagine(words)
    except (CheckpointError, ValueError) as e:
        print(f"train/ask.py: error: {e}", file=sys.stderr)
        return 2
    for i, o in enumerate(answer["orders"]):
        if not o["known"]:
            print(f"order {i + 1}: no object I know answers to {words!r} (best match {o['score']:.2f}, needs "
                  f"{exp.config.imagine_floor:.2f})")
            continue
        c, s, z, w = o["color"], o["shape"], o["size"], o["weight"]
        amb = f"; as well as another (score {o['runner_up']:.2f}): ambiguous" if o["runner_up"] >= o["score"] - 0.01 \
            else ""
        print(f"order {i + 1}: {words!r} names a stored object (match {o['score']:.2f}{amb}): colour "
              f"{c['nearest']} rgb={c['rgb']} (unit {c['unit'][0]}, {c['unit'][1]:.2f}); shape {s['kind']} "
              f"fill={s['fill']} (unit {s['unit'][0]}); size {z['cm']} cm (unit {z['unit'][0]}); weight "
              f"{w['g']} g (unit {w['unit'][0]}); expected {o['expected_cm3']} cm^3")
    e = answer["expected_cm3"]
    print(f"expected_cm3={'unknown' if e is None else e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
