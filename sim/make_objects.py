"""Random object sets: a seeded generator of valid objects files, for trying the model on sets it has never seen.

    python -m sim.make_objects --seed S [--train 8] [--probe 8] [--pairs] [--jar default|random] [--out FILE [--force]]

Every set holds every shape among its train objects, sinkers and floaters (densities log-uniform over 0.15 to
3 g/cm^3, at least a quarter of the train objects on each side of water), sizes spread over what fits the jar
(footprint up to the room beside the ball, height up to the water's depth), and random colours. With `--pairs`
the set also holds the pairs an experimenter sets up, each changing one property of one object: a colour pair
(another colour) and a weight pair (a floater and a sinker of the same look, the paper's episodes 1 and 3), and
with 12 or more train objects a size pair (the same object scaled, both sinking) and a shape pair (same size and
mass, another shape, both sinking). The rest are drawn freely. Probes are always drawn freely (novel objects).

The same seed and arguments give the same file, byte for byte. The result is validated by `sim.objects` (an object
that would not fit is redrawn), so what is written always loads.

`--out FILE` is written atomically (a temporary file in the same directory, renamed into place), never over an
existing file unless `--force` is given, never through a symbolic link, and never onto a directory or anything but
a regular file. Every refusal (a bad flag too) is one line on stderr, exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the project importable without installing it
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.objects import ObjectsConfig, ObjectsFileError, _printable, parse_objects
from sim.output_files import write_atomic

PROG = "python -m sim.make_objects"

SHAPE_ORDER = ("cylinder", "cube", "sphere", "box")


@dataclass(frozen=True)
class GeneratorConfig:
    # densities log-uniform over this range: corks and wood (0.15-0.8) to plastics, stone and light metals (1.2-3)
    density_g_cm3: tuple = (0.15, 3.0)
    # a random jar: inner diameter, height and the water's share of the height; jars around the
    # default (12 cm wide), wide enough for the hand's objects beside the 4 cm ball
    jar_diameter_cm: tuple = (11.0, 16.0)
    jar_height_cm: tuple = (18.0, 24.0)
    water_fraction: tuple = (0.6, 0.75)
    # smallest side: a 2 cm object is still a handful of pixels and a grip; lightest object 5 g: five standard
    # deviations of the wrist's noise (sim/sensor_model.py), so its weight is felt at all
    min_side_cm: float = 2.0
    min_mass_g: float = 5.0
    # an object displaces at most this share of the room between the water and the rim
    max_rise_fraction: float = 0.8
    # a cylinder's height over its diameter, a box's sides over its longest: log-uniform up to this aspect
    max_aspect: float = 3.0
    # a tall object is kept under the water's depth, so a sinker is covered and displaces its whole volume (the
    # closed form still covers one that sticks out; the generated sets just do not lean on it)
    height_margin_cm: float = 0.5
    # the light and heavy twins of a weight pair: densities this far below and above water
    weight_pair_densities: tuple = (0.3, 2.0)


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _colour(rng: np.random.Generator, avoid=None) -> list:
    """A random rgb, well away (> 0.5) from `avoid` when given."""
    while True:
        c = [round(float(x), 3) for x in rng.uniform(0.05, 0.95, 3)]
        if avoid is None or np.linalg.norm(np.subtract(c, avoid)) > 0.5:
            return c


def _volume(shape: str, dims: list) -> float:
    if shape == "cylinder":
        return math.pi * dims[0] ** 2 / 4 * dims[1]
    if shape == "sphere":
        return math.pi * dims[0] ** 3 / 6
    if shape == "cube":
        return dims[0] ** 3
    return dims[0] * dims[1] * dims[2]


def _dims(rng: np.random.Generator, shape: str, room: float, tall: float, cfg: GeneratorConfig) -> list:
    """Dimensions of a random `shape` whose footprint fits in `room` cm and whose height is at most `tall` cm."""
    lo = cfg.min_side_cm
    if shape in ("cube", "sphere"):
        side_max = min(tall, room / math.sqrt(2) if shape == "cube" else room)
        return [round(_log_uniform(rng, lo, side_max), 2)]
    if shape == "cylinder":
        d = _log_uniform(rng, lo, room)
        h = d * _log_uniform(rng, 1 / cfg.max_aspect, cfg.max_aspect)
        return [round(d, 2), round(min(max(h, lo), tall), 2)]
    # box: its longest side stands vertical (the objects file's rule), its footprint's diagonal fits the room
    z = _log_uniform(rng, lo, tall)
    x, y = (max(lo, z * _log_uniform(rng, 1 / cfg.max_aspect, 1.0)) for _ in range(2))
    scale = min(1.0, room / math.hypot(x, y))
    return [round(max(lo, x * scale), 2), round(max(lo, y * scale), 2), round(z, 2)]


def _mass(volume: float, density: float, config: ObjectsConfig, cfg: GeneratorConfig = GeneratorConfig()) -> float:
    return round(min(max(volume * density, cfg.min_mass_g), config.max_mass_g), 1)


def generate(seed: int, n_train: int = 8, n_probe: int = 8, pairs: bool = False, jar: str = "random",
             cfg: GeneratorConfig = GeneratorConfig(), config: ObjectsConfig = ObjectsConfig()) -> dict:
    """A valid objects file (as a dict) drawn from `seed`. ValueError if the counts cannot make such a set."""
    if n_train < 4:
        raise ValueError(f"n_train must be >= 4 (every shape among the train objects), got {n_train}")
    if pairs and n_train < 6:
        raise ValueError(f"--pairs needs n_train >= 6 (two pairs and two more), got {n_train}")
    if n_probe < 0:
        raise ValueError(f"n_probe must be >= 0, got {n_probe}")
    rng = np.random.default_rng([seed, n_train, n_probe, int(pairs)])
    if jar == "random":
        d = round(rng.uniform(*cfg.jar_diameter_cm), 1)
        h = round(rng.uniform(*cfg.jar_height_cm), 1)
        depth = round(h * rng.uniform(*cfg.water_fraction), 1)
        jar_d = {"inner_diameter_cm": d, "height_cm": h, "water_depth_cm": depth}
    elif jar == "default":
        jar_d = dict(zip(("inner_diameter_cm", "height_cm", "water_depth_cm"), config.default_jar))
    else:
        raise ValueError(f"jar must be 'random' or 'default', not {jar!r}")
    room = jar_d["inner_diameter_cm"] - config.ball_diameter_cm - 2 * config.fit_clearance_cm - 0.05
    tall = jar_d["water_depth_cm"] - cfg.height_margin_cm
    if room < cfg.min_side_cm or tall < cfg.min_side_cm:
        raise ValueError("the jar leaves no room for an object")

    area = math.pi * jar_d["inner_diameter_cm"] ** 2 / 4
    max_volume = cfg.max_rise_fraction * (jar_d["height_cm"] - jar_d["water_depth_cm"]) * area

    def free(shape: str, sinks: bool | None = None) -> dict:
        dims = _dims(rng, shape, room, tall, cfg)
        while _volume(shape, dims) > max_volume:   # it could overflow the jar: draw again
            dims = _dims(rng, shape, room, tall, cfg)
        lo, hi = cfg.density_g_cm3
        if sinks is None:
            density = _log_uniform(rng, lo, hi)
        else:
            density = _log_uniform(rng, 1.15, hi) if sinks else _log_uniform(rng, lo, 0.85)
        return {"shape": shape, "color": _colour(rng), "dims_cm": dims,
                "mass_g": _mass(_volume(shape, dims), density, config)}

    train: list[dict] = []
    if pairs:
        wl, wh = cfg.weight_pair_densities
        base = free(str(rng.choice(SHAPE_ORDER)))                          # colour pair
        train += [base, {**base, "color": _colour(rng, base["color"])}]
        base = free(str(rng.choice(SHAPE_ORDER)))                          # weight pair: a floater, a sinker
        v = _volume(base["shape"], base["dims_cm"])
        train += [{**base, "mass_g": _mass(v, wl, config)}, {**base, "mass_g": _mass(v, wh, config)}]
    if pairs and n_train >= 12:
        while True:                                                        # size pair: both sink
            base = free(str(rng.choice(SHAPE_ORDER)), sinks=True)
            if min(base["dims_cm"]) * 0.8 >= cfg.min_side_cm:              # the small one stays above the minimum
                break
        f = _log_uniform(rng, max(0.6, cfg.min_side_cm / min(base["dims_cm"])), 0.8)   # same mass, denser
        small = [round(x * f, 2) for x in base["dims_cm"]]
        train += [base, {**base, "dims_cm": small}]
        # shape pair: a cube and a sphere (or cylinder) of the same side, the same mass, both sinking
        side = round(_log_uniform(rng, 2.5, min(tall, room / math.sqrt(2))), 2)
        other = str(rng.choice(("sphere", "cylinder")))
        mass = _mass(side ** 3, 1.3, config, cfg)                            # denser than water as a cube
        colour = _colour(rng)
        train += [{"shape": "cube", "color": colour, "dims_cm": [side], "mass_g": mass},
                  {"shape": other, "color": colour, "dims_cm": [side, side] if other == "cylinder" else [side],
                   "mass_g": mass}]
    shapes = [s for s in SHAPE_ORDER if s not in {o["shape"] for o in train}]
    while len(train) < n_train:
        shape = shapes.pop(0) if shapes else str(rng.choice(SHAPE_ORDER))
        sinks = None
        n_sink = sum(_sinks(o) for o in train)
        left = n_train - len(train)
        if n_sink + left <= max(2, n_train // 4):
            sinks = True
        elif (len(train) - n_sink) + left <= max(2, n_train // 4):
            sinks = False
        train.append(free(shape, sinks))
    order = rng.permutation(len(train))
    train = [train[i] for i in order]
    probe = [free(str(rng.choice(SHAPE_ORDER))) for _ in range(n_probe)]
    for i, o in enumerate(train):
        o["name"] = f"t{i:02d}_{o['shape']}"
    for i, o in enumerate(probe):
        o["name"] = f"p{i:02d}_{o['shape']}"
    data = {"_comment": f"generated by python -m sim.make_objects --seed {seed} --train {n_train} --probe {n_probe}"
                        + (" --pairs" if pairs else "") + f" --jar {jar}",
            "jar": jar_d, "train": [_ordered(o) for o in train], "probe": [_ordered(o) for o in probe]}
    parse_objects(data, config)   # a generated set always loads; a bug here must not write a bad file
    return data


def _sinks(o: dict) -> bool:
    return o["mass_g"] > _volume(o["shape"], o["dims_cm"])


def _ordered(o: dict) -> dict:
    return {k: o[k] for k in ("name", "shape", "color", "dims_cm", "mass_g")}


class UsageError(Exception):
    """A refused command line or --out: one line on stderr, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):   # argparse prints its usage and the message; one line is enough
        raise UsageError(message)


