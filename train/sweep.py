"""Sweeps: conditions x object sets x orders x seeds, run as Ray tasks, the rows of every episode in Parquet.

    python train/sweep.py SWEEP.toml [--out DIR] [--resume] [--address ADDR] [--workers N]

The sweep file (docs/sweeps.md) names conditions (a model, its ablations, overrides of its config) and object sets
(objects files, or sets drawn by `sim.make_objects.generate`), each learned in N random orders from each seed. A
cell is one condition on one object set with one seed: all its orders learn side by side as one batched agent (as
benches/ablation.py runs them), and each cell is one Ray task on one core. Each finished cell's rows are written at
once to DIR/cells/<cell>.parquet (a temporary file renamed into place), <cell> a stable hash of everything the cell
computes from; DIR/sweep.json records the resolved sweep. So a Ctrl-C (one line, exit code 130) or a lost machine
leaves every finished cell on disk, and `--resume` runs only the cells not there, refusing in one line a DIR whose
sweep.json records another sweep. A bad sweep file, flag or DIR is refused in one line on stderr, exit code 2,
before Ray starts and before anything is written. A cell that fails is reported in one line; the others go on, and
the sweep ends with exit code 1 (--resume runs the failed cells again).

Without --address a local Ray instance is started on this machine with --workers CPUs (default: its cores) and shut
down at the end; with --address (e.g. `auto` or `HOST:6379`) the sweep joins that cluster, whose nodes need this
repository at the same path and the same Python environment. `python -m train.report DIR` summarises the rows.

The cells are named by their spec, not by the code: after changing the agent or the object generator, sweep into
a new DIR.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import math
import os
import signal
import socket
import stat
import sys
import tempfile
import threading
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the project importable without installing it
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

ROOT = Path(__file__).resolve().parents[1]
PROG = "train/sweep.py"
FORMAT = 3               # in every cell's hash: bumped when the rows a spec gives change (2: batch_knowledge,
                         # stored, recalled, probe_errors, probe_floors; 3: config)
BATCH_MAX_TRAIN = 500    # the batch answer compares every pair of a set's train objects: up to this many
WORLDS = ("closed_form", "closed_form_exact", "physics")
from train.run_config import ABLATIONS, MODELS, check_capacity  # noqa: E402   the runner's tables, torch-free
MAX_CELLS = 1_000_000
MAX_SEEDS = 1_000_000    # seeds of one range
MAX_ORDERS = 100_000     # orders of one cell (one batched agent)
MAX_SEED = 2 ** 63       # torch.Generator.manual_seed takes a 64-bit integer
MAX_SWEEP_BYTES = 1_000_000     # a sweep file: the shipped ones are under 2 kB and a sweep of a million cells
                                # needs a few lines; a file far larger is no sweep file (/dev/zero: read no further)
MAX_RECORD_BYTES = 1 << 30      # DIR/sweep.json and DIR/configs.json as this program writes them (the largest
                                # legal sweep, 1,000,000 cells, records well under this; see docs/sweeps.md)
MAX_NESTING = 16                # tables and lists in tables: the shipped sweep files nest 5 deep
KNOWLEDGE_LETTERS = "ULDI"   # train.summary.KNOWLEDGE_LETTERS: one per aesop_torch.rules.STATES code
RULE_LETTERS = "SEGU"        # aesop_torch.rules.RULE_NAMES
# aesop_torch.encoders.OBJECT_PROPERTIES: a model has the paper's four or the split five (null in the others)
PROPERTY_COLUMNS = ("color", "shape", "fill", "elongation", "size", "weight")

TOP_KEYS = ("description", "world", "conditions", "sets")
CONDITION_KEYS = ("name", "model", "ablate", "overrides")
SET_KEYS = ("name", "files", "generate", "orders", "seeds", "checks")
GENERATE_KEYS = ("seeds", "train", "probe", "pairs", "jar")


class SweepError(Exception):
    """A bad sweep file, flag or DIR: one line on stderr, exit code 2."""


# -- the sweep file ----------------------------------------------------------------------------------------------

def _show(v) -> str:
    text = json.dumps(v, default=str)
    return text if len(text) <= 60 else text[:57] + "..."


def _keys(d, allowed, where: str) -> dict:
    if not isinstance(d, dict):
        raise SweepError(f"{where}: expected a table, got {_show(d)}")
    if bad := [k for k in d if k not in allowed]:
        raise SweepError(f"{where}: unknown key {bad[0]!r} (known: {', '.join(allowed)})")
    return d


def _int(v, where: str, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise SweepError(f"{where}: expected a whole number, got {_show(v)}")
    if not lo <= v <= hi:
        raise SweepError(f"{where}: must be in {lo}..{hi}, got {v}")
    return v


def _entry_name(entry: dict, where: str, names: set, kind: str) -> tuple[str, str]:
    """A [[conditions]] or [[sets]] entry's name, present and unique among `names` (added to them), and the place
    to name in its errors from now on."""
    if "name" not in entry:
        raise SweepError(f"{where}: no 'name'")
    name = _name(entry["name"], where + ".name")
    if name in names:
        raise SweepError(f"{where}.name: {name!r} is the name of another {kind}")
    names.add(name)
    return name, f"{where} {name!r}"


def _name(v, where: str) -> str:
    if not isinstance(v, str) or not v.strip():
        raise SweepError(f"{where}: expected a non-empty string, got {_show(v)}")
    if not v.isprintable() or len(v) > 100:
        raise SweepError(f"{where}: at most 100 printable characters, got {_show(v)}")
    return v


def _list(v, where: str) -> list:
    if not isinstance(v, list):
        raise SweepError(f"{where}: expected a list, got {_show(v)}")
    if not v:
        raise SweepError(f"{where}: the list is empty")
    return v


def _seeds(v, where: str) -> list[int]:
    """[a, b]: the half-open range a..b-1; {list = [s, ...]}: exactly these."""
    if isinstance(v, dict):
        _keys(v, ("list",), where)
        if "list" not in v:
            raise SweepError(f"{where}: a table of seeds needs 'list'")
        seeds = [_int(s, f"{where}.list[{i}]", 0, MAX_SEED - 1) for i, s in enumerate(_list(v["list"], where + ".list"))]
        if len(set(seeds)) != len(seeds):
            raise SweepError(f"{where}.list: seed {next(s for s in seeds if seeds.count(s) > 1)} is listed twice")
        return seeds
    if not isinstance(v, list) or len(v) != 2:
        raise SweepError(f"{where}: expected a range [first, end) of two whole numbers or {{list = [...]}}, "
                         f"got {_show(v)}")
    a, b = (_int(x, f"{where}[{i}]", 0, MAX_SEED) for i, x in enumerate(v))
    if b <= a:
        raise SweepError(f"{where}: the range [{a}, {b}) is empty")
    if b - a > MAX_SEEDS:
        raise SweepError(f"{where}: the range [{a}, {b}) holds more than {MAX_SEEDS:,} seeds")
    return list(range(a, b))


def _orders(v, where: str, n_train: int) -> str:
    """As train.experiment.draw_orders takes it: 'N', 'listed' or 'all'."""
    if v in ("listed", "all"):
        if v == "all" and math.factorial(n_train) > 40_320:
            raise SweepError(f"{where}: 'all' orders of {n_train} objects are {math.factorial(n_train):,} "
                             f"(at most 8 objects); give a number of random orders")
        return v
    if isinstance(v, str):
        raise SweepError(f"{where}: expected a number of random orders, 'listed' or 'all', got {_show(v)}")
    return str(_int(v, where, 1, MAX_ORDERS))


def _n_orders(orders: str, n_train: int) -> int:
    return 1 if orders == "listed" else math.factorial(n_train) if orders == "all" else int(orders)


def _checks(v, where: str, n_train: int) -> list[int]:
    if v is None:
        return list(range(1, n_train + 1))
    return sorted({_int(c, f"{where}[{i}]", 1, n_train) for i, c in enumerate(_list(v, where))})


def _flat_overrides(d, where: str, prefix: str = "") -> dict:
    """{"rules.uncertain_decay": 1.0} or {rules = {uncertain_decay = 1.0}} -> the dotted form."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flat_overrides(v, where, key + "."))
        elif isinstance(v, (bool, int, float, str)) or (isinstance(v, list) and all(
                isinstance(x, (bool, int, float, str)) or (isinstance(x, list) and all(
                    isinstance(y, (bool, int, float, str)) for y in x)) for x in v)):
            if isinstance(v, float) and not math.isfinite(v):
                raise SweepError(f"{where}: {key!r} = {v} is not a finite number")
            out[key] = v
        else:
            raise SweepError(f"{where}: {key!r}: expected a number, string, boolean or list, got {_show(v)}")
    return out


