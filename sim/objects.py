"""The objects file (CONTRACTS.md "Objects file"): parse it, refuse a bad one, and give each object its geometry.

Units are the file's: cm, g, g/cm^3 (the world converts to metres and kilograms).

An object stands on the stand, is carried and is dropped in the orientation its dims describe: a cylinder with its
axis vertical ([diameter, height]), a box with its z side vertical ([x, y, z]). "Fits in the jar" is checked in
that orientation: the circle around its footprint (cylinder and sphere: the diameter, cube and box: the diagonal of
the x-y face) must fit in the jar *beside the floating ball*, with `ObjectsConfig.fit_clearance_cm` to spare on
each side: footprint + ball + 2 clearance <= inner diameter. An object that only passes the mouth would land on the
ball and could pin it under water, adding the ball's volume to the reading. It must not be taller than the jar.
For a cylinder, a cube and a sphere that footprint is also their smallest cross-section; a box that would only fit
turned is refused with a hint to list its longest side last.

Unknown keys are refused (a typo such as "mass" for "mass_g" must not silently fall back to a default), except keys
that start with "_", which are comments (JSON has none). Validation reads the file and never writes anything.

What the file admits, a run must finish: every limit the world, the robot or the agent has is checked here, up front,
and named in `ObjectsConfig` with where it comes from (the jar's size from the table and the arm's reach, the water's
least depth from the ball, the lightest object from the hand and from the simulated water, the number of objects
from the agent's memory). A bad file is refused with one ObjectsFileError line naming the object and the field;
nothing else is raised for any JSON value in any field, and a message never carries a raw control character (a name
with a newline or an ANSI escape is shown escaped, `_show`).

Not refused, but outside the closed form: a light object longer than the jar is wide that cannot float upright
ends leaning on the wall, which then carries part of its weight, so it displaces less than its mass (a 3 x 18 cm,
60 g stick: 54 cm^3, not 60). No default object comes near that.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim.input_files import printable, quoted, show

DEFAULT_OBJECTS_FILE = Path(__file__).with_name("default_objects.json")
WATER_DENSITY_G_CM3 = 1.0
SHAPES = {"cylinder": 2, "cube": 1, "sphere": 1, "box": 3}  # shape -> number of dims
FILL = {"cylinder": math.pi / 4.0, "cube": 1.0, "sphere": math.pi / 6.0, "box": 1.0}  # volume / bounding box
DIMS_MEANING = {"cylinder": "[diameter, height]", "cube": "[side]", "sphere": "[diameter]", "box": "[x, y, z]"}

# Saturated enough that perception separates them, none pure 0/1 so a rendering never clips.
PALETTE = {
    "red": (0.85, 0.10, 0.10),
    "green": (0.10, 0.70, 0.20),
    "blue": (0.10, 0.25, 0.85),
    "yellow": (0.90, 0.85, 0.10),
    "orange": (0.95, 0.50, 0.05),
    "purple": (0.55, 0.15, 0.70),
    "white": (0.95, 0.95, 0.95),
    "black": (0.08, 0.08, 0.08),
    "grey": (0.50, 0.50, 0.50),
    "gray": (0.50, 0.50, 0.50),
    "brown": (0.50, 0.30, 0.10),
    "pink": (0.95, 0.55, 0.70),
    "cyan": (0.10, 0.80, 0.85),
}

NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*", re.ASCII)  # names become directory names for saved frames
MAX_NAME_CHARS = 64          # a name is a directory name for saved frames, and a label in figures and logs
MAX_FILE_BYTES = 1_000_000   # the default file is 2 kB; a file a thousand times larger is not an objects file
MAX_NESTING = 32             # the schema nests 4 deep; deeper input would only exhaust the parser's recursion
MAX_DIGITS = 32              # digits of an integer literal; a 400-digit mass would overflow the float conversion
OBJECT_KEYS = {"name", "shape", "color", "dims_cm", "mass_g"}
JAR_KEYS = {"inner_diameter_cm", "height_cm", "water_depth_cm"}
TOP_KEYS = {"jar", "train", "probe", "pool", "trials"}
TRIAL_KEYS = {"stand", "goal"}
DEFAULT_GOAL = "reach the green ball"   # the paper's goal: what the teacher says when a trial names none
MAX_GOAL_CHARS = 200         # a goal is a short phrase; this bounds the error line that quotes it
MAX_STAND = 8                # objects on the stand of one goal trial: the exact random baseline enumerates subsets


class ObjectsFileError(ValueError):
    """A bad objects file; the message is one line naming the object (or the jar) and the field.

    Whatever the message quotes (a name, a key, a path), it is printed escaped: a character that does not print
    (a newline, an ANSI escape, a bidi control) appears as its Python escape, so the error is one line and cannot
    move the terminal's cursor or recolour it."""

    def __init__(self, message: str):
        super().__init__(_printable(str(message)))