def _out_problem(out: Path, force: bool) -> str | None:
    """Why `out` cannot be written, or None."""
    if str(out) == "":
        return "--out is empty"
    if out.is_symlink():
        return f"--out {out} is a symbolic link (not followed: give the file's own path)"
    if out.is_dir():
        return f"--out {out} is a directory (give a file name in it)"
    parent = out.parent
    if not parent.is_dir():
        return f"--out {out}: its directory {parent} does not exist" if not parent.exists() else \
            f"--out {out}: {parent} is not a directory"
    if out.exists():
        if not out.is_file():
            return f"--out {out} exists and is not a regular file"
        if not force:
            return f"--out {out} exists (--force to overwrite it)"
    return None


def write_atomically(out: Path, text: str, force: bool) -> None:
    """Write `text` to `out` through a temporary file in its directory: a reader never sees half a file, and a
    failure leaves no file behind. Without `force` the file is put in place with a hard link, which fails if the
    name was taken meanwhile; where hard links are not supported, by a rename after checking the name is free.
    UsageError (one line) if it cannot."""
    why = _out_problem(out, force)
    if why:
        raise UsageError(why)
    try:
        write_atomic(out, text.encode("utf-8"), replace=force)
    except FileExistsError:
        raise UsageError(f"--out {out} exists (--force to overwrite it)") from None
    except OSError as e:
        raise UsageError(f"--out {out}: cannot write it: {e.strerror or e}") from None


