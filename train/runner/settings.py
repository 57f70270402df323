"""A run's settings from its flags: --orders and --seed as given, the config from --config, --set, --model, --ablate
and --seed (train/common/config.py), a resumed run's own settings from DIR/run.json, the objects, and every check of them
that needs no simulation.

The config's overrides apply in order, a later value of a key replacing an earlier one: the --config file, each --set
in the order given, then --model, --ablate and --seed (shorthands for the keys model, ablate and seed). Their syntax
and the run-level keys are checked torch-free (gather_config); every other key against the dataclasses
(resolve_config, which imports torch and the simulator). Each refusal is a UsageError naming where the value came
from. The tables of models and ablations and check_capacity are train/common/models.py's, shared with the sweeps.
"""

from __future__ import annotations

import argparse
import copy
import re
from pathlib import Path

from train.common.exits import UsageError
from train.common.models import ABLATIONS, MODELS
from train.runner.out_dir import CONFIG_NAME, RUN_NAME

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OBJECTS = ROOT / "sim" / "default_objects.json"
DEFAULT_ORDERS = "4"     # the paper's Figure 2: four random orders of the eight objects
MAX_ORDERS = 1_000_000   # orders of one run; beyond this the orders alone fill gigabytes (8 ints each, as lists)
# orders run in detail, more as a population: 64 orders x 8 episodes of full records is ~0.5 MB of JSON; 40,320
# would be ~300 MB
FULL_RUNS = 64
MAX_SEED = 2 ** 63       # torch.Generator.manual_seed takes a 64-bit integer; stored as int64 in tensors
ORDERS_RE = re.compile(r"[1-9][0-9]{0,6}|listed|all", re.ASCII)
SEED_RE = re.compile(r"[0-9]{1,19}", re.ASCII)


def orders_arg(text: str) -> str:
    if not ORDERS_RE.fullmatch(text) or (text.isdigit() and int(text) > MAX_ORDERS):
        raise argparse.ArgumentTypeError(f"must be a number from 1 to {MAX_ORDERS:,} (ASCII digits), 'listed' or "
                                         f"'all', not {shown(text)}")
    return text


def seed_arg(text: str) -> int:
    if not SEED_RE.fullmatch(text) or int(text) >= MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be an integer from 0 to 2**63 - 1 (ASCII digits), not {shown(text)}")
    return int(text)


def shown(text: str, cut: int | None = None) -> str:
    """A command-line word as an error line quotes it: escaped, cut as every refused value is (CONTRACTS.md)."""
    from sim.input_files import MAX_SHOWN
    cut = cut or MAX_SHOWN
    return repr(text if len(text) <= cut else text[:cut - 3] + "...")


def gather_config(a) -> None:
    """The config's overrides in the order they apply (--config, each --set, then --model, --ablate, --seed) as
    a.overrides {dotted key: value}, where each came from as a.origins {key: "--set k=v" | "--config FILE" | flag},
    and the run-level keys resolved into a.model, a.ablate, a.seed. Torch-free: the syntax, the file and these three
    keys are checked here; every other key against the dataclasses in resolve_config."""
    from train.common.config import ConfigError, load_toml, parse_set

    overrides, origins = {}, {}

    def put(key, value, origin):
        overrides.pop(key, None)   # re-inserted: the dicts' order is the order the values apply in
        origins.pop(key, None)
        overrides[key], origins[key] = value, origin

    if a.config is not None:
        try:
            for key, value in load_toml(a.config).items():
                put(key, value, f"--config {a.config}")
        except ConfigError as e:
            raise UsageError(f"--config {e}") from None
    for text in a.sets:
        try:
            key, value = parse_set(text)
        except ConfigError as e:
            raise UsageError(f"--set {shown(text, 100)[1:-1]}: {e}") from None
        put(key, value, f"--set {shown(text, 100)[1:-1]}")
    if a.model is not None:
        put("model", a.model, "--model")
    if a.ablate is not None:
        put("ablate", list(dict.fromkeys(a.ablate)), "--ablate")
    if getattr(a, "explore", None) is not None:
        put("explore", a.explore, "--explore")
    if a.seed is not None:
        put("seed", a.seed, "--seed")
    a.overrides, a.origins = overrides, origins
    if not getattr(a, "resume", False):   # --resume: once the run's own model is known (adopt_run)
        run_level(a)