# the quoters of sim/input_files.py (one home for every input file's refusals), under the names this module and
# sim/apparatus.py use
_printable, _show, _quoted = printable, show, quoted


@dataclass(frozen=True)
class ObjectsConfig:
    # CONTRACTS.md's example jar (12 cm wide, 14 cm of water) but 19.5 cm tall, fitted to the robot's reach (world.py):
    # the iCub's hand cannot enter the mouth, so the ball is reachable once its top floats up to the rim; it starts
    # 2.2 cm below, the paper's heavy cylinder (+3.2 cm) brings it up, a 14 g float (+0.1 cm) does not.
    default_jar: tuple[float, float, float] = (12.0, 19.5, 14.0)  # inner diameter, height, water depth (cm)
    # the world's green ball (sim/water.py TankConfig): a ping-pong ball, 4 cm. Objects must fit beside it.
    ball_diameter_cm: float = 4.0
    # play on each side of the object and of the ball: the hand lets go within a few mm of its aim.
    fit_clearance_cm: float = 0.25
    # below 1 cm an object is a few pixels for the 96 px camera and too small for the hand to hold.
    min_dim_cm: float = 1.0
    # the iCub's arm carries about a kilogram; heavier would make the carry a test of the motors, not of the task.
    max_mass_g: float = 1000.0
    # the lightest object: the least mass the hand reports (sim/sensor_model.py SensorModel.min_felt_mass_g, which
    # sim/world.py's weighing also floors to). Below it an object would be felt as heavier than it is; far below it
    # the engine breaks: pybullet takes a body under 2.2e-16 kg as static, and the hand "lifting" it fights its own
    # motors (1e-300 g was felt as 22,707 g).
    min_mass_g: float = 0.1
    # a light, wide object bobs on the water at w = sqrt(rho g a / (m (1 - a / A))) (a: its cross-section at the
    # surface, A the jar's: the level rises as it sinks), and the simulated water (sim/water.py, explicit buoyancy
    # at TankConfig.timestep_s = 1/240 s) follows that only while w dt stays under ~1.5: measured, a 7 x 1 cm disc
    # of 0.3 g (w dt ~ 1.8) jumps out of the 12 cm jar, of 0.4 g (~ 1.6) settles; a 24.5 x 1 cm disc in a 29 cm
    # jar fails at 10.5 g (~ 1.6), settles from 12 g (~ 1.5). So m (1 - a / A) / a >= this (`min_mass_g_for`), a
    # taken as large as the object can show: w dt <= 0.83 at the limit (tests/test_water.py), about 3x the mass
    # where it fails; the 7 cm disc at least 1.8 g, the 24.5 cm one 41 g, a 3 cm cube 0.36 g.
    min_mass_per_area_g_cm2: float = 0.025
    # the jar stands on the table (sim/world.py WorldConfig: its axis at jar_xy = (0.27, 0.06) m, 15 cm from the
    # table's front edge at x = 0.12 m, which keeps the robot's pelvis clear; TankConfig's walls are 0.5 cm thick),
    # so its inner diameter is at most 2 x (15 - 0.5) cm (tests/test_world.py derives it and runs the widest jar).
    max_jar_diameter_cm: float = 29.0
    # the hand carries an object's bottom 4 cm over the rim and withdraws 6 cm above that after letting go
    # (WorldConfig carry_clearance_cm, hover_cm; the palm 1.5 cm over the object's top): its highest point is the
    # table (0.40 m) + the jar's 1 cm bottom + jar height + object height + 11.5 cm. The palm, facing down, reaches
    # 1.00 m above the jar (IK; measured: jar + object 47 cm runs, 48 cm fails), so jar + object height <= this,
    # 2 cm short of it; the jar's own height is at most this less the smallest object (min_dim_cm).
    max_jar_plus_object_cm: float = 45.0
    # the green ball (ball_diameter_cm, 2.7 g: sim/water.py TankConfig) floats with a 0.7 cm draft; 2 cm of water
    # keeps it 1.3 cm off the bottom, floating free (shallower, it rests on the bottom and the closed form no longer
    # holds; under 0.24 cm the jar holds less water than the ball displaces and the world cannot be built).
    min_water_depth_cm: float = 2.0
    # objects one life can meet: train (one episode each) plus pool (dropped in goal trials). Not the memory's 230
    # episodes: a memory or hub that forgets when full (MemoryConfig / HubConfig.when_full) runs any length, and the
    # runner refuses up front only a `refuse` one that is too small (train/runner/settings.py check_capacity); 2000 bounds a
    # file to what one life can simulate (about a second per drop with physics, ~35 min).
    max_objects: int = 2000

    @property
    def max_jar_height_cm(self) -> float:
        """The tallest jar the hand can carry the smallest object over."""
        return self.max_jar_plus_object_cm - self.min_dim_cm

    @property
    def min_jar_diameter_cm(self) -> float:
        """The narrowest jar that holds the smallest object beside the ball, with the clearances."""
        return self.ball_diameter_cm + 2.0 * self.fit_clearance_cm + self.min_dim_cm


