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

Not refused, but outside the closed form: a light object longer than the jar is wide that cannot float upright
ends leaning on the wall, which then carries part of its weight, so it displaces less than its mass (a 3 x 18 cm,
60 g stick: 54 cm^3, not 60). No default object comes near that.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

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
    """A bad objects file; the message is one line naming the object (or the jar) and the field."""


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


def archimedes_cm3(spec: ObjectSpec, jar: JarSpec) -> float:
    """The closed-form yardstick: water displaced once the object is at rest in the jar (1 g/cm^3 water).

    A floater displaces its mass; a sinker its volume, or only its submerged part when it stands on the bottom and
    sticks out of the water. One formula covers both: V = min(m / rho, S(L0 + V / A)), where S(L) is the volume of
    the upright object below level L and A the jar's cross-section. The right side grows with V at a slope below
    a/A < 1 (a: the object's cross-section), so there is exactly one V; it is found by bisection to 1e-12 cm^3.
    For a prism that sticks out this is L = L0 / (1 - a/A), V = a L. (A floater in water too shallow to float it
    is grounded and displaces S(L) < m; no object of the default set comes near that.)
    """
    m_over_rho = spec.mass_g / WATER_DENSITY_G_CM3
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
    try:
        # O_NONBLOCK: opening a FIFO must not wait for a writer; a regular file reads as usual
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise ObjectsFileError("the objects file is not a regular file")
            raw = f.read(MAX_FILE_BYTES + 1)
        if len(raw) > MAX_FILE_BYTES:
            raise ObjectsFileError(f"the objects file is larger than {MAX_FILE_BYTES:,} bytes")
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ObjectsFileError(f"cannot read the objects file: {type(e).__name__}: {e}") from None
    depth = _nesting(text)
    if depth > MAX_NESTING:
        raise ObjectsFileError(f"the objects file nests {depth} levels deep (at most {MAX_NESTING})")
    try:
        data = json.loads(text, parse_int=_bounded_int)
    except json.JSONDecodeError as e:
        raise ObjectsFileError(f"malformed JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    except RecursionError:
        raise ObjectsFileError(f"the objects file nests too deeply (at most {MAX_NESTING} levels)") from None
    return parse_objects(data, config)


def _bounded_int(literal: str) -> int:
    if len(literal.lstrip("-")) > MAX_DIGITS:
        raise ObjectsFileError(f"an integer of {len(literal.lstrip('-'))} digits (at most {MAX_DIGITS}): "
                               f"{literal[:12]}...")
    return int(literal)


def _nesting(text: str) -> int:
    """The deepest nesting of [ and { outside strings (the file is not yet known to be valid JSON)."""
    depth = deepest = 0
    for c in re.sub(r'"(?:[^"\\]|\\.)*"', "", text):
        if c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


def parse_objects(data, config: ObjectsConfig = ObjectsConfig()) -> ObjectSet:
    """Validate the decoded JSON of an objects file and return the ObjectSet."""
    if not isinstance(data, dict):
        raise ObjectsFileError("the objects file must be a JSON object with a 'train' list")
    _no_unknown_keys(data, TOP_KEYS, "the objects file")
    jar = _parse_jar(data.get("jar"), config)
    if "train" not in data:
        raise ObjectsFileError("the objects file has no 'train' list")
    groups = {}
    for group in ("train", "probe", "pool"):
        items = data.get(group, [])
        if not isinstance(items, list):
            raise ObjectsFileError(f"'{group}' must be a list of objects")
        groups[group] = [_parse_object(item, f"{group}[{i}]", jar, config) for i, item in enumerate(items)]
    if not groups["train"]:
        raise ObjectsFileError("'train' is empty: at least one object must be dropped")
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
        raise ObjectsFileError("'trials' must be a list of {\"stand\": [names], \"goal\": phrase}")
    trials, goals = [], []
    for i, t in enumerate(items):
        where = f"trials[{i}]"
        if not isinstance(t, dict):
            raise ObjectsFileError(f"{where}: must be an object {{\"stand\": [names]}}")
        _no_unknown_keys(t, TRIAL_KEYS, where)
        stand = t.get("stand")
        if not isinstance(stand, list) or not 1 <= len(stand) <= MAX_STAND:
            raise ObjectsFileError(f"{where} field 'stand': must be a list of 1 to {MAX_STAND} object names")
        for n in stand:
            if not isinstance(n, str) or n not in names:
                raise ObjectsFileError(f"{where} field 'stand': {json.dumps(n)} is not an object of train, probe "
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
        shown = json.dumps(goal if not isinstance(goal, str) or len(goal) <= 40 else goal[:40] + "...")
        raise ObjectsFileError(f"{at}: must be a phrase of 1 to {MAX_GOAL_CHARS} characters, not {shown}")
    if unknown := unknown_words(goal):
        raise ObjectsFileError(f"{at}: unknown word(s) {', '.join(map(repr, unknown))} (the words I know: "
                               f"{' '.join(VOCABULARY + FUNCTION_WORDS)})")
    words = goal.lower().replace("_", " ").split()
    if not set(GOAL_WORDS) <= set(words):
        raise ObjectsFileError(f"{at}: {json.dumps(goal)} is no goal I know: I can reach the ball (a goal says "
                               f"{' and '.join(map(repr, GOAL_WORDS))}, e.g. {json.dumps(DEFAULT_GOAL)})")
    phrase = " ".join(words)
    return None if phrase == DEFAULT_GOAL else phrase


def _no_unknown_keys(d: dict, allowed: set, where: str):
    unknown = sorted(k for k in d if k not in allowed and not str(k).startswith("_"))
    if unknown:
        raise ObjectsFileError(f"{where}: unknown key '{unknown[0]}' (allowed: {', '.join(sorted(allowed))}; "
                               f"keys starting with '_' are comments)")


def _number(value, where: str, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ObjectsFileError(f"{where} field '{field}': must be a number, not {json.dumps(value)}")
    if not math.isfinite(value):
        raise ObjectsFileError(f"{where} field '{field}': must be finite, not {value}")
    if value <= 0:
        raise ObjectsFileError(f"{where} field '{field}': must be > 0, not {value}")
    return float(value)


def _parse_jar(jar, config: ObjectsConfig) -> JarSpec:
    if jar is None:
        return JarSpec(*config.default_jar)
    if not isinstance(jar, dict):
        raise ObjectsFileError("jar: must be an object with inner_diameter_cm, height_cm, water_depth_cm")
    _no_unknown_keys(jar, JAR_KEYS, "jar")
    default = dict(zip(("inner_diameter_cm", "height_cm", "water_depth_cm"), config.default_jar))
    vals = {k: _number(jar[k], "jar", k) if k in jar else default[k] for k in default}
    if vals["water_depth_cm"] >= vals["height_cm"]:
        raise ObjectsFileError(f"jar field 'water_depth_cm': {vals['water_depth_cm']} cm of water does not fit "
                               f"in a jar {vals['height_cm']} cm high")
    return JarSpec(**vals)


def _parse_color(color, where: str) -> tuple[float, float, float]:
    if isinstance(color, str):
        if color.lower() not in PALETTE:
            raise ObjectsFileError(f"{where} field 'color': unknown colour name '{color}' "
                                   f"(known: {', '.join(sorted(PALETTE))}; or [r, g, b] in 0..1)")
        return PALETTE[color.lower()]
    ok = isinstance(color, list) and len(color) == 3 and all(
        isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) and 0.0 <= c <= 1.0
        for c in color)
    if not ok:
        raise ObjectsFileError(f"{where} field 'color': must be a palette name or [r, g, b] with each in 0..1, "
                               f"not {json.dumps(color)}")
    return tuple(float(c) for c in color)


def _parse_object(item, where: str, jar: JarSpec, config: ObjectsConfig) -> ObjectSpec:
    if not isinstance(item, dict):
        raise ObjectsFileError(f"{where}: must be an object with name, shape, color, dims_cm, mass_g")
    name = item.get("name")
    if not isinstance(name, str) or not NAME_RE.fullmatch(name) or len(name) > MAX_NAME_CHARS:
        shown = json.dumps(name if not isinstance(name, str) or len(name) <= MAX_NAME_CHARS else name[:40] + "...")
        raise ObjectsFileError(f"{where} field 'name': must be 1 to {MAX_NAME_CHARS} letters, digits, '_', '.', "
                               f"'-' starting with a letter or digit (it names a directory), not {shown}")
    where = f"object '{name}'"
    _no_unknown_keys(item, OBJECT_KEYS, where)
    for k in ("shape", "color", "dims_cm", "mass_g"):
        if k not in item:
            raise ObjectsFileError(f"{where} field '{k}': missing")
    shape = item["shape"]
    if shape not in SHAPES:
        raise ObjectsFileError(f"{where} field 'shape': unknown shape {json.dumps(shape)} "
                               f"(known: {', '.join(SHAPES)})")
    dims = item["dims_cm"]
    if not isinstance(dims, list) or len(dims) != SHAPES[shape]:
        raise ObjectsFileError(f"{where} field 'dims_cm': a {shape} takes {SHAPES[shape]} number(s) "
                               f"{DIMS_MEANING[shape]}, not {json.dumps(dims)}")
    dims = tuple(_number(d, where, "dims_cm") for d in dims)
    if min(dims) < config.min_dim_cm:
        raise ObjectsFileError(f"{where} field 'dims_cm': {min(dims)} cm is below the smallest size the robot "
                               f"can see and hold ({config.min_dim_cm} cm)")
    mass = _number(item["mass_g"], where, "mass_g")
    if mass > config.max_mass_g:
        raise ObjectsFileError(f"{where} field 'mass_g': {mass} g is more than the arm carries "
                               f"({config.max_mass_g} g)")
    spec = ObjectSpec(name, shape, dims, mass, _parse_color(item["color"], where))
    _check_fits(spec, jar, where, config)
    return spec


def _check_fits(spec: ObjectSpec, jar: JarSpec, where: str, config: ObjectsConfig):
    room = jar.inner_diameter_cm - config.ball_diameter_cm - 2.0 * config.fit_clearance_cm
    if spec.footprint_cm > room:
        hint = " (stand it on its smallest face: list its longest side last)" if spec.shape == "box" else ""
        raise ObjectsFileError(f"{where} field 'dims_cm': its footprint ({spec.footprint_cm:.2f} cm across) does "
                               f"not fit beside the {config.ball_diameter_cm} cm ball in the jar's "
                               f"{jar.inner_diameter_cm} cm (at most {room:.2f} cm across){hint}")
    if spec.height_cm > jar.height_cm:
        raise ObjectsFileError(f"{where} field 'dims_cm': {spec.height_cm} cm tall, taller than the "
                               f"{jar.height_cm} cm jar")
    v = archimedes_cm3(spec, jar)
    level = jar.water_depth_cm + v / jar.area_cm2
    if level > jar.height_cm:
        field = "dims_cm" if spec.sinks else "mass_g"
        raise ObjectsFileError(f"{where} field '{field}': it displaces {v:.0f} cm^3, which would raise the water "
                               f"from {jar.water_depth_cm} to {level:.1f} cm, over the jar's {jar.height_cm} cm rim")