def run_level(a) -> None:
    """a.model, a.ablate, a.seed from a.overrides, checked (torch-free)."""
    from train.common.config import show

    overrides, origins = a.overrides, a.origins
    model = overrides.get("model", "paper")
    if model not in MODELS:   # a flag's is checked by argparse; the file's and --set's here (before the first line)
        raise UsageError(f"{origins['model']}: model takes one of {', '.join(MODELS)}, got {show(model)}")
    ablate = overrides.get("ablate", [])
    if not isinstance(ablate, list) or not all(isinstance(p, str) for p in ablate):
        raise UsageError(f"{origins['ablate']}: ablate takes an array of strings, got {show(ablate)}")
    if bad := [p for p in ablate if p not in ABLATIONS[model]]:
        where = f"--ablate {bad[0]}" if origins["ablate"] == "--ablate" else f"{origins['ablate']}: ablate {bad[0]}"
        raise UsageError(f"{where}: not a part of the {model} model (it has: {', '.join(ABLATIONS[model])})")
    seed = overrides.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < MAX_SEED:
        raise UsageError(f"{origins['seed']}: seed takes an integer from 0 to 2**63 - 1, got {show(seed)}")
    a.model, a.ablate, a.seed = model, list(dict.fromkeys(ablate)), seed


def adopt_run(a) -> None:
    """--resume: the run's own settings from DIR/run.json (written when it started), so that --resume --out DIR
    alone continues it. A flag given must agree with them: one that contradicts one is refused, naming the stored
    value. A run from before run.json: the flags as given (the checkpoint's check refuses a mismatch, saying the
    directory holds no run.json)."""

    from train.common.config import show

    path = a.out / RUN_NAME
    if path.is_symlink() or not path.is_file():
        run_level(a)   # a run from before run.json: the flags as given
        return
    try:
        from sim.input_files import InputFileError, read_json   # bounded, strict (duplicate keys, nesting)
        run = read_json(path, "the file", 4_000_000)   # the objects (at most 1 MB as a file) and the overrides
        stored, overrides = {k: run[k] for k in ("orders", "physics")}, run["overrides"]
        if not isinstance(overrides, dict) or not isinstance(run["objects"], dict):
            raise TypeError
    except (OSError, ValueError, KeyError, TypeError) as e:
        why = str(e) if isinstance(e, InputFileError) else type(e).__name__
        raise UsageError(f"--resume: {path} is damaged ({why}); nothing was changed") from None
    for flag, key in (("--orders", "orders"), ("--physics", "physics")):
        given = getattr(a, key)
        if given is not None and given != stored[key]:
            raise UsageError(f"--resume: {flag} {given} contradicts the run's {key} {stored[key]}")
        setattr(a, key, stored[key])
    for key, value in a.overrides.items():
        if key in overrides and overrides[key] != value:
            origin = a.origins[key]
            said = origin if origin.startswith("--set") else (f"{origin} {' '.join(value)}" if key == "ablate" and
                                                               origin == "--ablate" else
                                                               f"{origin} {value}" if origin.startswith("--") and
                                                               not origin.startswith("--config") else
                                                               f"{origin}: {key} = {show(value)}")
            raise UsageError(f"--resume: {said} contradicts the run's {key} {show(overrides[key])}")
    merged = {**overrides, **a.overrides}
    a.origins = {**{k: f"the run's {k} ({path})" for k in overrides}, **a.origins}
    a.overrides = merged
    run_level(a)
    a.stored_objects = run["objects"]


def run_settings(args, objects) -> dict:
    """What DIR/run.json holds: the run's settings as --resume adopts them."""
    return {"objects": objects.canonical(), "orders": args.orders, "physics": args.physics,
            "overrides": {**args.overrides, "model": args.model, "ablate": args.ablate, "seed": args.seed}}


def load_objects_or_fail(path: Path):
    from sim.objects import ObjectsFileError, load_objects
    try:
        return load_objects(path)
    except ObjectsFileError as e:
        raise UsageError(f"{path}: {e}") from None


def load_run_objects(args):
    """The run's objects: --objects (checked against a resumed run's), else the resumed run's, else the default."""
    from sim.objects import ObjectsFileError, parse_objects

    stored = getattr(args, "stored_objects", None)
    if stored is None:
        return load_objects_or_fail(args.objects or DEFAULT_OBJECTS)
    if args.objects is None:
        try:
            return parse_objects(stored)
        except ObjectsFileError as e:
            raise UsageError(f"--resume: the run's objects in {args.out / RUN_NAME}: {e}") from None
    objects = load_objects_or_fail(args.objects)
    if objects.canonical() != stored:
        raise UsageError(f"--resume: --objects {args.objects} contradicts the run's objects (in "
                         f"{args.out / RUN_NAME})")
    return objects


def count_orders(n_objects: int, orders: str) -> int:
    """How many orders the flag asks for, refused beyond MAX_ORDERS (before any is drawn)."""
    if orders == "listed":
        return 1
    if orders == "all":
        count = 1
        for k in range(2, n_objects + 1):
            count *= k
            if count > MAX_ORDERS:
                raise UsageError(f"--orders all: {n_objects} train objects have {n_objects}! orders, more than "
                                 f"{MAX_ORDERS:,} (at most 9 objects); use --orders N to draw N of them")
        return count
    return int(orders)