@dataclass(frozen=True)
class JarSpec:
    """A cylindrical jar; `water_depth_cm` is the level at the start, with the green ball already floating in it."""
    inner_diameter_cm: float
    height_cm: float
    water_depth_cm: float

    @property
    def area_cm2(self) -> float:
        return math.pi * self.inner_diameter_cm ** 2 / 4.0

    def to_dict(self) -> dict:
        return {"inner_diameter_cm": self.inner_diameter_cm, "height_cm": self.height_cm,
                "water_depth_cm": self.water_depth_cm}


@dataclass(frozen=True)
class ObjectSpec:
    """One object of the file, its colour resolved to rgb; geometry as it stands (z up), in cm and g."""
    name: str
    shape: str
    dims_cm: tuple[float, ...]
    mass_g: float
    rgb: tuple[float, float, float]

    @property
    def size_xyz_cm(self) -> np.ndarray:
        """Bounding box as it stands (x, y, z), z vertical."""
        d = self.dims_cm
        if self.shape == "cylinder":
            return np.array([d[0], d[0], d[1]], dtype=float)
        return np.array(d * 3 if len(d) == 1 else d, dtype=float)

    @property
    def extent_cm(self) -> np.ndarray:
        """Bounding box sides sorted descending: what the eye measures regardless of pose."""
        return np.sort(self.size_xyz_cm)[::-1].copy()

    @property
    def height_cm(self) -> float:
        return float(self.size_xyz_cm[2])

    @property
    def volume_cm3(self) -> float:
        return float(np.prod(self.size_xyz_cm)) * FILL[self.shape]

    @property
    def fill(self) -> float:
        """Volume / bounding-box volume: 1 for a cube or box, pi/4 for a cylinder, pi/6 for a sphere."""
        return FILL[self.shape]

    @property
    def max_section_cm2(self) -> float:
        """A bound on the largest plane cross-section through the object, the most it can show at a water surface
        in any pose: a sphere's great circle; otherwise longest side x the diagonal of the other two (a cube's
        diagonal rectangle exactly, above a box's or a cylinder's largest section)."""
        if self.shape == "sphere":
            return math.pi * self.dims_cm[0] ** 2 / 4.0
        e = self.extent_cm
        return float(e[0] * math.hypot(e[1], e[2]))

    @property
    def density_g_cm3(self) -> float:
        return self.mass_g / self.volume_cm3

    @property
    def sinks(self) -> bool:
        return self.density_g_cm3 > WATER_DENSITY_G_CM3

    @property
    def footprint_cm(self) -> float:
        """Diameter of the circle around the footprint as it stands: what must pass the jar's mouth."""
        x, y, _ = self.size_xyz_cm
        return float(x) if self.shape in ("cylinder", "sphere") else math.hypot(x, y)

    def submerged_upright_cm3(self, level_cm: float) -> float:
        """Volume below `level_cm` when the object stands upright on the jar's bottom."""
        h = min(max(level_cm, 0.0), self.height_cm)
        if self.shape == "sphere":
            r = self.dims_cm[0] / 2.0
            return math.pi * h * h * (3.0 * r - h) / 3.0  # spherical cap
        return self.volume_cm3 * h / self.height_cm  # prisms: cross-section x height

    def exact_measurement(self) -> dict:
        """What a perfect eye and hand would report: {rgb, extent_cm (descending), fill, mass_g}, plain floats."""
        return {"rgb": [float(x) for x in self.rgb], "extent_cm": [float(x) for x in self.extent_cm],
                "fill": float(self.fill), "mass_g": float(self.mass_g)}

    def true_values(self) -> dict:
        """The file's size, shape cue and mass, logged beside what was perceived (never given to the agent)."""
        return {k: v for k, v in self.exact_measurement().items() if k != "rgb"}

    def to_dict(self) -> dict:
        return {"name": self.name, "shape": self.shape, "color": list(self.rgb), "dims_cm": list(self.dims_cm),
                "mass_g": self.mass_g}


