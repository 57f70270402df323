"""The Aesop battery's apparatus (issue 32): task files (CONTRACTS.md "Task file") and their closed-form outcome.

A task is tubes side by side, a floating reward in some, and objects to drop; a trial offers every (open tube,
object) pair. `outcome` is the yardstick (and the scoring bench's fast world): what one drop does to every level.
  - water: a floater displaces its mass (g as cm^3), a sinker its volume (only its part under water if it stands
    out: `sim.objects.archimedes_cm3`, reused), a hollow open-topped cup fills and displaces its walls only;
  - sand and sawdust are static beds: an object lands on the surface, which does not rise;
  - tubes joined by a hidden channel share their water: a drop into any of them raises all by V / (sum of areas).
The reward is in reach when its tube's surface is at least `height_cm - reach_cm` (the beak or hand reaches
`reach_cm` down into a tube). Units: cm, g (the objects file's).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from sim.objects import (MAX_NAME_CHARS, NAME_RE, WATER_DENSITY_G_CM3, ObjectsConfig, ObjectsFileError, ObjectSpec,
                         JarSpec, _no_unknown_keys, _number, _parse_object, _quoted, _show, archimedes_cm3, load_objects)

SUBSTRATES = ("water", "sand", "sawdust")
TOP_KEYS = {"apparatus", "objects", "train", "probe", "correct"}
APPARATUS_KEYS = {"tubes", "connections", "reach_cm"}
TUBE_KEYS = {"name", "substrate", "inner_diameter_cm", "height_cm", "level_cm", "reward", "open"}
HOLLOW_KEYS = {"hollow", "wall_cm"}


class TaskFileError(ObjectsFileError):
    """A bad task file: one line naming the tube or object and the field (as ObjectsFileError)."""


@dataclass(frozen=True)
class TaskConfig:
    # tubes the iCub's table holds side by side and its hand can drop into: a finger's width (a 1 cm object with
    # its clearances needs 1.5 cm) to the jar's widest (ObjectsConfig.max_jar_diameter_cm)
    min_tube_diameter_cm: float = 1.5
    max_tube_diameter_cm: float = 29.0
    # as the jar: the hand carries an object over the rim (ObjectsConfig.max_jar_height_cm)
    max_tube_height_cm: float = 44.0
    # a cup's wall thinner than this is a few pixels' edge and not a solid the physics can hold
    min_wall_cm: float = 0.1
    # default reach into a tube: a crow's beak (~3 cm past the rim) is what Jelbert et al. 2014 scored against
    reach_cm: float = 3.0
    max_tubes: int = 6       # the battery's tasks have 1 to 3; more would not fit on the table


@dataclass(frozen=True)
class Tube:
    name: str
    substrate: str            # "water" | "sand" | "sawdust"
    inner_diameter_cm: float
    height_cm: float
    level_cm: float           # the surface at the start (water, or the bed's top), above the inner bottom
    reward: bool = False      # holds a floating reward (on a bed: the reward rests on it)
    open: bool = True         # objects can be dropped into it (a U-tube's reward tube cannot)

    @property
    def area_cm2(self) -> float:
        return math.pi * self.inner_diameter_cm ** 2 / 4.0


@dataclass(frozen=True)
class TaskObject(ObjectSpec):
    """An object of the task; `wall_cm` set: a hollow open-topped cylinder (cup) with walls and floor that thick."""
    wall_cm: float | None = None

    @property
    def hollow(self) -> bool:
        return self.wall_cm is not None

    @property
    def walls_cm3(self) -> float:
        """The solid of a cup: its outer cylinder less the cavity (open at the top, floor `wall_cm` thick)."""
        d, h = self.dims_cm
        t = self.wall_cm or 0.0
        return math.pi / 4.0 * (d * d * h - (d - 2 * t) ** 2 * (h - t))

    @property
    def fill(self) -> float:
        """Volume / bounding box as the eye sees it. A cup's cavity is open to a camera above it (its depth shows
        the floor inside), so what is seen filled is the walls: walls_cm3 over the box; a solid's is its shape's."""
        if not self.hollow:
            return super().fill
        d, h = self.dims_cm
        return self.walls_cm3 / (d * d * h)


@dataclass(frozen=True)
class Task:
    name: str
    tubes: tuple[Tube, ...]
    objects: tuple[TaskObject, ...]
    connections: tuple[tuple[str, ...], ...] = ()
    reach_cm: float = TaskConfig.reach_cm
    train: tuple[ObjectSpec, ...] = ()
    probe: tuple[ObjectSpec, ...] = ()
    correct: tuple[tuple[str, str], ...] = field(default=())

    def tube(self, name: str) -> Tube:
        return next(t for t in self.tubes if t.name == name)

    def options(self) -> list[tuple[Tube, TaskObject]]:
        """The choices on one trial: every open tube with every object, one drop."""
        return [(t, o) for t in self.tubes if t.open for o in self.objects]

    def group(self, name: str) -> tuple[str, ...]:
        """The tubes sharing water with `name` (itself included)."""
        for g in self.connections:
            if name in g:
                return g
        return (name,)

    def start_levels(self) -> dict:
        return {t.name: t.level_cm for t in self.tubes}


def displaced_cm3(tube_substrate: str, obj: ObjectSpec, jar: JarSpec) -> float:
    """Water one object displaces at rest in a (possibly shared) column `jar`; 0 on a bed."""
    if tube_substrate != "water":
        return 0.0
    if getattr(obj, "wall_cm", None) is not None:
        return obj.walls_cm3      # a sunk cup is full: only its walls push water aside
    return archimedes_cm3(obj, jar)


def outcome(task: Task, levels: dict, tube: Tube, obj: ObjectSpec) -> dict:
    """One drop of `obj` into `tube` from `levels` ({tube name: cm}): {"levels", "rise_cm" (per tube),
    "reward_rise_cm" (the most any reward tube rose), "reached" (a reward tube's surface within reach), "sank" (the
    object came to rest on the bottom or on the bed, as the robot sees it: a floater in water did not; a hollow cup
    fills and sinks)}."""
    new = dict(levels)
    names = task.group(tube.name)
    group = [task.tube(n) for n in names]
    area = sum(t.area_cm2 for t in group)
    start = levels[tube.name]
    if tube.substrate == "water":
        # the shared column as one jar of the group's area, height the dropped-into tube's
        jar = JarSpec(2.0 * math.sqrt(area / math.pi), tube.height_cm, start)
        rise = displaced_cm3(tube.substrate, obj, jar) / area
        for n in names:
            new[n] = levels[n] + rise
    rises = {n: new[n] - levels[n] for n in levels}
    rewards = [t for t in task.tubes if t.reward]
    floats = (tube.substrate == "water" and getattr(obj, "wall_cm", None) is None
              and obj.mass_g < obj.volume_cm3 * WATER_DENSITY_G_CM3)
    return {"levels": new, "rise_cm": rises,
            "reward_rise_cm": max((rises[t.name] for t in rewards), default=0.0),
            "reached": any(new[t.name] >= t.height_cm - task.reach_cm for t in rewards), "sank": not floats}


def correct_options(task: Task) -> list[tuple[str, str]]:
    """The (tube, object) options whose one drop from the start levels brings a reward in reach."""
    lv = task.start_levels()
    return [(t.name, o.name) for t, o in task.options() if outcome(task, lv, t, o)["reached"]]


# -- parsing ---------------------------------------------------------------------------------------------------------
def load_task(path, config: TaskConfig = TaskConfig(), objects_config: ObjectsConfig = ObjectsConfig()) -> Task:
    """Read and validate a task file; TaskFileError (one line) if anything is wrong. The JSON is read as the
    objects file is (bounded size, nesting, integers: sim.objects.load_objects's reader)."""
    try:
        data = _read_json(path)
    except ObjectsFileError as e:
        raise TaskFileError(str(e).replace("objects file", "task file")) from None
    return parse_task(data, Path(str(path)).stem, config, objects_config)


def _read_json(path):
    """sim.objects.load_objects's bounded reader (size, nesting, integer length), stopped before its schema: its
    parse_objects is swapped for a catch while it runs, so there is one reader, not a copy (single-threaded use)."""
    import sim.objects as so
    captured = {}
    real = so.parse_objects

    def grab(data, config=None):
        captured["data"] = data
        raise _Got()
    so.parse_objects = grab
    try:
        load_objects(path)
    except _Got:
        return captured["data"]
    finally:
        so.parse_objects = real
    raise TaskFileError("the task file could not be read")   # not reached: load_objects always parses


class _Got(Exception):
    pass


def parse_task(data, name: str = "task", config: TaskConfig = TaskConfig(),
               objects_config: ObjectsConfig = ObjectsConfig()) -> Task:
    """Validate a task file's decoded JSON; TaskFileError (one line) if anything is wrong, whichever of
    sim.objects' checks (reused for objects and fields) found it."""
    try:
        return _parse_task(data, name, config, objects_config)
    except TaskFileError:
        raise
    except ObjectsFileError as e:
        raise TaskFileError(str(e)) from None


def _parse_task(data, name: str, config: TaskConfig, objects_config: ObjectsConfig) -> Task:
    if not isinstance(data, dict):
        raise TaskFileError("the task file must be a JSON object with 'apparatus' and 'objects'")
    _no_unknown_keys(data, TOP_KEYS, "the task file")
    for k in ("apparatus", "objects", "train"):
        if k not in data:
            raise TaskFileError(f"the task file has no '{k}'")
    ap = data["apparatus"]
    if not isinstance(ap, dict):
        raise TaskFileError(f"apparatus: must be an object with 'tubes', not {_show(ap)}")
    _no_unknown_keys(ap, APPARATUS_KEYS, "apparatus")
    tubes = _parse_tubes(ap.get("tubes"), config)
    reach = _number(ap["reach_cm"], "apparatus", "reach_cm") if "reach_cm" in ap else config.reach_cm
    connections = _parse_connections(ap.get("connections", []), tubes)
    open_tubes = [t for t in tubes if t.open]
    if not open_tubes:
        raise TaskFileError("apparatus field 'tubes': no tube is open (an object must be droppable somewhere)")
    if not any(t.reward for t in tubes):
        raise TaskFileError("apparatus field 'tubes': no tube holds the reward")
    tallest = max(t.height_cm for t in tubes)
    # objects are checked as the objects file checks them, in the widest jar the table holds (the tubes' own fit
    # is checked below, against the narrowest open tube)
    jar = JarSpec(objects_config.max_jar_diameter_cm, min(tallest, objects_config.max_jar_height_cm),
                  objects_config.min_water_depth_cm)
    groups = {}
    for group in ("objects", "train", "probe"):
        items = data.get(group, [])
        if not isinstance(items, list) or (group != "probe" and not items):
            raise TaskFileError(f"'{group}' must be a non-empty list of objects, not {_show(items)}")
        groups[group] = tuple(_parse_task_object(it, f"{group}[{i}]", jar, open_tubes, objects_config, config,
                                                 hollow_ok=group == "objects") for i, it in enumerate(items))
    seen = set()
    for o in groups["objects"] + groups["train"] + groups["probe"]:
        if o.name in seen:
            raise TaskFileError(f"object '{o.name}' field 'name': duplicate name")
        seen.add(o.name)
    task = Task(name, tubes, groups["objects"], connections, reach, groups["train"], groups["probe"])
    derived = correct_options(task)
    if not derived:
        raise TaskFileError("the task file: no option brings the reward in reach (check levels and objects)")
    if "correct" in data:
        given = data["correct"]
        ok = isinstance(given, list) and all(isinstance(c, list) and len(c) == 2 and all(isinstance(x, str)
                                                                                       for x in c) for c in given)
        if not ok:
            raise TaskFileError(f"the task file field 'correct': must be a list of [tube, object], not "
                                f"{_show(given)}")
        if sorted(map(tuple, given)) != sorted(derived):
            raise TaskFileError(f"the task file field 'correct': {_show(given)} but the physics says "
                                f"{_show([list(c) for c in derived])}")
    return Task(name, tubes, groups["objects"], connections, reach, groups["train"], groups["probe"],
                tuple(derived))


def _parse_tubes(items, config: TaskConfig) -> tuple[Tube, ...]:
    if not isinstance(items, list) or not 1 <= len(items) <= config.max_tubes:
        raise TaskFileError(f"apparatus field 'tubes': must be a list of 1 to {config.max_tubes} tubes, not "
                            f"{_show(items)}")
    tubes, names = [], set()
    for i, t in enumerate(items):
        where = f"tube {i}"
        if not isinstance(t, dict):
            raise TaskFileError(f"{where}: must be an object with {', '.join(sorted(TUBE_KEYS))}")
        name = t.get("name")
        if not isinstance(name, str) or len(name) > MAX_NAME_CHARS or not NAME_RE.fullmatch(name):
            raise TaskFileError(f"{where} field 'name': must be 1 to {MAX_NAME_CHARS} letters, digits, '_', '.', "
                                f"'-', not {_show(name)}")
        where = f"tube '{name}'"
        if name in names:
            raise TaskFileError(f"{where} field 'name': duplicate name")
        names.add(name)
        _no_unknown_keys(t, TUBE_KEYS, where)
        for k in ("substrate", "inner_diameter_cm", "height_cm", "level_cm"):
            if k not in t:
                raise TaskFileError(f"{where} field '{k}': missing")
        if t["substrate"] not in SUBSTRATES:
            raise TaskFileError(f"{where} field 'substrate': {_show(t['substrate'])} (known: "
                                f"{', '.join(SUBSTRATES)})")
        d = _number(t["inner_diameter_cm"], where, "inner_diameter_cm")
        h = _number(t["height_cm"], where, "height_cm")
        lv = _number(t["level_cm"], where, "level_cm")
        if not config.min_tube_diameter_cm <= d <= config.max_tube_diameter_cm:
            raise TaskFileError(f"{where} field 'inner_diameter_cm': {d:g} cm (from {config.min_tube_diameter_cm:g} "
                                f"to {config.max_tube_diameter_cm:g} cm)")
        if h > config.max_tube_height_cm:
            raise TaskFileError(f"{where} field 'height_cm': {h:g} cm is taller than the robot can drop into (at "
                                f"most {config.max_tube_height_cm:g} cm)")
        if lv >= h:
            raise TaskFileError(f"{where} field 'level_cm': {lv:g} cm does not fit in a tube {h:g} cm high")
        flags = {}
        for k, default in (("reward", False), ("open", True)):
            v = t.get(k, default)
            if not isinstance(v, bool):
                raise TaskFileError(f"{where} field '{k}': must be true or false, not {_show(v)}")
            flags[k] = v
        tubes.append(Tube(name, t["substrate"], d, h, lv, **flags))
    return tuple(tubes)


def _parse_connections(items, tubes) -> tuple[tuple[str, ...], ...]:
    """Hidden channels: lists of tube names sharing water. They must be water tubes at one level (at rest, joined
    water stands level) and each tube in one group at most."""
    names = {t.name: t for t in tubes}
    if not isinstance(items, list):
        raise TaskFileError(f"apparatus field 'connections': must be a list of lists of tube names, not "
                            f"{_show(items)}")
    out, used = [], set()
    for g in items:
        if not isinstance(g, list) or len(g) < 2 or not all(isinstance(n, str) for n in g):
            raise TaskFileError(f"apparatus field 'connections': each must list 2 or more tube names, not {_show(g)}")
        for n in g:
            if n not in names:
                raise TaskFileError(f"apparatus field 'connections': no tube named {_quoted(n)}")
            if n in used:
                raise TaskFileError(f"apparatus field 'connections': tube {_quoted(n)} is in two channels")
            if names[n].substrate != "water":
                raise TaskFileError(f"apparatus field 'connections': tube {_quoted(n)} holds "
                                    f"{names[n].substrate}, not water")
            used.add(n)
        if len({names[n].level_cm for n in g}) > 1:
            raise TaskFileError(f"apparatus field 'connections': tubes {_show(g)} are joined but their levels "
                                f"differ (joined water stands level)")
        out.append(tuple(g))
    return tuple(out)


def _parse_task_object(item, where: str, jar: JarSpec, open_tubes, objects_config: ObjectsConfig,
                       config: TaskConfig, hollow_ok: bool) -> TaskObject:
    wall = None
    if isinstance(item, dict) and (set(item) & HOLLOW_KEYS):
        name = item.get("name", where)
        owhere = f"object '{name}'" if isinstance(name, str) else where
        if not hollow_ok:
            raise TaskFileError(f"{owhere} field 'hollow': only trial objects ('objects') may be hollow")
        if item.get("hollow") is not True:
            raise TaskFileError(f"{owhere} field 'hollow': must be true with 'wall_cm', not "
                                f"{_show(item.get('hollow'))}")
        if item.get("shape") != "cylinder":
            raise TaskFileError(f"{owhere} field 'shape': a hollow object is an open-topped cylinder (a cup)")
        wall = _number(item.get("wall_cm"), owhere, "wall_cm") if "wall_cm" in item else None
        if wall is None:
            raise TaskFileError(f"{owhere} field 'wall_cm': missing (a hollow cup's wall thickness)")
        item = {k: v for k, v in item.items() if k not in HOLLOW_KEYS}
    spec = _parse_object(item, where, jar, objects_config)
    where = f"object '{spec.name}'"
    obj = TaskObject(spec.name, spec.shape, spec.dims_cm, spec.mass_g, spec.rgb, wall)
    if wall is not None:
        d, h = spec.dims_cm
        if not config.min_wall_cm <= wall < min(d / 2, h):
            raise TaskFileError(f"{where} field 'wall_cm': {wall:g} cm (from {config.min_wall_cm:g} cm to less than "
                                f"half the diameter and the height)")
        if spec.mass_g <= obj.walls_cm3:
            raise TaskFileError(f"{where} field 'mass_g': {spec.mass_g:g} g; its walls ({obj.walls_cm3:.2f} cm^3) "
                                f"must be denser than water so the filled cup sinks")
    for t in open_tubes:
        room = t.inner_diameter_cm - 2.0 * objects_config.fit_clearance_cm
        if spec.footprint_cm > room:
            raise TaskFileError(f"{where} field 'dims_cm': its footprint ({spec.footprint_cm:.2f} cm) does not fit "
                                f"tube '{t.name}' (at most {room:.2f} cm across)")
    return obj
