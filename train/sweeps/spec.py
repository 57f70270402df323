"""A sweep file -> its resolved spec and its cells (docs/sweeps.md "The sweep file").

Every key is checked and every default filled in before anything runs: a bad file is a SweepError, one line. A
cell is one condition on one object set with one seed; its id is a stable hash of its spec (everything its rows
are computed from), so a resumed sweep finds the cells an earlier run wrote.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

from sim.input_files import show
from train.common.models import ABLATIONS, MODELS, check_capacity

PROG = "train/sweep.py"  # what every line of a sweep starts with
FORMAT = 4               # in every cell's hash: bumped when the rows a spec gives change (2: batch_knowledge,
                         # stored, recalled, probe_errors, probe_floors; 3: config; 4: commit)
WORLDS = ("closed_form", "closed_form_exact", "physics")
MAX_CELLS = 1_000_000
MAX_SEEDS = 1_000_000    # seeds of one range
MAX_ORDERS = 100_000     # orders of one cell (one batched agent)
MAX_SEED = 2 ** 63       # torch.Generator.manual_seed takes a 64-bit integer
MAX_SWEEP_BYTES = 1_000_000     # a sweep file: the shipped ones are under 2 kB and a sweep of a million cells
                                # needs a few lines; a file far larger is no sweep file (/dev/zero: read no further)
MAX_NESTING = 16                # tables and lists in tables: the shipped sweep files nest 5 deep

TOP_KEYS = ("description", "world", "conditions", "sets")
CONDITION_KEYS = ("name", "model", "ablate", "overrides")
SET_KEYS = ("name", "files", "generate", "orders", "seeds", "checks")
GENERATE_KEYS = ("seeds", "train", "probe", "pairs", "jar")


class SweepError(Exception):
    """A bad sweep file, flag or DIR: one line on stderr, exit code 2."""


def _keys(d, allowed, where: str) -> dict:
    if not isinstance(d, dict):
        raise SweepError(f"{where}: expected a table, got {show(d)}")
    if bad := [k for k in d if k not in allowed]:
        raise SweepError(f"{where}: unknown key {bad[0]!r} (known: {', '.join(allowed)})")
    return d


def _int(v, where: str, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise SweepError(f"{where}: expected a whole number, got {show(v)}")
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
        raise SweepError(f"{where}: expected a non-empty string, got {show(v)}")
    if not v.isprintable() or len(v) > 100:
        raise SweepError(f"{where}: at most 100 printable characters, got {show(v)}")
    return v


def _list(v, where: str) -> list:
    if not isinstance(v, list):
        raise SweepError(f"{where}: expected a list, got {show(v)}")
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
                         f"got {show(v)}")
    a, b = (_int(x, f"{where}[{i}]", 0, MAX_SEED) for i, x in enumerate(v))
    if b <= a:
        raise SweepError(f"{where}: the range [{a}, {b}) is empty")
    if b - a > MAX_SEEDS:
        raise SweepError(f"{where}: the range [{a}, {b}) holds more than {MAX_SEEDS:,} seeds")
    return list(range(a, b))


def _orders(v, where: str, n_train: int) -> str:
    """As train.learning.experiment.draw_orders takes it: 'N', 'listed' or 'all'."""
    if v in ("listed", "all"):
        if v == "all" and math.factorial(n_train) > 40_320:
            raise SweepError(f"{where}: 'all' orders of {n_train} objects are {math.factorial(n_train):,} "
                             f"(at most 8 objects); give a number of random orders")
        return v
    if isinstance(v, str):
        raise SweepError(f"{where}: expected a number of random orders, 'listed' or 'all', got {show(v)}")
    return str(_int(v, where, 1, MAX_ORDERS))


def n_orders(orders: str, n_train: int) -> int:
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
            raise SweepError(f"{where}: {key!r}: expected a number, string, boolean or list, got {show(v)}")
    return out


def agent_config(condition: dict, seed: int, n_train: int):
    """The cell's AgentConfig: the named model with its ablations, the buffers sized to the set (as
    benches/ablation.py sizes them), then the condition's overrides (which may size them otherwise)."""
    from aesop_torch.agent import AgentConfig
    cfg = AgentConfig.named(condition["model"], ablate=tuple(condition["ablate"]), seed=seed)
    cfg.memory.max_episodes = cfg.hub.max_assemblies = n_train
    if condition["overrides"]:
        from train.common.config import apply_overrides
        cfg = apply_overrides(cfg, condition["overrides"])
    return cfg