@dataclass(frozen=True)
class ObjectSet:
    """A validated objects file: the jar, the objects dropped one per episode (train), the ones only lifted (probe),
    and for goal trials (sim/trial.py) objects used only there (pool) and the trials, each the names on the stand,
    with per trial the teacher's goal phrase (goals: words in lower case, or None for DEFAULT_GOAL; empty: all
    default)."""
    jar: JarSpec
    train: list[ObjectSpec]
    probe: list[ObjectSpec] = field(default_factory=list)
    pool: list[ObjectSpec] = field(default_factory=list)
    trials: list[tuple[str, ...]] = field(default_factory=list)
    goals: list[str | None] = field(default_factory=list)

    def get(self, name: str) -> ObjectSpec:
        for o in self.train + self.probe + self.pool:
            if o.name == name:
                return o
        known = ", ".join(o.name for o in self.train + self.probe + self.pool)
        raise ValueError(f"no object named {name!r} (known: {known})")

    def canonical(self) -> dict:
        """The resolved set as plain JSON values (colours as rgb): equal iff the experiments are the same. A file
        without pool and trials gives exactly the keys it always did."""
        out = {"jar": self.jar.to_dict(), "train": [o.to_dict() for o in self.train],
               "probe": [o.to_dict() for o in self.probe]}
        if self.pool:
            out["pool"] = [o.to_dict() for o in self.pool]
        if self.trials:
            goals = self.goals or [None] * len(self.trials)
            out["trials"] = [{"stand": list(t), **({"goal": g} if g else {})} for t, g in zip(self.trials, goals)]
        return out


def min_mass_g_for(spec: ObjectSpec, jar: JarSpec, config: ObjectsConfig = ObjectsConfig()) -> float:
    """The lightest `spec` (its shape and size) may be in `jar` for the world to simulate it: the hand's least
    felt mass, and enough mass for the simulated water to follow its bobbing (ObjectsConfig.min_mass_per_area_g_cm2):
    m >= mu a / (1 - a / A), with a the most it can show at the surface: its largest cross-section
    (`ObjectSpec.max_section_cm2`), at most the room beside the ball (a disc of the jar's diameter less the ball
    and the clearances), so a / A < 1."""
    room = jar.inner_diameter_cm - config.ball_diameter_cm - 2.0 * config.fit_clearance_cm
    a = min(spec.max_section_cm2, math.pi * room * room / 4.0)
    return max(config.min_mass_g, config.min_mass_per_area_g_cm2 * a / (1.0 - a / jar.area_cm2))