def main(argv=None) -> int:
    config = ObjectsConfig()
    ap = _Parser(prog=PROG, description=__doc__.split("\n")[0],
                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("--seed", type=int, required=True, help="the set's seed (same seed, same file)")
    ap.add_argument("--train", type=int, default=8,
                    help=f"train objects (4 to {config.max_objects}; >= 6 with --pairs)")
    ap.add_argument("--probe", type=int, default=8, help="probe objects")
    ap.add_argument("--pairs", action="store_true", help="include colour, weight, size and shape pairs")
    ap.add_argument("--jar", choices=("random", "default"), default="random", help="a random jar or the default")
    ap.add_argument("--out", default="-", help="output file ('-': standard output)")
    ap.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    try:
        a = ap.parse_args(argv)
        if not 0 <= a.seed < 2 ** 63 or not 4 <= a.train <= config.max_objects or not 0 <= a.probe <= 1000:
            raise UsageError(f"--seed must be in 0..2^63-1, --train in 4..{config.max_objects} (the objects "
                             f"file's limit), --probe in 0..1000")
        out = None if a.out == "-" else Path(a.out)
        if out is not None and (why := _out_problem(out, a.force)):
            raise UsageError(why)          # before the work, as well as when writing
        try:
            data = generate(a.seed, a.train, a.probe, a.pairs, a.jar, config=config)
        except (ValueError, ObjectsFileError) as e:
            raise UsageError(str(e)) from None
        text = json.dumps(data, indent=1) + "\n"
        if out is None:
            sys.stdout.write(text)
        else:
            write_atomically(out, text, a.force)
    except UsageError as e:
        print(f"{PROG}: error: {_printable(str(e))}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