def _condition(c, where: str, names: set) -> dict:
    _keys(c, CONDITION_KEYS, where)
    name, where = _entry_name(c, where, names, "condition")
    if "model" not in c:
        raise SweepError(f"{where}: no 'model' (one of: {', '.join(MODELS)})")
    model = c["model"]
    if model not in MODELS:
        raise SweepError(f"{where}: model: {show(model)} is not a model (known: {', '.join(MODELS)})")
    ablate = c.get("ablate", [])
    if not isinstance(ablate, list):
        raise SweepError(f"{where}: ablate: expected a list (e.g. [\"rules\"]), got {show(ablate)}")
    for a in ablate:
        if a not in ABLATIONS[model]:
            raise SweepError(f"{where}: ablate: {show(a)} is no ablation of the {model} model (it has: "
                             f"{', '.join(ABLATIONS[model])})")
    if len(set(ablate)) != len(ablate):
        raise SweepError(f"{where}: ablate: {next(a for a in ablate if ablate.count(a) > 1)!r} is listed twice")
    overrides = c.get("overrides", {})
    if not isinstance(overrides, dict):
        raise SweepError(f"{where}: overrides: expected a table of dotted keys, got {show(overrides)}")
    cond = {"name": name, "model": model, "ablate": [a for a in ABLATIONS[model] if a in ablate],
            "overrides": dict(sorted(_flat_overrides(overrides, where + " overrides").items()))}
    for key, why in (("model", "the condition's model"), ("ablate", "the condition's ablate"),
                     ("seed", "a set's seeds")):
        if key in cond["overrides"]:
            raise SweepError(f"{where}: overrides: {key!r} is set by {why}, not by an override")
    if cond["overrides"]:
        try:
            from train.common.config import ConfigError
        except ImportError:
            raise SweepError(f"{where}: overrides need train/common/config.py, which this checkout lacks") from None
        try:
            from train.common.agent_checks import check_agent
            check_agent(agent_config(cond, 0, 8), given=tuple(cond["overrides"]))
        except (ConfigError, ValueError, TypeError) as e:
            why = (str(e).strip().splitlines() or [type(e).__name__])[0]
            raise SweepError(f"{where}: overrides: {why}") from None
    return cond


def digest(obj) -> str:
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
            found.append({"label": f, "generator_seed": None, "source": {"file": f, "sha256": digest(data)},
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
            raise SweepError(f"{where}.generate.pairs: expected true or false, got {show(gen['pairs'])}")
        if gen["jar"] not in ("random", "default"):
            raise SweepError(f"{where}.generate.jar: expected \"random\" or \"default\", got {show(gen['jar'])}")
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
    """A file's bytes, if it is a regular file of at most `limit` bytes; SweepError (one line) otherwise: the
    project's bounded reader (sim.input_files.read_bytes: no wait on a FIFO, /dev/zero read no further than the
    limit), its refusals worded as the sweeps' contract words them (docs/sweeps.md)."""
    from sim.input_files import InputFileError, read_bytes
    try:
        return read_bytes(path, str(path), limit)
    except InputFileError as e:
        if e.reason == "kind":
            raise SweepError(f"{path}: is {e.detail}, not {what} (a regular file)") from None
        if e.reason == "size":
            raise SweepError(f"{path}: larger than {limit:,} bytes, too large for {what}") from None
        raise SweepError(f"{path}: cannot read it: {e.detail or e}") from None


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
        raise SweepError(f"description: expected a string, got {show(doc['description'])}")
    world = doc.get("world", "closed_form")
    if world not in WORLDS:
        raise SweepError(f"world: {show(world)} is not a world (known: {', '.join(WORLDS)})")
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
                    cells.append({"id": digest(cs)[:16], "spec": cs, "objects": f["data"]})
    if len({c["id"] for c in cells}) != len(cells):
        raise SweepError("two cells are the same (a condition or an object set listed twice under other names?)")
    # the longest first: a long cell started last would keep one worker busy while the rest idle
    cells.sort(key=lambda c: -c["spec"]["n_train"] * max(8, n_orders(c["spec"]["orders"], c["spec"]["n_train"])))
    return spec, cells