def archimedes_cm3(spec: ObjectSpec, jar: JarSpec, water_density_g_cm3: float = WATER_DENSITY_G_CM3) -> float:
    """The closed-form yardstick: water displaced once the object is at rest in the jar (1 g/cm^3 water, or the
    world's water: sim.water.WaterConfig.density / 1000, which the runner passes).

    A floater displaces its mass; a sinker its volume, or only its submerged part when it stands on the bottom and
    sticks out of the water. One formula covers both: V = min(m / rho, S(L0 + V / A)), where S(L) is the volume of
    the upright object below level L and A the jar's cross-section. The right side grows with V at a slope below
    a/A < 1 (a: the object's cross-section), so there is exactly one V; it is found by bisection to 1e-12 cm^3.
    For a prism that sticks out this is L = L0 / (1 - a/A), V = a L. (A floater in water too shallow to float it
    is grounded and displaces S(L) < m; no object of the default set comes near that.)
    """
    m_over_rho = spec.mass_g / water_density_g_cm3
    A, L0 = jar.area_cm2, jar.water_depth_cm

    def excess(v: float) -> float:  # decreasing in v; zero at the answer
        return min(m_over_rho, spec.submerged_upright_cm3(L0 + v / A)) - v

    lo, hi = 0.0, min(m_over_rho, spec.volume_cm3)
    while hi - lo > 1e-12 * max(1.0, hi):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if excess(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


# -- parsing ---------------------------------------------------------------------------------------------------------

def load_objects(path, config: ObjectsConfig = ObjectsConfig()) -> ObjectSet:
    """Read and validate an objects file; ObjectsFileError (one line) if anything is wrong. Reading is bounded
    (a regular file of at most MAX_FILE_BYTES: `/dev/zero` or a pipe is refused, not read forever), and so are
    nesting depth and integer length, which would otherwise end in a RecursionError or an OverflowError."""
    from sim.input_files import InputFileError, read_json
    try:
        # NaN and Infinity are let through to the schema, which names the field that holds one
        data = read_json(path, "the objects file", MAX_FILE_BYTES, MAX_NESTING, strict=False)
    except InputFileError as e:
        raise ObjectsFileError(str(e)) from None
    return parse_objects(data, config)


def parse_objects(data, config: ObjectsConfig = ObjectsConfig()) -> ObjectSet:
    """Validate the decoded JSON of an objects file and return the ObjectSet."""
    if not isinstance(data, dict):
        raise ObjectsFileError("the objects file must be a JSON object with a 'train' list")
    _no_unknown_keys(data, TOP_KEYS, "the objects file")
    jar = _parse_jar(data["jar"], config) if "jar" in data else JarSpec(*config.default_jar)
    if "train" not in data:
        raise ObjectsFileError("the objects file has no 'train' list")
    for group in ("train", "probe", "pool"):
        if not isinstance(data.get(group, []), list):
            raise ObjectsFileError(f"'{group}' must be a list of objects, not {_show(data[group])}")
    if not data["train"]:
        raise ObjectsFileError("'train' is empty: at least one object must be dropped")
    met = len(data["train"]) + len(data.get("pool", []))
    if met > config.max_objects:
        raise ObjectsFileError(f"'train' and 'pool' hold {met} objects, more than the agent can learn in one life "
                               f"(at most {config.max_objects})")
    groups = {group: [_parse_object(item, f"{group}[{i}]", jar, config) for i, item in enumerate(data.get(group, []))]
              for group in ("train", "probe", "pool")}
    seen = set()
    for o in groups["train"] + groups["probe"] + groups["pool"]:
        if o.name in seen:
            raise ObjectsFileError(f"object '{o.name}' field 'name': duplicate name (train, probe and pool names "
                                   f"must all differ)")
        seen.add(o.name)
    trials, goals = _parse_trials(data.get("trials", []), seen)
    return ObjectSet(jar, groups["train"], groups["probe"], groups["pool"], trials, goals)


def _parse_trials(items, names: set) -> tuple[list[tuple[str, ...]], list[str | None]]:
    """`trials`: a list of {"stand": [names], "goal": phrase}, 1 to MAX_STAND distinct objects of train, probe or
    pool each, and optionally the teacher's goal (`_parse_goal`). Returns the stands and the goals."""
    if not isinstance(items, list):
        raise ObjectsFileError(f"'trials' must be a list of {{\"stand\": [names], \"goal\": phrase}}, not "
                               f"{_show(items)}")
    trials, goals = [], []
    for i, t in enumerate(items):
        where = f"trials[{i}]"
        if not isinstance(t, dict):
            raise ObjectsFileError(f"{where}: must be an object {{\"stand\": [names]}}, not {_show(t)}")
        _no_unknown_keys(t, TRIAL_KEYS, where)
        stand = t.get("stand")
        if not isinstance(stand, list) or not 1 <= len(stand) <= MAX_STAND:
            raise ObjectsFileError(f"{where} field 'stand': must be a list of 1 to {MAX_STAND} object names, not "
                                   f"{_show(stand)}")
        for n in stand:
            if not isinstance(n, str) or n not in names:
                raise ObjectsFileError(f"{where} field 'stand': {_show(n)} is not an object of train, probe "
                                       f"or pool")
        if len(set(stand)) != len(stand):
            raise ObjectsFileError(f"{where} field 'stand': an object is listed twice")
        trials.append(tuple(stand))
        goals.append(_parse_goal(t["goal"], where) if "goal" in t else None)
    return trials, goals


def _parse_goal(goal, where: str) -> str | None:
    """A trial's goal phrase: words the agent knows (aesop_torch.encoders: the vocabulary and a few function words),
    among them the goal's own (GOAL_WORDS: "reach" and "ball"); anything else is no goal the robot could be given
    (the agent's Agent.hear_goal says the same: the goal is heard when both its words are). Lower case, one space
    between words; None when it is the default goal."""
    from aesop_torch.encoders import FUNCTION_WORDS, GOAL_WORDS, VOCABULARY, unknown_words
    at = f"{where} field 'goal'"
    if not isinstance(goal, str) or not goal.strip() or len(goal) > MAX_GOAL_CHARS:
        raise ObjectsFileError(f"{at}: must be a phrase of 1 to {MAX_GOAL_CHARS} characters, not {_show(goal)}")
    if unknown := unknown_words(goal):
        raise ObjectsFileError(f"{at}: unknown word(s) {', '.join(map(_quoted, unknown))} (the words I know: "
                               f"{' '.join(VOCABULARY + FUNCTION_WORDS)})")
    words = goal.lower().replace("_", " ").split()
    if not set(GOAL_WORDS) <= set(words):
        raise ObjectsFileError(f"{at}: {_show(goal)} is no goal I know: I can reach the ball (a goal says "
                               f"{' and '.join(map(repr, GOAL_WORDS))}, e.g. {json.dumps(DEFAULT_GOAL)})")
    phrase = " ".join(words)
    return None if phrase == DEFAULT_GOAL else phrase


def _no_unknown_keys(d: dict, allowed: set, where: str):
    unknown = sorted(k for k in d if k not in allowed and not str(k).startswith("_"))
    if unknown:
        raise ObjectsFileError(f"{where}: unknown key {_quoted(unknown[0])} (allowed: {', '.join(sorted(allowed))}; "
                               f"keys starting with '_' are comments)")


def _number(value, where: str, field: str) -> float:
    """A finite number > 0 as a float. A Python int too large for a float (parse_objects on a dict; a file's
    integers are already bounded by MAX_DIGITS) is refused here, not by an OverflowError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ObjectsFileError(f"{where} field '{field}': must be a number, not {_show(value)}")
    if isinstance(value, int) and abs(value) >= 10 ** MAX_DIGITS:
        raise ObjectsFileError(f"{where} field '{field}': must be a number of at most {MAX_DIGITS} digits")
    if not math.isfinite(value):
        raise ObjectsFileError(f"{where} field '{field}': must be finite, not {value}")
    if value <= 0:
        raise ObjectsFileError(f"{where} field '{field}': must be > 0, not {value}")
    return float(value)


def _parse_jar(jar, config: ObjectsConfig) -> JarSpec:
    """The jar: each of its three numbers finite and > 0 (missing ones default), the water shallower than the jar,
    and within what the world can hold: a jar on the table, the robot able to carry an object over its rim, and
    water the ball floats in (`ObjectsConfig`)."""
    if not isinstance(jar, dict):
        raise ObjectsFileError(f"jar: must be an object with inner_diameter_cm, height_cm, water_depth_cm, not "
                               f"{_show(jar)}")
    _no_unknown_keys(jar, JAR_KEYS, "jar")
    default = dict(zip(("inner_diameter_cm", "height_cm", "water_depth_cm"), config.default_jar))
    vals = {k: _number(jar[k], "jar", k) if k in jar else default[k] for k in default}
    d, h, w = vals["inner_diameter_cm"], vals["height_cm"], vals["water_depth_cm"]
    if d > config.max_jar_diameter_cm:
        raise ObjectsFileError(f"jar field 'inner_diameter_cm': {d:g} cm is wider than the table holds (at most "
                               f"{config.max_jar_diameter_cm:g} cm: the jar stands on the table, in reach of the "
                               f"robot)")
    if d < config.min_jar_diameter_cm:
        raise ObjectsFileError(f"jar field 'inner_diameter_cm': {d:g} cm leaves no room for an object beside the "
                               f"{config.ball_diameter_cm:g} cm ball (at least {config.min_jar_diameter_cm:g} cm)")
    if h > config.max_jar_height_cm:
        raise ObjectsFileError(f"jar field 'height_cm': {h:g} cm is taller than the robot can carry an object over "
                               f"(at most {config.max_jar_height_cm:g} cm: jar and object together at most "
                               f"{config.max_jar_plus_object_cm:g} cm)")
    if w >= h:
        raise ObjectsFileError(f"jar field 'water_depth_cm': {w:g} cm of water does not fit in a jar {h:g} cm high")
    if w < config.min_water_depth_cm:
        raise ObjectsFileError(f"jar field 'water_depth_cm': {w:g} cm of water is too shallow for the "
                               f"{config.ball_diameter_cm:g} cm ball to float (at least "
                               f"{config.min_water_depth_cm:g} cm)")
    return JarSpec(**vals)


def _parse_color(color, where: str) -> tuple[float, float, float]:
    if isinstance(color, str):
        if color.lower() not in PALETTE:
            raise ObjectsFileError(f"{where} field 'color': unknown colour name {_quoted(color)} "
                                   f"(known: {', '.join(sorted(PALETTE))}; or [r, g, b] in 0..1)")
        return PALETTE[color.lower()]
    ok = isinstance(color, list) and len(color) == 3 and all(
        isinstance(c, (int, float)) and not isinstance(c, bool) and abs(c) < 10 ** MAX_DIGITS
        and math.isfinite(c) and 0.0 <= c <= 1.0 for c in color)
    if not ok:
        raise ObjectsFileError(f"{where} field 'color': must be a palette name or [r, g, b] with each in 0..1, "
                               f"not {_show(color)}")
    return tuple(float(c) for c in color)


def parse_object(item, jar=None, config: ObjectsConfig = ObjectsConfig()) -> ObjectSpec:
    """One object in the objects file's format ({"shape", "color", "dims_cm", "mass_g"}, "name" optional) checked
    as the file checks it, in the default jar unless one is given (a jar dict as in the file, or a JarSpec). For
    the library's predict: one schema for an object, whether it comes in a file or in a call."""
    jar = jar if isinstance(jar, JarSpec) else _parse_jar({} if jar is None else jar, config)
    item = {"name": "object", **item} if isinstance(item, dict) else item
    return _parse_object(item, "object", jar, config)


def _parse_object(item, where: str, jar: JarSpec, config: ObjectsConfig) -> ObjectSpec:
    if not isinstance(item, dict):
        raise ObjectsFileError(f"{where}: must be an object with name, shape, color, dims_cm, mass_g")
    name = item.get("name")
    if not isinstance(name, str) or len(name) > MAX_NAME_CHARS or not NAME_RE.fullmatch(name):
        raise ObjectsFileError(f"{where} field 'name': must be 1 to {MAX_NAME_CHARS} letters, digits, '_', '.', "
                               f"'-' starting with a letter or digit (it names a directory), not {_show(name)}")
    where = f"object '{name}'"
    _no_unknown_keys(item, OBJECT_KEYS, where)
    for k in ("shape", "color", "dims_cm", "mass_g"):
        if k not in item:
            raise ObjectsFileError(f"{where} field '{k}': missing")
    shape = item["shape"]
    if not isinstance(shape, str) or shape not in SHAPES:
        raise ObjectsFileError(f"{where} field 'shape': unknown shape {_show(shape)} "
                               f"(known: {', '.join(SHAPES)})")
    dims = item["dims_cm"]
    if not isinstance(dims, list) or len(dims) != SHAPES[shape]:
        raise ObjectsFileError(f"{where} field 'dims_cm': a {shape} takes {SHAPES[shape]} number(s) "
                               f"{DIMS_MEANING[shape]}, not {_show(dims)}")
    dims = tuple(_number(d, where, "dims_cm") for d in dims)
    if min(dims) < config.min_dim_cm:
        raise ObjectsFileError(f"{where} field 'dims_cm': {min(dims)} cm is below the smallest size the robot "
                               f"can see and hold ({config.min_dim_cm} cm)")
    mass = _number(item["mass_g"], where, "mass_g")
    if mass > config.max_mass_g:
        raise ObjectsFileError(f"{where} field 'mass_g': {mass:g} g is more than the arm carries "
                               f"({config.max_mass_g:g} g)")
    if mass < config.min_mass_g:
        raise ObjectsFileError(f"{where} field 'mass_g': {mass:g} g is lighter than the hand can feel (at least "
                               f"{config.min_mass_g:g} g)")
    spec = ObjectSpec(name, shape, dims, mass, _parse_color(item["color"], where))
    _check_fits(spec, jar, where, config)
    least = min_mass_g_for(spec, jar, config)
    if mass < least:
        raise ObjectsFileError(f"{where} field 'mass_g': {mass:g} g is too light for its size in this jar: the "
                               f"simulated water could not follow it bobbing (at least {least:.2f} g; see "
                               f"ObjectsConfig.min_mass_per_area_g_cm2)")
    return spec


def _fixed(x: float) -> str:
    """x to two decimals, or in three significant digits if that would be a long line (a 1e300 cm footprint)."""
    return f"{x:.2f}" if abs(x) < 1e6 else f"{x:.3g}"


def _check_fits(spec: ObjectSpec, jar: JarSpec, where: str, config: ObjectsConfig):
    room = jar.inner_diameter_cm - config.ball_diameter_cm - 2.0 * config.fit_clearance_cm
    if spec.footprint_cm > room:
        hint = " (stand it on its smallest face: list its longest side last)" if spec.shape == "box" else ""
        raise ObjectsFileError(f"{where} field 'dims_cm': its footprint ({_fixed(spec.footprint_cm)} cm across) does "
                               f"not fit beside the {config.ball_diameter_cm} cm ball in the jar's "
                               f"{jar.inner_diameter_cm} cm (at most {room:.2f} cm across){hint}")
    if spec.height_cm > jar.height_cm:
        raise ObjectsFileError(f"{where} field 'dims_cm': {spec.height_cm:g} cm tall, taller than the "
                               f"{jar.height_cm:g} cm jar")
    if spec.height_cm + jar.height_cm > config.max_jar_plus_object_cm:
        raise ObjectsFileError(f"{where} field 'dims_cm': {spec.height_cm:g} cm tall, too tall for the hand to "
                               f"carry over the {jar.height_cm:g} cm jar's rim (jar and object together at most "
                               f"{config.max_jar_plus_object_cm:g} cm)")
    v = archimedes_cm3(spec, jar)
    level = jar.water_depth_cm + v / jar.area_cm2
    if level > jar.height_cm:
        field = "dims_cm" if spec.sinks else "mass_g"
        raise ObjectsFileError(f"{where} field '{field}': it displaces {v:.0f} cm^3, which would raise the water "
                               f"from {jar.water_depth_cm} to {level:.1f} cm, over the jar's {jar.height_cm} cm rim")