def agent_config(condition: dict, seed: int, n_train: int):
    """The cell's AgentConfig: the named model with its ablations, the buffers sized to the set (as
    benches/ablation.py sizes them), then the condition's overrides (which may size them otherwise)."""
    from aesop_torch.agent import AgentConfig
    cfg = AgentConfig.named(condition["model"], ablate=tuple(condition["ablate"]), seed=seed)
    cfg.memory.max_episodes = cfg.hub.max_assemblies = n_train
    if condition["overrides"]:
        from train.config import apply_overrides
        cfg = apply_overrides(cfg, condition["overrides"])
    return cfg


def _condition(c, where: str, names: set) -> dict:
    _keys(c, CONDITION_KEYS, where)
    name, where = _entry_name(c, where, names, "condition")
    if "model" not in c:
        raise SweepError(f"{where}: no 'model' (one of: {', '.join(MODELS)})")
    model = c["model"]
    if model not in MODELS:
        raise SweepError(f"{where}: model: {_show(model)} is not a model (known: {', '.join(MODELS)})")
    ablate = c.get("ablate", [])
    if not isinstance(ablate, list):
        raise SweepError(f"{where}: ablate: expected a list (e.g. [\"rules\"]), got {_show(ablate)}")
    for a in ablate:
        if a not in ABLATIONS[model]:
            raise SweepError(f"{where}: ablate: {_show(a)} is no ablation of the {model} model (it has: "
                             f"{', '.join(ABLATIONS[model])})")
    if len(set(ablate)) != len(ablate):
        raise SweepError(f"{where}: ablate: {next(a for a in ablate if ablate.count(a) > 1)!r} is listed twice")
    overrides = c.get("overrides", {})
    if not isinstance(overrides, dict):
        raise SweepError(f"{where}: overrides: expected a table of dotted keys, got {_show(overrides)}")
    cond = {"name": name, "model": model, "ablate": [a for a in ABLATIONS[model] if a in ablate],
            "overrides": dict(sorted(_flat_overrides(overrides, where + " overrides").items()))}
    for key, why in (("model", "the condition's model"), ("ablate", "the condition's ablate"),
                     ("seed", "a set's seeds")):
        if key in cond["overrides"]:
            raise SweepError(f"{where}: overrides: {key!r} is set by {why}, not by an override")
    if cond["overrides"]:
        try:
            from train.config import ConfigError
        except ImportError:
            raise SweepError(f"{where}: overrides need train/config.py, which this checkout lacks") from None
        try:
            agent_config(cond, 0, 8)
        except (ConfigError, ValueError, TypeError) as e:
            why = (str(e).strip().splitlines() or [type(e).__name__])[0]
            raise SweepError(f"{where}: overrides: {why}") from None
    return cond


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _set(s, where: str, base: Path, names: set) -> tuple[dict, list[dict]]:
    """A [[sets]] entry -> (its resolved spec, its object sets: each {label, generator_seed, source, data,
    n_train, n_probe, seeds, checks, orders})."""
    from sim.make_objects import generate
    from sim.objects import ObjectsConfig, ObjectsFileError, load_objects
    _keys(s, SET_KEYS, where)
    name, where = _entry_name(s, where, names, "set")
    if ("files" in s) == ("generate" in s):
        raise SweepError(f"{where}: give either 'files' (objects files) or 'generate' (a generator spec)")
    run_seeds = _seeds(s["seeds"], where + ".seeds") if "seeds" in s else None
    found = []
    if "files" in s:
        files = _list(s["files"], where + ".files")
        for i, f in enumerate(files):
            f = _name(f, f"{where}.files[{i}]")
            if files.index(f) != i:
                raise SweepError(f"{where}.files: {f!r} is listed twice")
            path = base / f
            try:
                objs = load_objects(path)
            except ObjectsFileError as e:
                raise SweepError(f"{where}: {f}: {e}") from None
            data = objs.canonical()
            found.append({"label": f, "generator_seed": None, "source": {"file": f, "sha256": _digest(data)},
                          "data": data, "n_train": len(objs.train), "n_probe": len(objs.probe),
                          "seeds": run_seeds or [0]})
    else:
        g = _keys(s["generate"], GENERATE_KEYS, where + ".generate")
        if "seeds" not in g:
            raise SweepError(f"{where}.generate: no 'seeds' (e.g. seeds = [0, 10])")
        config = ObjectsConfig()
        gen = {"train": _int(g.get("train", 8), where + ".generate.train", 4, config.max_objects),
               "probe": _int(g.get("probe", 8), where + ".generate.probe", 0, 1000),
               "pairs": g.get("pairs", True), "jar": g.get("jar", "random")}
        if not isinstance(gen["pairs"], bool):
            raise SweepError(f"{where}.generate.pairs: expected true or false, got {_show(gen['pairs'])}")
        if gen["jar"] not in ("random", "default"):
            raise SweepError(f"{where}.generate.jar: expected \"random\" or \"default\", got {_show(gen['jar'])}")
        seeds = _seeds(g["seeds"], where + ".generate.seeds")
        try:
            generate(seeds[0], gen["train"], gen["probe"], gen["pairs"], gen["jar"])   # the counts' refusals
        except (ValueError, ObjectsFileError) as e:
            raise SweepError(f"{where}.generate: {e}") from None
        for sd in seeds:
            found.append({"label": str(sd), "generator_seed": sd, "source": {"generate": {"seed": sd, **gen}},
                          "data": None, "n_train": gen["train"], "n_probe": gen["probe"],
                          "seeds": run_seeds or [sd]})
    for f in found:
        f["orders"] = _orders(s.get("orders", 1), where + ".orders", f["n_train"])
        f["checks"] = _checks(s.get("checks"), where + ".checks", f["n_train"])
    spec = {"name": name, "orders": found[0]["orders"], "checks": s.get("checks"),
            "objects": [{k: f[k] for k in ("label", "source", "n_train", "n_probe", "seeds")} for f in found]}
    return spec, found


def read_bounded(path, limit: int, what: str) -> bytes:
    """A file's bytes, if it is a regular file of at most `limit` bytes; SweepError (one line) otherwise. Opened
    without blocking (a FIFO must not wait for a writer) and read no further than the limit (/dev/zero never ends)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise SweepError(f"{path}: cannot read it: {e.strerror or e}") from None
    try:
        with os.fdopen(fd, "rb") as f:
            mode = os.fstat(f.fileno()).st_mode
            if not stat.S_ISREG(mode):
                kind = ("a directory" if stat.S_ISDIR(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else
                        "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode)
                        else "no regular file")
                raise SweepError(f"{path}: is {kind}, not {what} (a regular file)")
            raw = f.read(limit + 1)
    except OSError as e:
        raise SweepError(f"{path}: cannot read it: {e.strerror or e}") from None
    if len(raw) > limit:
        raise SweepError(f"{path}: larger than {limit:,} bytes, too large for {what}")
    return raw


def _depth(doc) -> int:
    """How deep tables and lists nest in a parsed document (a list of scalars inside the top table: 2), counted up
    to MAX_NESTING + 1. Without recursion: dotted keys a.b.c... parse flat, however deep they nest."""
    deepest, stack = 0, [(doc, 1)]
    while stack:
        v, d = stack.pop()
        deepest = max(deepest, d)
        if d > MAX_NESTING:
            break
        children = v.values() if isinstance(v, dict) else v
        stack.extend((c, d + 1) for c in children if isinstance(c, (dict, list)))
    return deepest


def _toml_error(message: str, text: str) -> str:
    """tomllib's message, first line, with the key named when it says only 'Cannot overwrite a value' (a key given
    twice): the key of the last `key = value` line at or before the place it points to."""
    import re
    first = message.splitlines()[0]
    if not first.startswith("Cannot overwrite a value"):
        return first
    lines = text.splitlines()
    part = r"""(?:[A-Za-z0-9_-]+|"[^"]*"|'[^']*')"""   # a bare, "basic" or 'literal' key
    at = re.search(r"at line (\d+)", first)
    end = int(at.group(1)) if at else len(lines)
    for i in range(min(end, len(lines)) - 1, -1, -1):
        m = re.match(rf"\s*({part}(?:\s*\.\s*{part})*)\s*=", lines[i])
        if m:
            return f"the key {m.group(1)} is given twice (line {i + 1}; a key may be set once per table)"
    return first


