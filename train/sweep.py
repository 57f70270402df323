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
import hashlib
import json
import math
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the project importable without installing it
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

ROOT = Path(__file__).resolve().parents[1]
PROG = "train/sweep.py"
FORMAT = 2               # in every cell's hash: bumped when the rows a spec gives change (2: batch_knowledge,
                         # stored, recalled, probe_errors, probe_floors)
BATCH_MAX_TRAIN = 500    # the batch answer compares every pair of a set's train objects: up to this many
WORLDS = ("closed_form", "closed_form_exact", "physics")
from train.run_config import ABLATIONS, MODELS, check_capacity  # noqa: E402   the runner's tables, torch-free
MAX_CELLS = 1_000_000
MAX_SEEDS = 1_000_000    # seeds of one range
MAX_ORDERS = 100_000     # orders of one cell (one batched agent)
MAX_SEED = 2 ** 63       # torch.Generator.manual_seed takes a 64-bit integer
KNOWLEDGE_LETTERS = "ULDI"   # train.summary.KNOWLEDGE_LETTERS: one per aesop_torch.rules.STATES code
RULE_LETTERS = "SEGU"        # aesop_torch.rules.RULE_NAMES
PROPERTY_COLUMNS = ("color", "shape", "size", "weight")   # aesop_torch.rules.PROPERTIES

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


