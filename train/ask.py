"""Ask a trained run what words bring to mind, or what objects will displace:

    python train/ask.py CHECKPOINT "heavy red cylinder"
    python train/ask.py CHECKPOINT --objects FILE

With --objects, every object of an objects file (train, probe and pool; the schema of CONTRACTS.md), perceived
exactly as the file describes it and anticipated with learning frozen: one line per object with what each order's
agents expect (their median) beside Archimedes in the file's jar, and a last line `median_rel_error=<value>`.

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


USAGE = 'usage: python train/ask.py CHECKPOINT "words" (e.g. "light blue cube") | CHECKPOINT --objects FILE'


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv in (["-h"], ["--help"]):
        print(USAGE + "\n\n" + __doc__.strip())
        return 0
    by_file = len(argv) == 3 and argv[1] == "--objects"
    if not (by_file or len(argv) == 2) or argv[0].startswith("-"):
        print(USAGE, file=sys.stderr)
        return 2
    path = argv[0]
    from sim.objects import ObjectsFileError, load_objects
    from train.learning.checkpoint import CheckpointError
    from train.learning.experiment import load_experiment
    if not Path(path).is_file():
        print(f"train/ask.py: error: no checkpoint file at {path}", file=sys.stderr)
        return 2
    try:
        objects = load_objects(argv[2]) if by_file else None
    except ObjectsFileError as e:   # named as the runner names it: which file, then what is wrong
        print(f"train/ask.py: error: --objects {argv[2]}: {e}", file=sys.stderr)
        return 2
    try:
        exp = load_experiment(path)
        if by_file:
            return _objects(exp, objects)
        words = argv[1]
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


def _objects(exp, objects) -> int:
    """Each object of the file anticipated by every order's agent: the median beside Archimedes."""
    import statistics

    from sim.objects import archimedes_cm3
    errors = []
    for spec in objects.train + objects.probe + objects.pool:
        predicted = [p for p in exp.predict(spec.exact_measurement()).tolist() if p == p]   # NaN: nothing recalled
        truth = archimedes_cm3(spec, objects.jar)
        if not predicted:
            print(f"{spec.name}: nothing recalled (Archimedes {truth:.1f} cm^3)")
            errors.append(1.0)   # expecting nothing is as wrong as expecting 0 cm^3, as the benches count it
            continue
        median = statistics.median(predicted)
        errors.append(abs(median - truth) / truth)
        print(f"{spec.name}: expected {median:.1f} cm^3 (orders {min(predicted):.1f}-{max(predicted):.1f}), "
              f"Archimedes {truth:.1f}, error {100 * errors[-1]:.1f} %")
    print(f"median_rel_error={statistics.median(errors):.4f}" if errors else "median_rel_error=unknown")
    return 0


if __name__ == "__main__":
    sys.exit(main())