def load_sweep(path: Path) -> tuple[dict, list[dict]]:
    """Read and check a sweep file: (the resolved spec, the cells in the order they are to run). Each cell is
    {"id", "spec" (what its id hashes), "objects" (an objects file's data, or None for a generated set)}. SweepError
    (one line) for anything wrong."""
    try:
        import tomllib
    except ModuleNotFoundError:   # Python 3.10
        import tomli as tomllib
    raw = read_bounded(path, MAX_SWEEP_BYTES, "a sweep file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise SweepError(f"{path}: not UTF-8 text") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SweepError(f"{path}: malformed TOML: {_toml_error(str(e), text)}") from None
    except RecursionError:
        raise SweepError(f"{path}: nests tables or lists more than {MAX_NESTING} levels deep") from None
    if _depth(doc) > MAX_NESTING:
        raise SweepError(f"{path}: nests tables or lists more than {MAX_NESTING} levels deep")
    try:
        return _resolve(doc, Path(path).resolve().parent)
    except SweepError as e:
        raise SweepError(f"{path}: {e}") from None


def resolve(doc: dict, base: Path) -> tuple[dict, list[dict]]:
    """load_sweep for a sweep file already read into a dict (a bench that builds its cells from its flags); objects
    files relative to base. SweepError (one line) for anything wrong."""
    return _resolve(doc, Path(base))


def _resolve(doc: dict, base: Path) -> tuple[dict, list[dict]]:
    _keys(doc, TOP_KEYS, "the sweep file")
    if "description" in doc and not isinstance(doc["description"], str):
        raise SweepError(f"description: expected a string, got {_show(doc['description'])}")
    world = doc.get("world", "closed_form")
    if world not in WORLDS:
        raise SweepError(f"world: {_show(world)} is not a world (known: {', '.join(WORLDS)})")
    for key in ("conditions", "sets"):
        if key not in doc:
            raise SweepError(f"no [[{key}]]")
        _list(doc[key], key)
    names: set = set()
    conditions = [_condition(c, f"conditions[{i}]", names) for i, c in enumerate(doc["conditions"])]
    names = set()
    sets = [_set(s, f"sets[{i}]", base, names) for i, s in enumerate(doc["sets"])]
    n = len(conditions) * sum(len(f["seeds"]) for _, found in sets for f in found)
    if n > MAX_CELLS:
        raise SweepError(f"{n:,} cells, more than {MAX_CELLS:,}")
    for i, cond in enumerate(conditions):   # the buffers fit the set unless an override sized them otherwise
        for n_train in sorted({f["n_train"] for _, found in sets for f in found}) if cond["overrides"] else ():
            why = check_capacity(agent_config(cond, 0, n_train), n_train,
                                 setting=lambda key, value: f"overrides {{ {json.dumps(key)} = {json.dumps(value)} }}")
            if why:
                raise SweepError(f"conditions[{i}] {cond['name']!r}: {why}")
    spec = {"format": FORMAT, "world": world, "conditions": conditions, "sets": [s for s, _ in sets]}
    cells = []
    for cond in conditions:
        for (s, found) in sets:
            for f in found:
                for seed in f["seeds"]:
                    cs = {"format": FORMAT, "world": world, "condition": cond, "set_group": s["name"],
                          "set": f["label"], "source": f["source"], "n_train": f["n_train"], "n_probe": f["n_probe"],
                          "seed": seed, "orders": f["orders"], "checks": f["checks"]}
                    cells.append({"id": _digest(cs)[:16], "spec": cs, "objects": f["data"]})
    if len({c["id"] for c in cells}) != len(cells):
        raise SweepError("two cells are the same (a condition or an object set listed twice under other names?)")
    # the longest first: a long cell started last would keep one worker busy while the rest idle
    cells.sort(key=lambda c: -c["spec"]["n_train"] * max(8, _n_orders(c["spec"]["orders"], c["spec"]["n_train"])))
    return spec, cells


# -- one cell -----------------------------------------------------------------------------------------------------

def objects_of(cell: dict, objects: dict | None):
    """The cell's ObjectSet: an objects file's data as sent, or the generated set drawn again."""
    from sim.objects import parse_objects
    if objects is None:
        from sim.make_objects import generate
        g = cell["source"]["generate"]
        objects = generate(g["seed"], g["train"], g["probe"], g["pairs"], g["jar"])
    return parse_objects(objects)


def world_outcomes(cell: dict, objects: dict | None) -> tuple[dict, dict]:
    """(outcomes, probes) as train.experiment.closed_form_outcomes gives them, in the cell's world: the closed form
    with the simulated robot's noise (closed_form), without noise (closed_form_exact), or the pybullet world, each
    distinct train object dropped once and each probe inspected once (physics: the jar is reset between episodes,
    so an object's outcome does not depend on the order it comes in; train/run.py's cached physics)."""
    from train.experiment import closed_form_outcomes, outcome_record, plain_measurement
    objs, seed = objects_of(cell, objects), cell["seed"]
    if cell["world"] != "physics":
        from sim.sensor_model import SensorModel
        return closed_form_outcomes(objs, reachable_above_cm3=_REACH_CM3,
                                    sensor=SensorModel() if cell["world"] == "closed_form" else None, seed=seed)
    from sim.objects import archimedes_cm3
    from train.physics import Physics
    physics = Physics(objs, seed=seed, workers=1)   # in this process: a cell is one core's work
    try:
        jobs = [("drop", o.name, False) for o in objs.train] + [("inspect", o.name, None) for o in objs.probe]
        results = physics.run(jobs)
    finally:
        physics.close()
    outcomes = {o.name: outcome_record(r) for o, r in zip(objs.train, results)}
    probes = {o.name: {"measurement": plain_measurement(m), "archimedes_cm3": float(archimedes_cm3(o, objs.jar))}
              for o, m in zip(objs.probe, results[len(objs.train):])}
    return outcomes, probes


_REACH_CM3 = 200.0   # the closed forms' reach: the ball counts as reached after more than this (closed_form_outcomes)


def config_record(cell: dict) -> dict:
    """The configs a cell runs with, fully resolved, as JSON data: {"agent": its AgentConfig without the seed (the
    rows' seed column), "world": {"name", "sensor": the SensorModel's noise (closed_form) or null, "reachable_above_cm3"
    (the closed forms), "physics": the pybullet WorldConfig (physics)}}. The same for every cell of a condition, set
    size and world: DIR/configs.json holds each once, keyed by config_hash."""
    key = json.dumps([cell["condition"], cell["n_train"], cell["world"]], sort_keys=True)
    if key not in _CONFIGS:
        from dataclasses import asdict
        agent = agent_config(cell["condition"], 0, cell["n_train"]).to_dict()
        agent.pop("seed", None)
        world: dict = {"name": cell["world"]}
        if cell["world"] == "physics":
            from sim.world import WorldConfig
            world["physics"] = asdict(WorldConfig())
        else:
            from sim.sensor_model import SensorModel
            world["sensor"] = asdict(SensorModel()) if cell["world"] == "closed_form" else None
            world["reachable_above_cm3"] = _REACH_CM3
        _CONFIGS[key] = json.loads(json.dumps({"agent": agent, "world": world}, default=str))
    return _CONFIGS[key]


_CONFIGS: dict = {}


def config_hash(record: dict) -> str:
    """The rows' config column: the first 16 hex digits of the SHA-256 of config_record's canonical JSON."""
    return _digest(record)[:16]


def world_key(cell: dict) -> str:
    """Cells with the same key see the same world (conditions differ): a physics world is simulated once per key."""
    return _digest([cell["world"], cell["source"], cell["seed"]])


def schema():
    """The Parquet rows' schema (docs/sweeps.md)."""
    import pyarrow as pa
    return pa.schema([
        ("cell", pa.string()), ("condition", pa.string()), ("model", pa.string()), ("ablate", pa.string()),
        ("overrides", pa.string()), ("config", pa.string()), ("world", pa.string()), ("set_group", pa.string()),
        ("set", pa.string()),
        ("generator_seed", pa.int64()), ("seed", pa.int64()), ("n_train", pa.int32()), ("n_probe", pa.int32()),
        ("n_orders", pa.int32()), ("order", pa.int32()), ("episode", pa.int32()), ("object", pa.string()),
        ("predicted_cm3", pa.float64()), ("observed_cm3", pa.float64()), ("archimedes_cm3", pa.float64()),
        ("sank", pa.bool_()), ("goal_reached", pa.bool_()), ("rules", pa.string()), ("knowledge", pa.string()),
        *[(p, pa.string()) for p in PROPERTY_COLUMNS], ("context_knowledge", pa.string()),
        ("probe_rel_error", pa.float64()),
        ("batch_knowledge", pa.string()), ("stored", pa.int32()), ("recalled", pa.float64()),
        ("probe_errors", pa.list_(pa.float64())), ("probe_floors", pa.list_(pa.float64()))])


def _median_rows(err):
    """(B, Q) errors -> (B,) median over the row (the mean of the middle two for an even count)."""
    s = err.sort(dim=1).values
    q = s.shape[1]
    return s[:, q // 2] if q % 2 else s[:, q // 2 - 1:q // 2 + 1].mean(1)


def run_cell(cell: dict, objects: dict | None = None, world: tuple | None = None):
    """One cell: its condition on its object set with its seed, all its orders as one batched agent, as
    benches/ablation.py runs them. cell: a cell's spec (load_sweep's cells[i]["spec"]); objects: the objects file's
    data (None: a generated set, drawn here); world: (outcomes, probes) when already simulated. Returns the cell's
    rows (a pyarrow Table of `schema()`, order by order, episode by episode). A deterministic function of its
    arguments, on one torch thread."""
    import numpy as np
    import pyarrow as pa
    import torch

    from aesop_torch.agent import Agent
    from train.experiment import draw_orders, one_thread, stack_measurements

    with one_thread(), torch.no_grad():
        objs = objects_of(cell, objects)
        outcomes, probes = world if world is not None else world_outcomes(cell, objects)
        names, pnames = [o.name for o in objs.train], [o.name for o in objs.probe]
        n = len(names)
        meas = stack_measurements([outcomes[k]["measurement"] for k in names])
        observed = torch.tensor([outcomes[k]["observed_cm3"] for k in names], dtype=torch.float64)
        ep = {k: torch.tensor([outcomes[x][k] for x in names]) for k in ("goal_before", "goal_after", "sank")}
        pmeas = stack_measurements([probes[k]["measurement"] for k in pnames]) if pnames else None
        truth = torch.tensor([probes[k]["archimedes_cm3"] for k in pnames])
        orders = torch.tensor(draw_orders(n, cell["orders"], cell["seed"]))
        B, Q = orders.shape[0], len(pnames)
        agent = Agent(agent_config(cell["condition"], cell["seed"], n), batch=B)
        checks = set(cell["checks"])
        predicted, fired, state, stored, by_context = [], [], [], [], []
        probe_err = torch.full((n, B), float("nan"), dtype=torch.float64)
        recalled = torch.full((n, B), float("nan"), dtype=torch.float64)
        per_probe = {}   # episode index -> (B, Q) each probe's error
        floors = None
        if Q:   # the senses' floor: Archimedes applied to the probes as the robot measures them (water at 1 g/cm^3)
            sensed = torch.minimum(pmeas["mass_g"], pmeas["fill"] * pmeas["extent_cm"].prod(-1))
            floors = torch.nan_to_num((sensed - truth).abs() / truth, nan=1.0).double().tolist()
        active = agent.config.explore == "active"
        if active:   # the robot chooses its next object: it looks at (and lifts) every one on the stand
            from aesop_torch.exploration import choose_in_order
            seen = agent.activities(meas)
        for t in range(n):
            obj = choose_in_order(agent, *seen, orders, t) if active else orders[:, t]
            res = agent.step({k: v[obj] for k, v in meas.items()}, observed[obj].float(), ep["goal_before"][obj],
                             ep["goal_after"][obj], sank=ep["sank"][obj])
            predicted.append(res.expected.double())
            fired.append(res.rules_fired().clone())
            state.append(agent.rules.state.clone())
            if hasattr(agent.rules, "context_state"):   # knowledge kept per context (contextual_rules.CONTEXTS)
                by_context.append(agent.rules.context_state.clone())
            stored.append(agent.memory.count.clone())
            if t + 1 in checks and Q:
                probe = agent.select(torch.arange(B).repeat_interleave(Q))
                p = probe.anticipate({k: v.repeat(B, *([1] * (v.ndim - 1))) for k, v in pmeas.items()})
                err = torch.nan_to_num((p.expected.view(B, Q) - truth).abs() / truth, nan=1.0)   # none: 100 %
                probe_err[t] = _median_rows(err).double()   # as benches/ablation.py
                per_probe[t] = err.double()
                recalled[t] = p.recall.valid.sum(1).view(B, Q).double().mean(1)   # episodes recalled per cue
        batch = None
        if n <= BATCH_MAX_TRAIN:   # the batch answer: every pair of the set's episodes compared at once
            from aesop_torch.rules import batch_knowledge
            codes = batch_knowledge(*agent.pairwise_evidence(meas, observed.float(), ep["sank"]), agent.config.rules,
                                    properties=agent.properties)
            batch = "".join(KNOWLEDGE_LETTERS[c] for c in codes.tolist())
    # rows order by order, episode by episode: (n, B) -> (B, n) -> flat
    flat = lambda x: np.ascontiguousarray(np.asarray(x).T).reshape(-1)
    obj_idx = orders.numpy()                                            # (B, n)
    pred = flat(torch.stack(predicted).numpy())
    perr = flat(probe_err.numpy())
    fired_codes = torch.stack(fired).permute(1, 0, 2).reshape(B * n, -1).tolist()
    state_codes = torch.stack(state).permute(1, 0, 2).reshape(B * n, -1).tolist()
    knowledge = ["".join(KNOWLEDGE_LETTERS[c] for c in row) for row in state_codes]
    props = list(agent.properties)
    context_knowledge = [None] * (B * n)
    if by_context:   # "floating:LETTERS;sinking:LETTERS;fate:LETTERS", one letter per property as `knowledge`
        names_c = agent.rules.contexts
        codes = torch.stack(by_context).permute(1, 0, 2, 3).reshape(B * n, len(names_c), -1).tolist()
        context_knowledge = [";".join(f"{c}:" + "".join(KNOWLEDGE_LETTERS[x] for x in row)
                                      for c, row in zip(names_c, rows)) for rows in codes]
    arch = np.array([outcomes[k]["archimedes_cm3"] for k in names])
    cond, N = cell["condition"], B * n
    col = lambda v, typ: pa.array([v] * N, typ)
    s = schema()
    data = {
        "cell": col(_digest(cell)[:16], pa.string()), "condition": col(cond["name"], pa.string()),
        "model": col(cond["model"], pa.string()), "ablate": col(",".join(cond["ablate"]), pa.string()),
        "overrides": col(json.dumps(cond["overrides"], sort_keys=True), pa.string()),
        "config": col(config_hash(config_record(cell)), pa.string()),
        "world": col(cell["world"], pa.string()), "set_group": col(cell["set_group"], pa.string()),
        "set": col(cell["set"], pa.string()),
        "generator_seed": col(cell["source"].get("generate", {}).get("seed"), pa.int64()),
        "seed": col(cell["seed"], pa.int64()), "n_train": col(n, pa.int32()), "n_probe": col(Q, pa.int32()),
        "n_orders": col(B, pa.int32()),
        "order": pa.array(np.repeat(np.arange(B), n), pa.int32()),
        "episode": pa.array(np.tile(np.arange(1, n + 1), B), pa.int32()),
        "object": pa.array([names[i] for i in obj_idx.reshape(-1)], pa.string()),
        "predicted_cm3": pa.array(pred, pa.float64(), mask=np.isnan(pred)),
        "observed_cm3": pa.array(observed.numpy()[obj_idx].reshape(-1), pa.float64()),
        "archimedes_cm3": pa.array(arch[obj_idx].reshape(-1), pa.float64()),
        "sank": pa.array(ep["sank"].numpy()[obj_idx].reshape(-1).astype(bool), pa.bool_()),
        "goal_reached": pa.array(ep["goal_after"].numpy()[obj_idx].reshape(-1).astype(bool), pa.bool_()),
        "rules": pa.array(["".join(RULE_LETTERS[c] for c in row) for row in fired_codes], pa.string()),
        "knowledge": pa.array(knowledge, pa.string()),
        **{p: pa.array([k[props.index(p)] if p in props else None for k in knowledge], pa.string())
           for p in PROPERTY_COLUMNS},
        "context_knowledge": pa.array(context_knowledge, pa.string()),
        "probe_rel_error": pa.array(perr, pa.float64(), mask=np.isnan(perr)),
        "batch_knowledge": col(batch, pa.string()),
        "stored": pa.array(flat(torch.stack(stored).numpy()), pa.int32()),
        "recalled": pa.array(flat(recalled.numpy()), pa.float64(), mask=np.isnan(flat(recalled.numpy()))),
        "probe_errors": pa.array([per_probe[t][b].tolist() if t in per_probe else None
                                  for b in range(B) for t in range(n)], pa.list_(pa.float64())),
        "probe_floors": pa.array([floors if t in per_probe else None for b in range(B) for t in range(n)],
                                 pa.list_(pa.float64())),
    }
    return pa.table([data[f.name] for f in s], schema=s)


def cell_id(cell: dict) -> str:
    return _digest(cell)[:16]


def _remote_functions():
    """The Ray tasks (made on first use: `import train.sweep` does not import ray)."""
    import ray

    @ray.remote(num_cpus=1, max_retries=2)   # retried only if a worker dies (e.g. a node lost)
    def world_task(cell, objects):
        import torch
        torch.set_num_threads(1)
        return world_outcomes(cell, objects)

    @ray.remote(num_cpus=1, max_retries=2)   # retried only if a worker dies (e.g. a node lost)
    def cell_task(cell, objects, world, commit):
        import torch
        torch.set_num_threads(1)
        started, t0 = utc_now(), time.perf_counter()
        table = run_cell(cell, objects, world)
        info = {"host": socket.gethostname(), "wall_s": round(time.perf_counter() - t0, 3), "started": started,
                "ended": utc_now()}
        # the Parquet file's bytes, encoded here on the worker: the driver, which shares the cores with the
        # workers on a small machine, only writes them (and Ray moves a few kB instead of the rows)
        return encode_cell(table, cell_metadata(cell, commit, info)), info

    return world_task, cell_task


# -- provenance ---------------------------------------------------------------------------------------------------

META_KEY = b"aesop_torch.sweep"   # the key of a cell file's provenance in its Parquet metadata
LIBRARIES = ("torch", "numpy", "pybullet", "pyarrow", "ray")


def utc_now() -> str:
    """The time now, UTC, ISO 8601 to the second (2026-12-06T14:03:59Z)."""
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def commit() -> str:
    """`git describe --always --dirty --tags` of this checkout; 'unknown' outside git (or without git)."""
    import subprocess
    try:
        r = subprocess.run(["git", "describe", "--always", "--dirty", "--tags"], cwd=ROOT, capture_output=True,
                           text=True, timeout=10, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return r.stdout.strip() if r.returncode == 0 and r.stdout.strip() else "unknown"


def versions() -> dict:
    """The installed versions of the libraries a cell's rows depend on, and Python's (None: not installed)."""
    from importlib import metadata
    found = {"python": sys.version.split()[0]}
    for name in LIBRARIES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found


def cell_metadata(cell: dict, commit: str, info: dict) -> dict:
    """A cell file's provenance (docs/sweeps.md): its id and format, the driver's commit, the worker's libraries,
    host and times, its config's hash and the config itself."""
    record = config_record(cell)
    return {"cell": cell_id(cell), "format": cell["format"], "commit": commit, "versions": versions(), **info,
            "config": config_hash(record), "config_record": record}


def cell_info(path) -> dict:
    """The provenance a cell file holds (cell_metadata's dict); {} for a file written without it."""
    import pyarrow.parquet as pq
    meta = pq.read_metadata(path).metadata or {}
    return json.loads(meta[META_KEY]) if META_KEY in meta else {}


# -- writing ------------------------------------------------------------------------------------------------------

def write_atomic(path: Path, data: bytes) -> None:
    """`data` to `path` through a temporary file in its directory, renamed into place: a reader (or --resume)
    never sees half a file."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def encode_cell(table, metadata: dict | None = None) -> bytes:
    """A cell's rows as the bytes of its Parquet file (zstd, a CRC per page, so --resume notices a damaged one),
    with `metadata` (cell_metadata) as JSON under META_KEY."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    if metadata is not None:
        table = table.replace_schema_metadata({META_KEY: json.dumps(metadata, sort_keys=True)})
    buf = pa.BufferOutputStream()
    pq.write_table(table, buf, compression="zstd", write_page_checksum=True)
    return buf.getvalue().to_pybytes()


def write_cell(out: Path, cid: str, table) -> None:
    """A cell's rows (a Table, or encode_cell's bytes) to DIR/cells/<cid>.parquet, atomically."""
    write_atomic(out / "cells" / f"{cid}.parquet", table if isinstance(table, bytes) else encode_cell(table))


def read_cell(path):
    """One cell file's rows (pyarrow Table of `schema()`, without the file's metadata), its pages' CRCs checked."""
    import pyarrow.parquet as pq
    return pq.read_table(path, page_checksum_verification=True).replace_schema_metadata(None)


def read_cells(out: Path, ids=None):
    """Every finished cell's rows under DIR/cells (only the cells named in `ids`, if given), as one pyarrow Table
    (cells in file-name order)."""
    import pyarrow as pa
    files = sorted((Path(out) / "cells").glob("*.parquet"))
    if ids is not None:
        ids = set(ids)
        files = [f for f in files if f.stem in ids]
    if not files:
        return schema().empty_table()
    return pa.concat_tables([read_cell(f) for f in files])


def check_cell_file(path: Path, cell: dict | None = None) -> str | None:
    """Why the file at `path` is not the finished rows of the cell its name says (None: it is). cell: that cell's
    spec, to check the rows against (its condition, set group, set, seed, orders and episodes); without it, only that
    the file reads and its rows are the cell of its name."""
    import numpy as np
    try:
        st = path.stat()
        if not stat.S_ISREG(st.st_mode):
            return "not a regular file"
        if st.st_size == 0:
            return "empty (0 bytes)"
        table = read_cell(path)
    except Exception as e:   # noqa: BLE001  pyarrow's reasons are many (ArrowInvalid, OSError, ...)
        import re
        why = (str(e).strip().splitlines() or [type(e).__name__])[0]
        why = re.sub(r"^Could not open Parquet input source '.*?': ", "", why)   # the path is said already
        return f"not a readable Parquet file ({why[:120]})"
    if table.schema != schema():
        return f"its columns are not those of format {FORMAT} (another version of train/sweep.py wrote it?)"
    ids = table.column("cell").unique().to_pylist()
    if ids != [path.stem]:
        return (f"holds the rows of cell {ids[0]}, not {path.stem} (renamed?)" if len(ids) == 1 else
                f"holds the rows of {len(ids)} cells" if ids else "holds no rows")
    if cell is None:
        return None
    n, B = cell["n_train"], _n_orders(cell["orders"], cell["n_train"])
    for column, want in (("condition", cell["condition"]["name"]), ("set_group", cell["set_group"]),
                         ("set", cell["set"]), ("seed", cell["seed"]), ("world", cell["world"])):
        got = table.column(column).unique().to_pylist()
        if got != [want]:
            return f"its rows' {column} is {', '.join(map(str, got[:3]))}, not this cell's {want}"
    if table.num_rows != B * n:
        return f"{table.num_rows} rows, not this cell's {B} order(s) x {n} episodes"
    if not (np.array_equal(table.column("order").to_numpy(), np.repeat(np.arange(B), n)) and
            np.array_equal(table.column("episode").to_numpy(), np.tile(np.arange(1, n + 1), B))):
        return "its rows are not this cell's orders and episodes, order by order"
    return None


def survey(out: Path, cells: list[dict]) -> tuple[set, list[str], list[tuple[Path, str]]]:
    """What DIR/cells holds: (the ids of the cells finished, checked by check_cell_file; the names of foreign files,
    no cell of this sweep; (path, why) of the files of this sweep's cells that are not their finished rows). Skipped:
    a write's temporary files (.<cell>.parquet.*.tmp) and files set aside (*.rejected)."""
    by_id = {c["id"]: c["spec"] for c in cells}
    done, foreign, bad = set(), [], []
    folder = out / "cells"
    if not folder.is_dir():
        return done, foreign, bad
    for path in sorted(folder.iterdir()):
        name = path.name
        if name.startswith(".") or name.endswith(".rejected"):
            continue
        if path.suffix != ".parquet" or path.stem not in by_id:
            foreign.append(name)
            continue
        why = check_cell_file(path, by_id[path.stem])
        if why is None:
            done.add(path.stem)
        else:
            bad.append((path, why))
    return done, foreign, bad


def _first_difference(a, b, where: str = "") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in list(a) + [k for k in b if k not in a]:
            if k not in a or k not in b or a[k] != b[k]:
                return _first_difference(a.get(k), b.get(k), f"{where}.{k}" if where else str(k))
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{where} ({len(b)} entries in the sweep file, {len(a)} recorded)"
        for i, (x, y) in enumerate(zip(a, b)):
            if x != y:
                return _first_difference(x, y, f"{where}[{i}]")
    return where or "the spec"


# -- the command line ---------------------------------------------------------------------------------------------

class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints usage + message; one line is enough
        raise SweepError(message)


def _count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {n}")
    return n


def parse_args(argv):
    ap = _Parser(prog=PROG, description=__doc__.split("\n")[0])
    ap.add_argument("sweep", type=Path, metavar="SWEEP.toml", help="the sweep file (TOML, docs/sweeps.md)")
    ap.add_argument("--out", type=Path, metavar="DIR", help="the sweep's directory (default: runs/sweep-<the sweep file's name>)")
    ap.add_argument("--resume", action="store_true", help="run only the cells not yet in DIR/cells")
    ap.add_argument("--address", metavar="ADDR", help="join this Ray cluster (e.g. auto, HOST:6379) instead of starting one here")
    ap.add_argument("--workers", type=_count, metavar="N", help="CPUs of the local Ray instance (default: this machine's cores)")
    a = ap.parse_args(argv)
    if a.address is not None and a.workers is not None:
        raise SweepError("--workers sizes a local Ray instance; with --address the cluster's CPUs decide")
    if a.out is None:
        a.out = Path("runs") / f"sweep-{a.sweep.stem}"
    return a


WRITTEN = ("sweep.json", "configs.json", "cells")   # what a sweep writes in DIR


def _link_inside(out: Path) -> Path | None:
    """The first symbolic link among what the sweep writes in DIR (a link would send its writes elsewhere)."""
    for name in WRITTEN:
        top = out / name
        if top.is_symlink():
            return top
    if (out / "cells").is_dir():
        for entry in sorted(os.scandir(out / "cells"), key=lambda e: e.name):
            if entry.is_symlink():
                return Path(entry.path)
    return None


def check_out(out: Path, spec: dict, resume: bool) -> dict | None:
    """Refuse a DIR this sweep may not write (nothing is created here). --resume: the record DIR/sweep.json holds."""
    if out.is_symlink() and not out.exists():
        raise SweepError(f"--out {out} is a symbolic link to nothing ({os.readlink(out)})")
    if out.exists() and not out.is_dir():
        raise SweepError(f"--out {out} exists and is not a directory")
    recorded = out / "sweep.json"
    record = None
    if resume:
        if link := _link_inside(out):
            raise SweepError(f"--resume: {link} is a symbolic link; the sweep writes only inside --out {out}: "
                             f"remove it")
        if not recorded.exists():
            raise SweepError(f"--resume: {out} holds no sweep ({recorded} not found)")
        try:
            record = json.loads(read_bounded(recorded, MAX_RECORD_BYTES, "a sweep record"))
            old = record["spec"]
        except SweepError as e:
            raise SweepError(f"--resume: {e}") from None
        except (ValueError, KeyError, TypeError, RecursionError) as e:
            why = "nested too deeply" if isinstance(e, RecursionError) else f"{type(e).__name__}: {e}"
            raise SweepError(f"--resume: cannot read {recorded}: {why}") from None
        if old != json.loads(json.dumps(spec)):
            raise SweepError(f"--resume: {out} holds another sweep ({_first_difference(old, spec)} differs); give "
                             f"another --out")
        if (out / "cells").exists() and not (out / "cells").is_dir():
            raise SweepError(f"--resume: {out / 'cells'} is not a directory")
    elif out.is_dir() and any(out.iterdir()):
        raise SweepError(f"--out {out} already holds files; --resume to continue its sweep, or another --out")
    p = out
    while not p.exists():
        if p.is_symlink():
            raise SweepError(f"--out {out}: {p} is a symbolic link to nothing")
        p = p.parent
    if not os.access(p, os.W_OK | os.X_OK):
        raise SweepError(f"--out {out}: {p} is not writable")
    if out.is_dir() and not os.access(out, os.W_OK | os.X_OK):
        raise SweepError(f"--out {out} is not writable")
    return record


def _describe(c: dict) -> str:
    s = c["spec"]
    return f"{s['condition']['name']} / {s['set_group']} {s['set']} / seed {s['seed']}"


class _Progress:
    """Cells done with an ETA: a tqdm bar on a terminal; in a log, a line at every tenth."""

    def __init__(self, total: int, done: int):
        self.total, self.n, self.start, self.t0 = total, done, done, time.perf_counter()
        self.bar = None
        if sys.stderr.isatty():
            import shutil

            from tqdm import tqdm
            sized = shutil.get_terminal_size((0, 0)).columns > 0   # a pty of unknown size reports 0 columns
            self.bar = tqdm(total=total, initial=done, desc="cells", unit="cell", file=sys.stderr, smoothing=0.1,
                            dynamic_ncols=sized, ncols=None if sized else 100, nrows=None if sized else 40)
        self.next = done + max(1, total // 10)

    def update(self) -> None:
        self.n += 1
        if self.bar is not None:
            self.bar.update(1)
        elif self.n >= self.next or self.n == self.total:
            self.next = self.n + max(1, self.total // 10)
            el = time.perf_counter() - self.t0
            eta = el / (self.n - self.start) * (self.total - self.n)
            print(f"cells: {self.n}/{self.total} [{el:.0f} s, ETA {eta:.0f} s]", file=sys.stderr, flush=True)

    def write(self, text: str) -> None:
        if self.bar is not None:
            self.bar.write(text, file=sys.stderr)
        else:
            print(text, file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class JoinError(Exception):
    """A Ray cluster that cannot be joined (--address): one line, exit code 2."""


AUTH_HINT = ("a cluster started with token authentication (ray start's default in recent Ray) needs "
             "RAY_AUTH_MODE=token and its token (RAY_AUTH_TOKEN or ~/.ray/auth_token) in this sweep's environment")


def start_ray(address: str | None, workers: int | None) -> bool:
    """Join `address` or start a quiet local instance; True when this process started (and so ends) it. Reuses a
    Ray already initialised in this process (then False). JoinError (one line) if the cluster cannot be joined."""
    import logging

    import ray
    if ray.is_initialized():
        return False
    job = ray.job_config.JobConfig(code_search_path=[str(ROOT)])   # the workers import train.sweep from here
    if address is not None:
        try:
            _reachable(address)
        except ConnectionError as e:
            raise JoinError(f"cannot join Ray at {address}: {e}; check the address (`ray start --head` prints it, "
                            f"`ray status` on its node)") from None
        with _stderr_kept() as said:   # Ray's gRPC retries print a screenful on a refused join: kept, judged here
            try:
                ray.init(address=address, log_to_driver=False, logging_level=logging.ERROR, job_config=job)
            except Exception as e:   # noqa: BLE001  Ray's reasons are many (ConnectionError, AuthenticationError, ...)
                raise JoinError(_join_failure(address, e, said())) from None
            text = said()
        if text:   # joined: what Ray said on the way (its warnings) is passed on as it was
            sys.stderr.write(text)
            sys.stderr.flush()
        return True
    from train.physics import cores
    # "local": a new instance of this process's own, even where a cluster runs (ray.init() would join that)
    ray.init(address="local", num_cpus=workers or cores(), include_dashboard=False, log_to_driver=False,
             logging_level=logging.ERROR, job_config=job)
    return True


def _join_failure(address: str, e: Exception, said: str) -> str:
    """The one line for a failed ray.init(address=...): an authentication failure named as such, with its fix."""
    import ray
    text = f"{type(e).__name__} {e} {said}".lower()
    first = (str(e).strip().splitlines() or [type(e).__name__])[0][:160]
    if isinstance(e, getattr(ray.exceptions, "AuthenticationError", ())) or any(
            w in text for w in ("unauthenticated", "authentication", "auth_token", "auth token")):
        return (f"cannot join Ray at {address}: the cluster requires token authentication: set RAY_AUTH_MODE=token "
                f"(and its token: RAY_AUTH_TOKEN or ~/.ray/auth_token) and run the sweep again")
    return f"cannot join Ray at {address}: {first}; {AUTH_HINT}"


@contextlib.contextmanager
def _stderr_kept():
    """File descriptor 2 (where Ray's C++ core writes) into a temporary file while the block runs, then back; yields
    a function that returns what was written. Python's sys.stderr writes through fd 2 too."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lambda: (sys.stderr.flush(), tmp.seek(0), tmp.read(1 << 20).decode("utf-8", "replace"))[-1]
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)


def _reachable(address: str, timeout: float = 10.0) -> None:
    """ConnectionError (one line) if HOST:PORT does not answer: ray.init would retry it for ever, printing warnings.
    Other forms (auto, ray://...) are left to Ray."""
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit() or "://" in address:
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as e:
        raise ConnectionError(f"it does not answer ({e.strerror or e})") from None


def run_sweep(cells: list[dict], out: Path, progress: _Progress, on_cell=None, commit: str = "unknown",
              finished: dict | None = None) -> list[tuple[dict, str]]:
    """Run the cells on Ray (initialised), writing each as it finishes; the failures as (cell, one-line reason).
    A few cells per CPU are handed to Ray at a time (the rest wait here: a Ctrl-C leaves little running, and a
    million-cell sweep does not sit in Ray's queues). on_cell(cell): called after each cell is written (tests).
    commit: recorded in each cell file; finished: filled with {cell id: {host, wall_s, started, ended}}."""
    import ray
    world_task, cell_task = _remote_functions()
    window = max(8, 4 * int(ray.cluster_resources().get("CPU", 1)))
    worlds: dict = {}   # a physics world is simulated once (its task), shared by the cells that see it

    def submit(c):
        world = None
        if c["spec"]["world"] == "physics":
            k = world_key(c["spec"])
            if k not in worlds:
                worlds[k] = world_task.remote(c["spec"], c["objects"])
            world = worlds[k]
        return cell_task.remote(c["spec"], c["objects"], world, commit)

    queue = list(reversed(cells))   # popped from the end: in the given order
    pending: dict = {}
    failed = []
    # Nothing is cancelled on the way out (Ctrl-C, a signal, an error): the driver's end (ray.shutdown, or its exit)
    # ends its tasks, locally and on a cluster; ray.cancel then the reply of a cell already done aborted Ray's core
    # worker ("Tried to complete task that was not pending"), exit 1 and a C++ stack trace instead of the one line.
    while queue or pending:
        while queue and len(pending) < window:
            c = queue.pop()
            pending[submit(c)] = c
        # a timeout, so Python sees a Ctrl-C: a wait without one blocks in Ray's C++ and never returns to it
        done, _ = ray.wait(list(pending), num_returns=1, timeout=0.5)
        for ref in done:
            c = pending.pop(ref)
            try:
                data, info = ray.get(ref)
            except ray.exceptions.RayError as e:
                cause = getattr(e, "cause", None) or e
                why = (str(cause).strip().splitlines() or [type(cause).__name__])[-1]
                failed.append((c, why))
                progress.write(f"{PROG}: cell {c['id']} ({_describe(c)}) failed: {why}")
                continue
            write_cell(out, c["id"], data)
            if finished is not None:
                finished[c["id"]] = info
            progress.update()
            if on_cell is not None:
                on_cell(c)
    return failed


# -- how a sweep ends ---------------------------------------------------------------------------------------------

class Ended(KeyboardInterrupt):
    """SIGTERM or SIGHUP (a `kill`, `timeout`, a closed terminal): the sweep ends as on Ctrl-C, a KeyboardInterrupt
    to every handler of one, with exit code 128 + the signal's number."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


ENDING = (signal.SIGTERM, signal.SIGHUP)   # the signals that end a sweep as Ctrl-C does
_DRIVER = {"pid": None, "signal": None}   # the process whose handlers raise Ended (a forked child resets them: see
                                         # _ended), and the last signal they saw


def _ended(signum, frame):
    if os.getpid() != _DRIVER["pid"]:   # a child forked with the handler: the default, silently
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    # kept: raised inside ray.wait, the exception reaches Python as Ray's own KeyboardInterrupt, without its signal
    _DRIVER["signal"] = signum
    raise Ended(signum)


@contextlib.contextmanager
def _ending_signals():
    """SIGTERM and SIGHUP raise Ended while main() runs (only the main thread may set handlers; one ignored, as
    under nohup, stays ignored); the previous handlers afterwards. Yields a function that sets them again: ray.init
    puts its own SIGTERM handler (sys.exit(15)) in place."""
    main = threading.current_thread() is threading.main_thread()
    previous = {sig: signal.getsignal(sig) for sig in ENDING} if main else {}
    _DRIVER["signal"] = None

    def install():
        for sig, handler in previous.items():
            if handler is not signal.SIG_IGN:
                _DRIVER["pid"] = os.getpid()
                signal.signal(sig, _ended)
    try:
        install()
        yield install
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


# a second Ctrl-C (or SIGTERM, SIGHUP) must not interrupt the clean-up after the first: the runner's guard
from train.endings import sigint_ignored as _quiet  # noqa: E402


def _how(e: KeyboardInterrupt) -> tuple[str, int]:
    """(" by SIGTERM" or "", exit code) of an interruption: Ctrl-C 130, a signal 128 + its number."""
    signum = getattr(e, "signum", None) or _DRIVER["signal"] or signal.SIGINT
    return ("" if signum == signal.SIGINT else f" by {signal.Signals(signum).name}"), 128 + signum


# -- main ---------------------------------------------------------------------------------------------------------

def _start(a) -> bool:
    """start_ray, a SIGTERM during ray.init (Ray's handler: sys.exit(15)) turned into Ended."""
    try:
        return start_ray(a.address, a.workers)
    except SystemExit as e:
        if e.code == signal.SIGTERM:
            raise Ended(signal.SIGTERM) from None
        raise


def _write_record(out: Path, record: dict) -> None:
    write_atomic(out / "sweep.json", (json.dumps(record, indent=1) + "\n").encode())


def _write_configs(out: Path, cells: list[dict]) -> None:
    """DIR/configs.json: {config hash: config_record} of every cell of the sweep, with those recorded before (a
    resumed sweep whose code resolves a config otherwise keeps both)."""
    configs = {}
    path = out / "configs.json"
    if path.exists():
        try:
            old = json.loads(read_bounded(path, MAX_RECORD_BYTES, "a configs record"))
            configs = old if isinstance(old, dict) else {}
        except (SweepError, ValueError, RecursionError):
            pass   # damaged: written anew from the cells
    for c in cells:
        record = config_record(c["spec"])
        configs.setdefault(config_hash(record), record)
    write_atomic(path, (json.dumps(configs, indent=1, sort_keys=True) + "\n").encode())


def main(argv=None, on_cell=None) -> int:
    with _ending_signals() as reinstall:
        return _main(argv, on_cell, reinstall)


def _main(argv, on_cell, reinstall) -> int:
    owns_ray = False   # this process started (or joined) Ray, and so ends it
    progress = None
    out = None
    n_cells = 0
    record, run = None, None   # DIR/sweep.json as written, and this run's entry in it
    try:
        try:
            a = parse_args(sys.argv[1:] if argv is None else argv)
            spec, cells = load_sweep(a.sweep)
            record = check_out(a.out, spec, a.resume)
        except SweepError as e:
            print(f"{PROG}: error: {e}", file=sys.stderr)
            return 2
        done, foreign, bad = survey(a.out, cells) if a.resume else (set(), [], [])
        for name in foreign:
            print(f"{PROG}: {a.out / 'cells' / name} is no cell of this sweep: not counted (move it out of "
                  f"{a.out / 'cells'})", file=sys.stderr)
        for path, why in bad:
            print(f"{PROG}: {path}: {why}: its cell runs again (the file is kept as {path.name}.rejected)",
                  file=sys.stderr)
        todo = [c for c in cells if c["id"] not in done]
        where = f"Ray at {a.address}" if a.address else "a local Ray instance"
        print(f"{PROG}: {len(cells)} cell(s) ({len(spec['conditions'])} condition(s), world {spec['world']}), "
              f"{len(cells) - len(todo)} on disk, {len(todo)} to run on {where} -> {a.out}", flush=True)
        t0 = time.perf_counter()
        failed = []
        if todo:   # Ray first: a cluster that cannot be joined leaves nothing behind
            import ray
            owns_ray = not ray.is_initialized()   # from here on a Ctrl-C during ray.init ends what it started
            try:
                _start(a)
            except JoinError as e:
                print(f"{PROG}: error: {e}", file=sys.stderr)
                return 2
            except Exception as e:   # noqa: BLE001  Ray's reasons are many (RuntimeError, OSError, ...)
                print(f"{PROG}: error: cannot start Ray: {(str(e).strip().splitlines() or [type(e).__name__])[0]}",
                      file=sys.stderr)
                return 1
            finally:
                reinstall()   # ray.init set its own SIGTERM handler
        try:
            (a.out / "cells").mkdir(parents=True, exist_ok=True)
            for path, _ in bad:
                os.replace(path, path.with_name(path.name + ".rejected"))
            prov = {"commit": commit(), "versions": versions()}
            run = {"started": utc_now(), "ended": None, "ended_by": None, "resumed": a.resume,
                   "host": socket.gethostname(), "ray": a.address or "local", **prov, "cells_run": 0,
                   "cells_failed": 0, "cells": {}}
            if record is None:
                record = {"format": FORMAT, "sweep_file": str(a.sweep), "spec": spec,
                          "cells": [c["id"] for c in cells], "runs": []}
            record.setdefault("runs", []).append(run)
            record["cells"] = [c["id"] for c in cells]
            _write_configs(a.out, cells)
            _write_record(a.out, record)
            out, n_cells = a.out, len(cells)
            if todo:
                progress = _Progress(len(cells), len(cells) - len(todo))
                try:
                    failed = run_sweep(todo, out, progress, on_cell, commit=prov["commit"], finished=run["cells"])
                finally:
                    progress.close()
        except OSError as e:   # a full disk, DIR removed under the sweep: the cells written so far stay
            with _quiet():
                _finish(out, record, run, "error")
                print(f"{_fresh_line()}{PROG}: error: cannot write {e.filename or a.out}: {e.strerror or e}",
                      file=sys.stderr)
            return 1
        _finish(out, record, run, "failed" if failed else "finished", len(failed))
        if failed:
            print(f"{PROG}: {len(failed)} of {len(cells)} cell(s) failed (the first: {_describe(failed[0][0])}: "
                  f"{failed[0][1]}); --resume runs them again", file=sys.stderr)
            return 1
        print(f"done: {len(cells)} cell(s) in {out / 'cells'} ({time.perf_counter() - t0:.0f} s); summary: "
              f"python -m train.report {out}", flush=True)
        return 0
    except KeyboardInterrupt as e:
        by, code = _how(e)
        with _quiet():
            if progress is not None:
                progress.close()
            if out is None:
                print(f"{_fresh_line()}{PROG}: interrupted{by} before the sweep started", file=sys.stderr)
            else:
                _finish(out, record, run, f"interrupted{by}")
                done = len(list((out / "cells").glob("*.parquet")))
                print(f"{_fresh_line()}{PROG}: interrupted{by}: {done} of {n_cells} cell(s) on disk in "
                      f"{out / 'cells'} (--resume runs the rest)", file=sys.stderr)
            if argv is None:   # the command line's sweep: its one line said, Ray's teardown says nothing more
                _silence_stderr()
            _stop_ray(owns_ray)
            owns_ray = False
        return code
    finally:
        if owns_ray:
            with _quiet():
                _stop_ray(True)


def _finish(out: Path | None, record: dict | None, run: dict | None, how: str, failed: int = 0) -> None:
    """This run's entry in DIR/sweep.json completed (its end, how it ended, the cells it ran); a write that fails
    here leaves the entry as written at the start (the sweep's own line says what happened)."""
    if out is None or record is None or run is None or run["ended"] is not None:
        return
    run.update(ended=utc_now(), ended_by=how, cells_run=len(run["cells"]), cells_failed=failed)
    try:
        _write_record(out, record)
    except OSError:
        pass


def _silence_stderr() -> None:
    """fd 2 to /dev/null: Ray's core worker writes to it directly while it tears down after an interruption (a cell
    that finished after the driver let go: 'Failed to push error to driver for task ...'), after the sweep's one
    line. Only for the command line (main() with argv None): a caller's own stderr is left alone."""
    try:
        sys.stderr.flush()
        fd = os.open(os.devnull, os.O_WRONLY)
        os.dup2(fd, 2)
        os.close(fd)
    except OSError:
        pass


def _fresh_line() -> str:
    """A newline on a terminal, where a progress bar (or ^C) may have left the cursor mid-line; nothing in a log."""
    return "\n" if sys.stderr.isatty() else ""


def _stop_ray(owns: bool) -> None:
    if owns:
        import ray
        try:
            if ray.is_initialized():
                ray.shutdown()
        except Exception:   # noqa: BLE001  a Ray already torn down by the same Ctrl-C: nothing left to end
            pass


if __name__ == "__main__":
    # through the importable module, so the Ray workers find the cell function by reference (not __main__'s copy)
    from train.sweep import main as _main
    sys.exit(_main())