def load_sweep(path: Path) -> tuple[dict, list[dict]]:
    """Read and check a sweep file: (the resolved spec, the cells in the order they are to run). Each cell is
    {"id", "spec" (what its id hashes), "objects" (an objects file's data, or None for a generated set)}. SweepError
    (one line) for anything wrong."""
    try:
        import tomllib
    except ModuleNotFoundError:   # Python 3.10
        import tomli as tomllib
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        raise SweepError(f"{path}: cannot read it: {e.strerror or e}") from None
    try:
        doc = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise SweepError(f"{path}: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as e:
        raise SweepError(f"{path}: malformed TOML: {str(e).splitlines()[0]}") from None
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
        return closed_form_outcomes(objs, sensor=SensorModel() if cell["world"] == "closed_form" else None,
                                    seed=seed)
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


def world_key(cell: dict) -> str:
    """Cells with the same key see the same world (conditions differ): a physics world is simulated once per key."""
    return _digest([cell["world"], cell["source"], cell["seed"]])


def schema():
    """The Parquet rows' schema (docs/sweeps.md)."""
    import pyarrow as pa
    return pa.schema([
        ("cell", pa.string()), ("condition", pa.string()), ("model", pa.string()), ("ablate", pa.string()),
        ("overrides", pa.string()), ("world", pa.string()), ("set_group", pa.string()), ("set", pa.string()),
        ("generator_seed", pa.int64()), ("seed", pa.int64()), ("n_train", pa.int32()), ("n_probe", pa.int32()),
        ("n_orders", pa.int32()), ("order", pa.int32()), ("episode", pa.int32()), ("object", pa.string()),
        ("predicted_cm3", pa.float64()), ("observed_cm3", pa.float64()), ("archimedes_cm3", pa.float64()),
        ("sank", pa.bool_()), ("goal_reached", pa.bool_()), ("rules", pa.string()), ("knowledge", pa.string()),
        *[(p, pa.string()) for p in PROPERTY_COLUMNS], ("probe_rel_error", pa.float64()),
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
        predicted, fired, state, stored = [], [], [], []
        probe_err = torch.full((n, B), float("nan"), dtype=torch.float64)
        recalled = torch.full((n, B), float("nan"), dtype=torch.float64)
        per_probe = {}   # episode index -> (B, Q) each probe's error
        floors = None
        if Q:   # the senses' floor: Archimedes applied to the probes as the robot measures them (water at 1 g/cm^3)
            sensed = torch.minimum(pmeas["mass_g"], pmeas["fill"] * pmeas["extent_cm"].prod(-1))
            floors = torch.nan_to_num((sensed - truth).abs() / truth, nan=1.0).double().tolist()
        for t in range(n):
            obj = orders[:, t]
            res = agent.step({k: v[obj] for k, v in meas.items()}, observed[obj].float(), ep["goal_before"][obj],
                             ep["goal_after"][obj], sank=ep["sank"][obj])
            predicted.append(res.expected.double())
            fired.append(res.rules_fired().clone())
            state.append(agent.rules.state.clone())
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
            codes = batch_knowledge(*agent.pairwise_evidence(meas, observed.float(), ep["sank"]), agent.config.rules)
            batch = "".join(KNOWLEDGE_LETTERS[c] for c in codes.tolist())
    # rows order by order, episode by episode: (n, B) -> (B, n) -> flat
    flat = lambda x: np.ascontiguousarray(np.asarray(x).T).reshape(-1)
    obj_idx = orders.numpy()                                            # (B, n)
    pred = flat(torch.stack(predicted).numpy())
    perr = flat(probe_err.numpy())
    fired_codes = torch.stack(fired).permute(1, 0, 2).reshape(B * n, -1).tolist()
    state_codes = torch.stack(state).permute(1, 0, 2).reshape(B * n, -1).tolist()
    knowledge = ["".join(KNOWLEDGE_LETTERS[c] for c in row) for row in state_codes]
    arch = np.array([outcomes[k]["archimedes_cm3"] for k in names])
    cond, N = cell["condition"], B * n
    col = lambda v, typ: pa.array([v] * N, typ)
    s = schema()
    data = {
        "cell": col(_digest(cell)[:16], pa.string()), "condition": col(cond["name"], pa.string()),
        "model": col(cond["model"], pa.string()), "ablate": col(",".join(cond["ablate"]), pa.string()),
        "overrides": col(json.dumps(cond["overrides"], sort_keys=True), pa.string()),
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
        **{p: pa.array([k[i] for k in knowledge], pa.string()) for i, p in enumerate(PROPERTY_COLUMNS)},
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
    def cell_task(cell, objects, world):
        import torch
        torch.set_num_threads(1)
        # the Parquet file's bytes, encoded here on the worker: the driver, which shares the cores with the
        # workers on a small machine, only writes them (and Ray moves a few kB instead of the rows)
        return encode_cell(run_cell(cell, objects, world))

    return world_task, cell_task


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


def encode_cell(table) -> bytes:
    """A cell's rows as the bytes of its Parquet file (zstd)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    buf = pa.BufferOutputStream()
    pq.write_table(table, buf, compression="zstd")
    return buf.getvalue().to_pybytes()


def write_cell(out: Path, cid: str, table) -> None:
    """A cell's rows (a Table, or encode_cell's bytes) to DIR/cells/<cid>.parquet, atomically."""
    write_atomic(out / "cells" / f"{cid}.parquet", table if isinstance(table, bytes) else encode_cell(table))


def read_cells(out: Path):
    """Every finished cell's rows under DIR/cells, as one pyarrow Table (cells in file-name order)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    files = sorted((Path(out) / "cells").glob("*.parquet"))
    if not files:
        return schema().empty_table()
    return pa.concat_tables([pq.read_table(f) for f in files])


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


def check_out(out: Path, spec: dict, resume: bool) -> None:
    """Refuse a DIR this sweep may not write (nothing is created here)."""
    if out.exists() and not out.is_dir():
        raise SweepError(f"--out {out} exists and is not a directory")
    recorded = out / "sweep.json"
    if resume:
        if not recorded.is_file():
            raise SweepError(f"--resume: {out} holds no sweep ({recorded} not found)")
        try:
            old = json.loads(recorded.read_text())["spec"]
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise SweepError(f"--resume: cannot read {recorded}: {e}") from None
        if old != json.loads(json.dumps(spec)):
            raise SweepError(f"--resume: {out} holds another sweep ({_first_difference(old, spec)} differs); give "
                             f"another --out")
    elif out.is_dir() and any(out.iterdir()):
        raise SweepError(f"--out {out} already holds files; --resume to continue its sweep, or another --out")
    p = out
    while not p.exists():
        p = p.parent
    if not os.access(p, os.W_OK | os.X_OK):
        raise SweepError(f"--out {out}: {p} is not writable")


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


def start_ray(address: str | None, workers: int | None) -> bool:
    """Join `address` or start a quiet local instance; True when this process started (and so ends) it. Reuses a
    Ray already initialised in this process (then False)."""
    import logging

    import ray
    if ray.is_initialized():
        return False
    job = ray.job_config.JobConfig(code_search_path=[str(ROOT)])   # the workers import train.sweep from here
    if address is not None:
        _reachable(address)
        ray.init(address=address, log_to_driver=False, logging_level=logging.ERROR, job_config=job)
        return True
    from train.physics import cores
    # "local": a new instance of this process's own, even where a cluster runs (ray.init() would join that)
    ray.init(address="local", num_cpus=workers or cores(), include_dashboard=False, log_to_driver=False,
             logging_level=logging.ERROR, job_config=job)
    return True


def _reachable(address: str, timeout: float = 10.0) -> None:
    """ConnectionError (one line) if HOST:PORT does not answer: ray.init would retry it for ever, printing warnings.
    Other forms (auto, ray://...) are left to Ray."""
    import socket
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit() or "://" in address:
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as e:
        raise ConnectionError(f"{address} does not answer ({e.strerror or e})") from None


def run_sweep(cells: list[dict], out: Path, progress: _Progress, on_cell=None) -> list[tuple[dict, str]]:
    """Run the cells on Ray (initialised), writing each as it finishes; the failures as (cell, one-line reason).
    A few cells per CPU are handed to Ray at a time (the rest wait here: a Ctrl-C leaves little running, and a
    million-cell sweep does not sit in Ray's queues). on_cell(cell): called after each cell is written (tests)."""
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
        return cell_task.remote(c["spec"], c["objects"], world)

    queue = list(reversed(cells))   # popped from the end: in the given order
    pending: dict = {}
    failed = []
    # Nothing is cancelled on the way out (Ctrl-C, an error): the driver's end (ray.shutdown, or its exit) ends its
    # tasks, locally and on a cluster; ray.cancel then the reply of a cell already done aborted Ray's core worker
    # ("Tried to complete task that was not pending"), exit 1 and a C++ stack trace instead of the one line.
    while queue or pending:
        while queue and len(pending) < window:
            c = queue.pop()
            pending[submit(c)] = c
        # a timeout, so Python sees a Ctrl-C: a wait without one blocks in Ray's C++ and never returns to it
        done, _ = ray.wait(list(pending), num_returns=1, timeout=0.5)
        for ref in done:
            c = pending.pop(ref)
            try:
                data = ray.get(ref)
            except ray.exceptions.RayError as e:
                cause = getattr(e, "cause", None) or e
                why = (str(cause).strip().splitlines() or [type(cause).__name__])[-1]
                failed.append((c, why))
                progress.write(f"{PROG}: cell {c['id']} ({_describe(c)}) failed: {why}")
                continue
            write_cell(out, c["id"], data)
            progress.update()
            if on_cell is not None:
                on_cell(c)
    return failed


def _sigint_ignored():
    """The runner's guard: a second Ctrl-C must not interrupt the clean-up after the first."""
    from train.endings import sigint_ignored
    return sigint_ignored()


def main(argv=None, on_cell=None) -> int:
    owns_ray = False   # this process started (or joined) Ray, and so ends it
    progress = None
    out = None
    n_cells = 0
    try:
        try:
            a = parse_args(sys.argv[1:] if argv is None else argv)
            spec, cells = load_sweep(a.sweep)
            check_out(a.out, spec, a.resume)
        except SweepError as e:
            print(f"{PROG}: error: {e}", file=sys.stderr)
            return 2
        cells_dir = a.out / "cells"
        on_disk = {p.stem for p in cells_dir.glob("*.parquet")} if cells_dir.is_dir() else set()
        todo = [c for c in cells if c["id"] not in on_disk]
        where = f"Ray at {a.address}" if a.address else "a local Ray instance"
        print(f"{PROG}: {len(cells)} cell(s) ({len(spec['conditions'])} condition(s), world {spec['world']}), "
              f"{len(cells) - len(todo)} on disk, {len(todo)} to run on {where} -> {a.out}", flush=True)
        t0 = time.perf_counter()
        failed = []
        if todo:   # Ray first: a cluster that cannot be joined leaves nothing behind
            import ray
            owns_ray = not ray.is_initialized()   # from here on a Ctrl-C during ray.init ends what it started
            try:
                start_ray(a.address, a.workers)
            except Exception as e:   # noqa: BLE001  Ray's reasons are many (ConnectionError, RuntimeError, ...)
                print(f"{PROG}: error: cannot {'join Ray at ' + a.address if a.address else 'start Ray'}: "
                      f"{(str(e).strip().splitlines() or [type(e).__name__])[0]}", file=sys.stderr)
                return 1
        try:
            cells_dir.mkdir(parents=True, exist_ok=True)
            if not a.resume:
                write_atomic(a.out / "sweep.json", (json.dumps({"format": FORMAT, "sweep_file": str(a.sweep),
                                                                "spec": spec}, indent=1) + "\n").encode())
            out, n_cells = a.out, len(cells)
            if todo:
                progress = _Progress(len(cells), len(cells) - len(todo))
                try:
                    failed = run_sweep(todo, out, progress, on_cell)
                finally:
                    progress.close()
        except OSError as e:   # a full disk, DIR removed under the sweep: the cells written so far stay
            print(f"{_fresh_line()}{PROG}: error: cannot write {e.filename or a.out}: {e.strerror or e}",
                  file=sys.stderr)
            return 1
        if failed:
            print(f"{PROG}: {len(failed)} of {len(cells)} cell(s) failed (the first: {_describe(failed[0][0])}: "
                  f"{failed[0][1]}); --resume runs them again", file=sys.stderr)
            return 1
        print(f"done: {len(cells)} cell(s) in {out / 'cells'} ({time.perf_counter() - t0:.0f} s); summary: "
              f"python -m train.report {out}", flush=True)
        return 0
    except KeyboardInterrupt:
        with _sigint_ignored():
            if progress is not None:
                progress.close()
            if out is None:
                print(f"{_fresh_line()}{PROG}: interrupted before the sweep started", file=sys.stderr)
            else:
                done = len(list((out / "cells").glob("*.parquet")))
                print(f"{_fresh_line()}{PROG}: interrupted: {done} of {n_cells} cell(s) on disk in {out / 'cells'} "
                      f"(--resume runs the rest)", file=sys.stderr)
            _stop_ray(owns_ray)
            owns_ray = False
        return 130
    finally:
        if owns_ray:
            with _sigint_ignored():
                _stop_ray(True)


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
