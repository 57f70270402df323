"""How well the robot perceives an object's fate (sank or floats) on the physics path, near neutral density.

    python benches/fate_perception.py [--objects N] [--seed S]

The closed-form runs (train/experiment.py closed_form_outcomes, the benches, the battery's jar life) tell the agent
the fate a model of the robot's perception gives (sim/sensor_model.py FatePerception), not the engine's density
test. This bench measures what that model stands on: N generated objects (the generator's shapes and sizes, in
the default jar), their densities log-uniform over 0.8-1.25 g/cm^3 (the band where a floater rides deep and a sinker
barely sinks), each dropped with full physics (sim/world.py run_episode: the side camera through the glass decides,
sim/perception.py rests_on_bottom). It prints the confusion matrix of perceived against true fate, the misjudged
objects' densities, and the band's edges those errors imply. Printed, never asserted: a few minutes of physics.
"""

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from cli_args import count, seed  # noqa: E402
from sim.make_objects import SHAPE_ORDER, GeneratorConfig, _colour, _dims, _volume  # noqa: E402
from sim.objects import ObjectsConfig, parse_objects  # noqa: E402
from sim.world import World  # noqa: E402

DENSITY_BAND = (0.8, 1.25)


def objects_near_neutral(n: int, seed_: int, band: tuple = DENSITY_BAND) -> dict:
    """An objects file (as a dict) of n generated objects in the default jar, densities log-uniform in the band."""
    rng = np.random.default_rng([seed_, n, 45])
    config, cfg = ObjectsConfig(), GeneratorConfig()
    d, h, depth = config.default_jar
    room = d - config.ball_diameter_cm - 2 * config.fit_clearance_cm - 0.05
    tall = depth - cfg.height_margin_cm
    train = []
    for i in range(n):
        shape = SHAPE_ORDER[i % 4]
        dims = _dims(rng, shape, room, tall, cfg)
        v = _volume(shape, dims)
        dens = math.exp(rng.uniform(*map(math.log, band)))
        train.append({"name": f"o{i:03d}_{shape}", "shape": shape, "color": _colour(rng), "dims_cm": dims,
                      "mass_g": round(min(max(v * dens, cfg.min_mass_g), config.max_mass_g), 1)})
    return {"jar": dict(zip(("inner_diameter_cm", "height_cm", "water_depth_cm"), config.default_jar)),
            "train": train, "probe": []}


def main(args) -> None:
    band = (args.low, args.high)
    objects = parse_objects(objects_near_neutral(args.objects, args.seed, band))
    world = World(objects, seed=args.seed)
    rows = []
    for o in objects.train:
        out = world.run_episode(o.name)
        rows.append((o.name, o.density_g_cm3, o.sinks, bool(out.sank), bool(getattr(out, "delivered", True))))
        print(f"{o.name:<16} density {o.density_g_cm3:6.3f}  sinks {int(o.sinks)}  seen sank {int(out.sank)}"
              f"{'' if rows[-1][4] else '  (not delivered)'}", flush=True)
    world.close()
    rows = [r for r in rows if r[4]]
    m = np.zeros((2, 2), dtype=int)
    for _, _, truth, seen, _ in rows:
        m[int(truth), int(seen)] += 1
    print(f"\nfate perceived on the physics path: {len(rows)} objects, densities {band[0]}-{band[1]} "
          f"g/cm^3, default jar, seed {args.seed}")
    print("                 seen floats  seen sank")
    print(f"  true floats    {m[0, 0]:>11}  {m[0, 1]:>9}")
    print(f"  true sinks     {m[1, 0]:>11}  {m[1, 1]:>9}")
    wrong = sorted((dens, truth, seen) for _, dens, truth, seen, _ in rows if truth != seen)
    print("  misjudged (density, true sinks, seen sank):", [(round(dd, 3), int(t), int(s)) for dd, t, s in wrong])
    sank_d = [dd for _, dd, _, s, _ in rows if s]
    float_d = [dd for _, dd, _, s, _ in rows if not s]
    print(f"  seen sank: densities {min(sank_d, default=float('nan')):.3f}..{max(sank_d, default=float('nan')):.3f}; "
          f"seen floating: {min(float_d, default=float('nan')):.3f}..{max(float_d, default=float('nan')):.3f}")
    print(f"fate_confusion=[[{m[0, 0]},{m[0, 1]}],[{m[1, 0]},{m[1, 1]}]] misjudged={len(wrong)}/{len(rows)}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=count, default=40, help="objects dropped (default 40)")
    ap.add_argument("--low", type=float, default=DENSITY_BAND[0], help="lowest density, g/cm^3")
    ap.add_argument("--high", type=float, default=DENSITY_BAND[1], help="highest density, g/cm^3")
    ap.add_argument("--seed", type=seed, default=0, help="the objects' and the world's seed (default 0)")
    main(ap.parse_args())