def resolve_config(args, objects):
    """The run's config (train.common.config.RunConfig: agent and world) from args.overrides, checked against the
    dataclasses and against the objects (a world its workers could not build). Imports torch and the simulator.
    UsageError naming where the refused key came from."""
    from train.common.config import ConfigError, resolve
    from train.runner.config_checks import check_run

    try:
        config = resolve(args.overrides)
        check_run(config, objects, args.overrides)   # what the workers build; settings that cannot work together
    except ConfigError as e:
        raise UsageError(f"{origin(args.origins, e.key)}{e}") from None
    return config


def origin(origins: dict, key: str | None) -> str:
    """"--set k=v: " for the key's last setting (or the last one under a table it names), else ""."""
    if key is None:
        return ""
    hits = [k for k in origins if k == key or k.startswith(key + ".") or key.startswith(k + ".")]
    return f"{origins[hits[-1]]}: " if hits else ""


def world_kw(args) -> dict:
    """Physics' `world` argument: the config's world when it is not the default one (the default needs none, and
    the stand-ins of Physics in tests/test_checkpoint.py take none)."""
    from sim.world import WorldConfig
    from train.common.config import config_dict

    world = args.run_config.world
    return {} if config_dict(world) == config_dict(WorldConfig()) else {"world": world}


def agent_keys_set(args) -> bool:
    """Whether the config sets an agent key beyond the run-level model, ablate and seed."""
    return any(k not in ("model", "ablate", "seed") and not k.startswith("world.") and k != "world"
               for k in args.overrides)


def check_same_config(args, objects, stored_agent: dict) -> None:
    """Refuse to resume with another config, naming the first key that differs: the agent's against the
    checkpoint's (as the experiment ran it), the world's against DIR/config.json (none: a run from before it was
    written, which built the default world)."""

    from aesop_torch.agent import AgentConfig
    from sim.world import WorldConfig
    from train.common.config import config_dict, first_difference, flatten, show

    def refuse(key, here, there):
        raise UsageError(f"--resume: the config's {key} differs from the interrupted run in {args.out} "
                         f"({show(flatten(here).get(key))} here, {show(flatten(there).get(key))} there)")

    here = config_dict(as_run(args.run_config.agent, len(objects.train), args.seed))
    there = config_dict(AgentConfig.from_dict(stored_agent))   # fields added since it was written: their defaults
    if key := first_difference(here, there):
        refuse(key, here, there)
    saved = args.out / CONFIG_NAME
    if saved.is_file():
        try:
            from sim.input_files import InputFileError, read_json   # bounded, strict (duplicate keys, nesting)
            there = read_json(saved, "the file", 1_000_000)["world"]
            if not isinstance(there, dict):
                raise TypeError
        except (OSError, ValueError, KeyError, TypeError) as e:
            why = str(e) if isinstance(e, InputFileError) else type(e).__name__
            raise UsageError(f"--resume: {saved} is damaged ({why}); nothing was changed") from None
    else:
        there = config_dict(WorldConfig())
    here = {"world": config_dict(args.run_config.world)}
    if key := first_difference(here, {"world": there}):
        refuse(key, here, {"world": there})


def check_same_run(args, objects, stored_run: dict) -> None:
    """Refuse to resume a checkpoint whose run (objects, seed, physics, --orders, model, ablate) is not the one
    given. With DIR/run.json the settings were adopted from it, so a difference means a damaged directory; without
    it (a run from before run.json, or one removed) the flags given are the run's only account of itself: say so,
    with the checkpoint's value."""
    wanted = {"objects": objects.canonical(), "seed": args.seed, "physics": args.physics,
              "orders_arg": args.orders, "model": args.model, "ablate": args.ablate}
    for key, value in wanted.items():
        if stored_run[key] == value:
            continue
        if not (args.out / RUN_NAME).is_file():
            v = stored_run[key]
            flag = {"orders_arg": "--orders", "seed": "--seed", "physics": "--physics", "model": "--model"}
            ran = ("other objects (give them with --objects)" if key == "objects" else
                   f"{flag[key]} {v}" if key in flag else
                   " ".join(f"--ablate {p}" for p in v) or "no --ablate" if key == "ablate" else f"{key} {v}")
            raise UsageError(f"--resume: {args.out} holds no {RUN_NAME} (the run's settings), so the run's own flags "
                             f"must be given again: its checkpoint ran {ran}")
        raise UsageError(f"--resume: {key} differs from the interrupted run in {args.out}")


def as_run(agent, n_train: int, seed: int):
    """A copy of an AgentConfig as train.learning.experiment.Experiment runs it (its __post_init__): the run's seed, the
    memory and the hub sized to the train objects."""
    agent = copy.deepcopy(agent)
    agent.seed = seed
    agent.memory.max_episodes = min(agent.memory.max_episodes, n_train)
    agent.hub.max_assemblies = min(agent.hub.max_assemblies, n_train)
    return agent
