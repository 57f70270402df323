"""The experiment runner: cumulative causal learning in the pybullet world, with checkpoints and tensorboard.

    python train/run.py [--objects FILE] [--orders N|listed|all] [--seed S] [--out DIR] [--resume]
                        [--config FILE.toml] [--set KEY=VALUE ...]
                        [--model paper|extended] [--ablate rules|gating|prior ...]
                        [--physics cached|per-episode] [--frames] [--gui]

The model's and the world's config (train/config.py): the defaults, then the --config file, then each --set in
order, then --model, --ablate and --seed (shorthands for the keys model, ablate and seed): a later value wins, so a
flag wins over the file.

Writes into DIR: tensorboard runs (tb/order_<i>/), checkpoints/latest.pt (after every episode, atomic, checksummed),
config.json (the run's config, at the start), figure2.png, frames/ (with --frames) and summary.json (CONTRACTS.md).
DIR belongs to one run at a time (a lock on DIR/.lock). Bad input: one line on stderr, exit code 2, nothing written.
Ctrl-C: one line, exit code 130; SIGTERM, SIGHUP: the same, exit code 143, 129 (128 + the signal's number); a full
disk or another write error, or a worker process that died: one line, exit code 1; either way the last checkpoint is
intact and --resume continues. A closed stdout (`>&-`): the run goes on without console output.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import errno
import os
import re
import signal
import stat
import sys
import threading
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the project importable without installing it
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# Only light imports up here: torch takes about a second to import, and the first line must come before it.
ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OBJECTS = ROOT / "sim" / "default_objects.json"
DEFAULT_ORDERS = "4"     # the paper's Figure 2: four random orders of the eight objects
DEFAULT_OUT = "runs/run-<date-time>"
FULL_TB_ORDERS = 16      # tensorboard run directories beyond this would drown a person; see README
MAX_ORDERS = 1_000_000   # orders of one run; beyond this the orders alone fill gigabytes (8 ints each, as lists)
MAX_SEED = 2 ** 63       # torch.Generator.manual_seed takes a 64-bit integer; stored as int64 in tensors
LOCK_NAME = ".lock"
CONFIG_NAME = "config.json"   # the run's config, written when it starts (summary.json's `config`)
RUN_NAME = "run.json"         # the run's settings as given (objects, orders, physics, overrides): what --resume reads
MODELS = ("paper", "contextual", "extended")                          # aesop_torch.agent.MODELS, without torch
ABLATIONS = {"paper": ("rules", "gating"), "contextual": ("rules", "gating", "context", "fit"),
             "extended": ("rules", "gating", "prior")}                   # and .ABLATIONS
ORDERS_RE = re.compile(r"[1-9][0-9]{0,6}|listed|all", re.ASCII)
SEED_RE = re.compile(r"[0-9]{1,19}", re.ASCII)


class UsageError(Exception):
    """Bad input: reported as one line and exit code 2."""


class Ended(KeyboardInterrupt):
    """SIGTERM or SIGHUP (a `kill`, `timeout`, a closed terminal): the run ends as on Ctrl-C, a KeyboardInterrupt to
    every handler of one, with exit code 128 + the signal's number."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


ENDING = (signal.SIGTERM, signal.SIGHUP)   # the signals that end a run as Ctrl-C does
_RUNNER = {"pid": None}   # the process whose handlers raise Ended (a forked child inherits them: see _ended)


def _ended(signum, frame):
    if os.getpid() != _RUNNER["pid"]:   # a worker forked before it reset its handlers: the default, silently
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    raise Ended(signum)


def _how(e: KeyboardInterrupt) -> tuple[str, int]:
    """(" by SIGTERM" or "", exit code) of an interruption: Ctrl-C 130, a signal 128 + its number."""
    signum = getattr(e, "signum", signal.SIGINT)
    return ("" if signum == signal.SIGINT else f" by {signal.Signals(signum).name}"), 128 + signum


@contextlib.contextmanager
def _ending_signals():
    """SIGTERM and SIGHUP raise Ended while main() runs (only the main thread may set handlers; one ignored, as
    under nohup, stays ignored); the previous handlers afterwards, so a signal after main() ends silently."""
    main = threading.current_thread() is threading.main_thread()
    previous = {sig: signal.getsignal(sig) for sig in ENDING} if main else {}
    try:
        for sig, handler in previous.items():
            if handler is not signal.SIG_IGN:
                _RUNNER["pid"] = os.getpid()
                signal.signal(sig, _ended)
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _console() -> None:
    """A closed stdout or stderr (`>&-`): /dev/null in its place. The run goes on without console output (its
    results are files; an error still sets the exit code), and no file the run opens can take fd 1 or 2, where
    pybullet's C output (sim/quiet.py) would write into it."""
    for fd, name in ((1, "stdout"), (2, "stderr")):
        try:
            os.fstat(fd)
            continue
        except OSError:
            pass
        null = os.open(os.devnull, os.O_WRONLY)
        if null != fd:
            os.dup2(null, fd)
            os.close(null)
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, "w", closefd=False))


class Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints usage + message; we promise one clear line
        raise UsageError(message)


class Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows defaults, except the None / False / [] of options whose help says what they default to."""

    def _get_help_string(self, action):
        none = action.default is None or action.default is False or action.default == []
        return action.help if none else super()._get_help_string(action)


def orders_arg(text: str) -> str:
    if not ORDERS_RE.fullmatch(text) or (text.isdigit() and int(text) > MAX_ORDERS):
        raise argparse.ArgumentTypeError(f"must be a number from 1 to {MAX_ORDERS:,} (ASCII digits), 'listed' or "
                                         f"'all', not {_shown(text)}")
    return text


def seed_arg(text: str) -> int:
    if not SEED_RE.fullmatch(text) or int(text) >= MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be an integer from 0 to 2**63 - 1 (ASCII digits), not {_shown(text)}")
    return int(text)


def _shown(text: str, cut: int = 40) -> str:
    return repr(text if len(text) <= cut else text[:cut] + "...")


CONFIG_HELP = """The config: every field of the agent's (aesop_torch.agent.AgentConfig: top-level keys such as
recall_sharpness, model, ablate, seed, and its parts encoder., hub., memory., rules.) and of the world's
(sim.world.WorldConfig under world.: world.mass_noise_g, world.tank..., world.tank.water..., world.robot...,
world.ik..., world.camera...). Applied in this order, a later value of a key replacing an earlier one: the
defaults, the --config file, each --set in the order given, then --model, --ablate and --seed (shorthands for the
keys model, ablate and seed): when the file and a flag both give a value, the flag wins. An unknown key, a value of
the wrong type or out of range: one line, exit 2, nothing written. CONTRACTS.md has the details."""


def parse_args(argv):
    ap = Parser(prog="train/run.py", description=__doc__.split("\n")[0], formatter_class=Formatter,
                epilog=CONFIG_HELP)
    ap.add_argument("--objects", type=Path, default=None, metavar="FILE",
                    help="objects file: JSON, schema in CONTRACTS.md (default: sim/default_objects.json)")
    ap.add_argument("--orders", type=orders_arg, default=None, metavar="N|listed|all",
                    help=f"N random orders of the train objects (N <= {MAX_ORDERS:,}), 'listed' (the file's order) "
                         f"or 'all' (every permutation: at most {MAX_ORDERS:,} orders, i.e. 9 objects) (default: "
                         f"{DEFAULT_ORDERS})")
    ap.add_argument("--seed", type=seed_arg, default=None, metavar="S",
                    help="seed of the random orders, of the maps' developmental training and of the sensor noise: "
                         "same seed, same run (default: 0, or the config's seed)")
    ap.add_argument("--out", type=Path, default=None, metavar="DIR", help=f"output directory (default: {DEFAULT_OUT})")
    ap.add_argument("--resume", action="store_true",
                    help="continue the interrupted run in --out with its own settings (a flag given must agree)")
    ap.add_argument("--config", type=Path, default=None, metavar="FILE.toml",
                    help="the model's and the world's config as a TOML file: top-level keys are AgentConfig fields, "
                         "tables its parts ([rules], [memory], ...) and the world's ([world], [world.tank], ...)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="sets",
                    help="set one config key (repeatable, applied after --config, in order), e.g. "
                         "rules.uncertain_decay=1.0, memory.max_recalls=none, model=extended, world.mass_noise_g=5, "
                         "'ablate=[\"rules\"]': the value is read as TOML, a bare word as a string, none as None")
    ap.add_argument("--model", choices=MODELS, default=None,
                    help="paper: the paper's mechanism (incremental rules, knowledge-gated recall, a weighted average "
                         "of recalled rewards); extended: evidence-set rules with contexts and a readout fitted with "
                         "the task's physics priors (default: paper, or the config's model)")
    ap.add_argument("--ablate", action="append", default=None, metavar="PART",
                    help="switch a part off (repeatable; replaces the config's ablate): rules (no rule fires), gating "
                         "(the memory's cue ignores the strengths), prior (extended only: the readout without its "
                         "physics priors)")
    ap.add_argument("--physics", choices=("cached", "per-episode"), default=None,
                    help="simulate each distinct object once (cached) or every episode of every order (default: "
                         "cached)")
    ap.add_argument("--frames", action="store_true", help="save camera frames of each simulated drop")
    ap.add_argument("--gui", action="store_true", help="pybullet GUI (needs a display)")
    a = ap.parse_args(argv)
    if a.gui:
        from sim.world import gui_unavailable
        if why := gui_unavailable():
            raise UsageError(f"--gui: {why}")
    gather_config(a)
    if a.resume and a.out is None:
        raise UsageError("--resume needs --out DIR (the run to continue)")
    a.stored_objects = None
    if a.resume:
        adopt_run(a)
    a.orders = a.orders or DEFAULT_ORDERS
    a.physics = a.physics or "cached"
    if a.out is None:
        a.out = Path("runs") / time.strftime("run-%Y%m%d-%H%M%S")
    if a.objects is None and a.stored_objects is None:
        a.objects = DEFAULT_OBJECTS
    return a


def gather_config(a) -> None:
    """The config's overrides in the order they apply (--config, each --set, then --model, --ablate, --seed) as
    a.overrides {dotted key: value}, where each came from as a.origins {key: "--set k=v" | "--config FILE" | flag},
    and the run-level keys resolved into a.model, a.ablate, a.seed. Torch-free: the syntax, the file and these three
    keys are checked here, before the first line; every other key against the dataclasses after it
    (resolve_config)."""
    from train.config import ConfigError, load_toml, parse_set, show

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
            raise UsageError(f"--set {_shown(text, 100)[1:-1]}: {e}") from None
        put(key, value, f"--set {_shown(text, 100)[1:-1]}")
    if a.model is not None:
        put("model", a.model, "--model")
    if a.ablate is not None:
        put("ablate", list(dict.fromkeys(a.ablate)), "--ablate")
    if a.seed is not None:
        put("seed", a.seed, "--seed")
    a.overrides, a.origins = overrides, origins
    _run_level(a)


def _run_level(a) -> None:
    """a.model, a.ablate, a.seed from a.overrides, checked (torch-free)."""
    from train.config import show

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
    value. A run from before run.json: the flags as given (the checkpoint's check refuses a mismatch)."""
    from train.config import show

    path = a.out / RUN_NAME
    if path.is_symlink() or not path.is_file():
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
    _run_level(a)
    a.stored_objects = run["objects"]


def run_settings(args, objects) -> dict:
    """What DIR/run.json holds: the run's settings as --resume adopts them."""
    return {"objects": objects.canonical(), "orders": args.orders, "physics": args.physics,
            "overrides": {**args.overrides, "model": args.model, "ablate": args.ablate, "seed": args.seed}}


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


def resolve_config(args, objects):
    """The run's config (train.config.RunConfig: agent and world) from args.overrides, checked against the
    dataclasses and against the objects (a world its workers could not build). Imports torch and the simulator:
    after the first line. UsageError naming where the refused key came from."""
    from train.config import ConfigError, resolve
    from train.config_checks import check_run

    try:
        config = resolve(args.overrides)
        check_run(config, objects, args.overrides)   # what the workers build; settings that cannot work together
    except ConfigError as e:
        raise UsageError(f"{_origin(args.origins, e.key)}{e}") from None
    return config


def check_capacity(agent, n_train: int, setting=lambda key, value: f"--set {key}={value}") -> str | None:
    """Why a run of n_train episodes cannot end with this AgentConfig, in one line, or None. A memory or hub whose
    when_full is `refuse` stops the run at its first episode past capacity, maybe hours in: refused before anything
    is written instead. The hub counts the train objects: probes are predicted on copies and the goal trials run on
    a copy with room for theirs (train/trials.py roomy_copy). setting(key, value) spells a fix (train/sweep.py's
    differs)."""
    full = []   # (part, its size's key, the size) of each part that would refuse
    for part, key in (("memory", "max_episodes"), ("hub", "max_assemblies")):
        c = getattr(agent, part)
        if c.when_full == "refuse" and n_train > getattr(c, key):
            full.append((part, key, getattr(c, key)))
    if not full:
        return None
    sizes = ", ".join(f"{part}.{key} = {size} and {part}.when_full = refuse" for part, key, size in full)
    forget = " ".join(setting(f"{part}.when_full", "forget_oldest") for part, _, _ in full)
    grow = " ".join(setting(f"{part}.{key}", n_train) for part, key, _ in full)
    return (f"{n_train} train objects but {sizes}: the run would stop at episode "
            f"{min(size for _, _, size in full) + 1}; {forget} (or forget_weakest), or {grow}")


def _origin(origins: dict, key: str | None) -> str:
    """"--set k=v: " for the key's last setting (or the last one under a table it names), else ""."""
    if key is None:
        return ""
    hits = [k for k in origins if k == key or k.startswith(key + ".") or key.startswith(k + ".")]
    return f"{origins[hits[-1]]}: " if hits else ""


def load_objects_or_fail(path: Path):
    from sim.objects import ObjectsFileError, load_objects
    try:
        return load_objects(path)
    except ObjectsFileError as e:
        raise UsageError(f"{path}: {e}") from None


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


def check_out(out: Path, resume: bool) -> None:
    """Refuse an --out that is not, or cannot become, a directory this run may write (nothing is created here)."""
    if out.is_symlink() and not out.exists():
        raise UsageError(f"--out {out} is a symbolic link to nothing ({os.readlink(out)})")
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} exists and is not a directory")
    if resume:
        if not out.is_dir():
            raise UsageError(f"--resume: no checkpoint at {out / 'checkpoints' / 'latest.pt'} ({out} does not exist)")
    else:
        p = out
        while not p.exists():
            if p.is_symlink():
                raise UsageError(f"--out {out}: {p} is a symbolic link to nothing")
            p = p.parent
        if not p.is_dir():
            raise UsageError(f"--out {out}: {p} is not a directory")
        if not os.access(p, os.W_OK | os.X_OK):
            raise UsageError(f"--out {out}: {p} is not writable")
        if p == out and _holds_a_run(out):
            busy = _lock_holder(out)
            raise UsageError(f"--out {out} is in use by another run (pid {busy})" if busy else
                             f"--out {out} already holds files; use --resume to continue it or another --out")
    if out.is_dir() and not os.access(out, os.W_OK | os.X_OK):
        raise UsageError(f"--out {out} is not writable")
    if resume and (link := _link_inside(out)):
        raise UsageError(f"--resume: {link} is a symbolic link; the run writes only inside --out {out}: remove it")


WRITTEN = ("tb", "checkpoints", "frames", CONFIG_NAME, RUN_NAME, "summary.json", "figure2.png")   # what a run writes


def _link_inside(out: Path) -> Path | None:
    """The first symbolic link among what the run writes in --out (a link would send its writes elsewhere)."""
    for name in WRITTEN:
        top = out / name
        if top.is_symlink():
            return top
        if top.is_dir():
            for root, dirs, files in os.walk(top):   # does not follow links
                for n in dirs + files:
                    if (Path(root) / n).is_symlink():
                        return Path(root) / n
    return None


def _leftover(out: Path, entry) -> bool:
    """What a run killed before its first checkpoint leaves: its config.json, run.json and checkpoint temp files."""
    if entry.name == LOCK_NAME:   # whatever it is, lock_out judges it
        return True
    if entry.name in (CONFIG_NAME, RUN_NAME) and entry.is_file(follow_symlinks=False):
        return True
    if entry.name == "checkpoints" and entry.is_dir(follow_symlinks=False):
        return all(re.fullmatch(r"latest\.pt\..+\.tmp", e.name) and e.is_file(follow_symlinks=False)
                   for e in os.scandir(entry.path))
    return False


def _holds_a_run(out: Path) -> bool:
    """Whether --out holds more than the lock and the leftovers of a run killed before its first checkpoint."""
    return not all(_leftover(out, e) for e in os.scandir(out))


def _remove_leftovers(out: Path) -> None:
    """A fresh run into the --out of one killed before its first checkpoint: its leftovers go (the lock stays)."""
    for e in list(os.scandir(out)):
        if e.name == "checkpoints":
            for f in os.scandir(e.path):
                os.unlink(f.path)
            os.rmdir(e.path)
        elif e.name != LOCK_NAME:
            os.unlink(e.path)


def _lock_holder(out: Path) -> str | None:
    """The pid written in DIR/.lock while a run holds it, else None. Only reads."""
    import fcntl

    try:
        fd = os.open(out / LOCK_NAME, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):   # not a lock of ours (a FIFO would block a read)
            return None
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return None
    except BlockingIOError:
        return os.read(fd, 32).decode(errors="replace").strip() or "unknown"
    finally:
        os.close(fd)   # closing drops the probe's shared lock, if it got one


def lock_out(out: Path) -> int:
    """Make --out this run's: an exclusive flock on DIR/.lock, held until the process ends (the kernel lets go
    even on SIGKILL). Refused (UsageError) while another run holds it."""
    import fcntl

    out.mkdir(parents=True, exist_ok=True)
    lock = out / LOCK_NAME
    # never through a link (it would write the pid into, or create, a file elsewhere) and never blocking (a FIFO)
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise UsageError(f"--out {out}: {lock} is a symbolic link, not a run's lock; remove it") from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise UsageError(f"--out {out}: {lock} is not a regular file, not a run's lock; remove it")
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 32).decode(errors="replace").strip()
        os.close(fd)
        raise UsageError(f"--out {out} is in use by another run" + (f" (pid {holder})" if holder else "")) from None
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    return fd


def prepare(args, objects, n_orders: int, physics=None):
    """Validate the rest (needs torch) and return (experiment, resumed, lock fd). Locks --out first, so that a
    checkpoint is read and verified only by the run that owns it; nothing else is written before everything is
    checked. physics (train.physics.Physics, optional): a new run forks its workers once everything is checked and
    before the experiment is built, so they build their worlds while the maps train (0.3 s off the wall time)."""
    import torch

    from aesop_torch.malloc import keep_freed_memory
    from train.experiment import Experiment, draw_orders
    from train.summary import FULL_RUNS

    keep_freed_memory()   # freed tensors are reused rather than faulted in again (aesop_torch/malloc.py)

    # small tensors (at most 64 agents in detail) run faster on one thread than on two fighting each other, and so
    # does building the experiment (its maps' training took 6.9 s on 2 threads of a busy machine, 0.3 s on 1); a
    # population of many orders sets its own (train/population.py)
    torch.set_num_threads(1)
    if n_orders > FULL_RUNS and args.physics == "per-episode":
        raise UsageError(f"--physics per-episode with {n_orders} orders would simulate "
                         f"{n_orders * len(objects.train)} drops; more than {FULL_RUNS} orders run as a population "
                         "on cached physics")
    created = [d for d in [args.out, *args.out.parents] if not d.exists()]   # innermost first
    lock = lock_out(args.out)
    try:
        if args.resume:
            return resume_experiment(args, objects), True, lock
        if _holds_a_run(args.out):   # filled since check_out: another run's
            raise UsageError(f"--out {args.out} already holds files; use --resume to continue it or another --out")
        _remove_leftovers(args.out)
        # more than FULL_RUNS orders: the first FULL_RUNS run in detail here, every order as a population at the end
        orders = draw_orders(len(objects.train), args.orders, args.seed)[:FULL_RUNS]
        if physics is not None:
            physics.start()
        # a copy: the experiment sizes its agents' buffers to the train objects in its config (train.experiment)
        config = copy.deepcopy(args.run_config.agent)
        try:
            return Experiment([o.name for o in objects.train], [o.name for o in objects.probe], orders,
                              seed=args.seed, physics=args.physics, config=config), False, lock
        except (ValueError, TypeError, IndexError, RuntimeError, OverflowError) as e:
            if not _agent_keys_set(args):
                raise   # the defaults must build: a bug, with its traceback
            lines = str(e).strip().splitlines()
            raise UsageError(f"the agents cannot be built with this config ({type(e).__name__}: "
                             f"{lines[0] if lines else ''})") from None
    except BaseException:
        os.close(lock)
        if created:   # refused or interrupted after all: leave nothing behind (rmdir: only if still empty)
            (args.out / LOCK_NAME).unlink(missing_ok=True)
            for d in created:
                with contextlib.suppress(OSError):
                    d.rmdir()
        raise


def write_config(config: dict, path: Path) -> None:
    """config.json, atomically (train.checkpoint's writer: a temporary file beside it, fsynced, renamed over it)."""
    import json

    from train.checkpoint import write_text_atomic
    write_text_atomic(json.dumps(config, indent=1) + "\n", path)


def world_kw(args) -> dict:
    """Physics' `world` argument: the config's world when it is not the default one (the default needs none, and
    the stand-ins of Physics in tests/test_checkpoint.py take none)."""
    from sim.world import WorldConfig
    from train.config import config_dict

    world = args.run_config.world
    return {} if config_dict(world) == config_dict(WorldConfig()) else {"world": world}


def _agent_keys_set(args) -> bool:
    """Whether the config sets an agent key beyond the run-level model, ablate and seed."""
    return any(k not in ("model", "ablate", "seed") and not k.startswith("world.") and k != "world"
               for k in args.overrides)


def resume_experiment(args, objects):
    from train.checkpoint import CheckpointError, load
    from train.experiment import Experiment

    ckpt_path = args.out / "checkpoints" / "latest.pt"
    if not ckpt_path.is_file():
        raise UsageError(f"--resume: no checkpoint at {ckpt_path}")
    try:
        state = load(ckpt_path)
    except CheckpointError as e:
        raise UsageError(f"--resume: {e}; nothing was changed") from None
    wanted = {"objects": objects.canonical(), "seed": args.seed, "physics": args.physics, "orders_arg": args.orders,
              "model": args.model, "ablate": args.ablate}
    for key, value in wanted.items():
        if state["run"][key] != value:
            raise UsageError(f"--resume: {key} differs from the interrupted run in {args.out}")
    check_same_config(args, objects, state["experiment"]["config"])
    return Experiment.from_state_dict(state["experiment"])


def check_same_config(args, objects, stored_agent: dict) -> None:
    """Refuse to resume with another config, naming the first key that differs: the agent's against the
    checkpoint's (as the experiment ran it), the world's against DIR/config.json (none: a run from before it was
    written, which built the default world)."""
    from aesop_torch.agent import AgentConfig
    from sim.world import WorldConfig
    from train.config import config_dict, first_difference, flatten, show

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


def as_run(agent, n_train: int, seed: int):
    """A copy of an AgentConfig as train.experiment.Experiment runs it (its __post_init__): the run's seed, the
    memory and the hub sized to the train objects."""
    agent = copy.deepcopy(agent)
    agent.seed = seed
    agent.memory.max_episodes = min(agent.memory.max_episodes, n_train)
    agent.hub.max_assemblies = min(agent.hub.max_assemblies, n_train)
    return agent


def main(argv=None) -> int:
    _console()
    with _ending_signals():
        return _main(argv)


def _main(argv=None) -> int:
    try:
        try:
            args = parse_args(sys.argv[1:] if argv is None else argv)
            if args.objects is not None and _is_task_file(args.objects):
                return run_task(args)
            objects = load_run_objects(args)
            n_orders = count_orders(len(objects.train), args.orders)
            check_out(args.out, args.resume)
            # the first line: everything checkable without torch is checked; torch's import takes the next second
            print(f"train/run.py: {'resuming' if args.resume else 'starting'} {n_orders:,} order(s) of "
                  f"{len(objects.train)} object(s), physics {args.physics}, seed {args.seed} -> {args.out}",
                  flush=True)
            from train.drawing import Drawer
            from train.physics import Physics
            _OPEN["drawer"] = Drawer()   # before torch's import: it imports the figure's modules on the idle core
            args.run_config = resolve_config(args, objects)   # imports torch and the simulator, checks every key
            if why := check_capacity(args.run_config.agent, len(objects.train)):
                raise UsageError(why)
            physics = _OPEN["physics"] = Physics(objects, seed=args.seed, gui=args.gui,
                                                 **world_kw(args))   # forked in prepare
            exp, resumed, lock = prepare(args, objects, n_orders, physics)
        except UsageError as e:
            _close_quietly()
            print(f"train/run.py: error: {e}", file=sys.stderr)
            return 2
        except OSError as e:   # creating --out or its lock failed (a full disk, a race with another program)
            _close_quietly()
            print(f"train/run.py: error: {_os_error(e)}", file=sys.stderr)
            return 1
        try:
            return run(args, exp, objects, resumed)
        finally:
            os.close(lock)   # the kernel would at exit; a caller of main() in-process may start another run
    except KeyboardInterrupt as e:   # before the run started: nothing of value was written
        by, code = _how(e)
        with _sigint_ignored():
            _close_quietly()
            print(f"{_fresh_line()}train/run.py: interrupted{by} before the run started", file=sys.stderr)
        return code


def _is_task_file(path: Path) -> bool:
    from train.task_run import is_task_file
    return is_task_file(path)


def run_task(args) -> int:
    """--objects is a task file of the Aesop battery (sim/tasks/): --orders N agents of --seed explore and play it in
    the apparatus built in pybullet (train/task_run.py). It has no checkpoints: an interrupted task run starts again."""
    given = [flag for flag, on in (("--resume", args.resume), ("--config/--set", args.overrides.keys() -
                                                                     {"model", "ablate", "seed"}),
                                   ("--gui", args.gui), ("--physics per-episode", args.physics != "cached")) if on]
    if given:
        raise UsageError(f"{args.objects} is a task file: {given[0]} does not apply to a task run (it takes --orders "
                         f"N agents, --seed, --model, --ablate, --frames and --out)")
    if not args.orders.isdigit():
        raise UsageError(f"{args.objects} is a task file: --orders takes a number of agents, not {args.orders!r}")
    from sim.apparatus import TaskFileError, load_task
    try:
        task = load_task(args.objects)
    except TaskFileError as e:
        raise UsageError(f"{args.objects}: {e}") from None
    check_out(args.out, False)
    print(f"train/run.py: task {task.name}: {args.orders} agent(s) of model {args.model}, seed {args.seed}, "
          f"physics in pybullet -> {args.out}", flush=True)
    lock = lock_out(args.out)
    try:
        from train.task_run import run_task_file
        try:
            run_task_file(task, args.out, args.model, args.seed, int(args.orders), tuple(args.ablate), args.frames)
        except OSError as e:
            print(f"{_fresh_line()}train/run.py: error: {_os_error(e)}", file=sys.stderr)
            return 1
        except KeyboardInterrupt as e:
            by, code = _how(e)
            print(f"{_fresh_line()}train/run.py: interrupted{by}; a task run keeps no checkpoint: run it again "
                  f"(with another --out, or remove {args.out})", file=sys.stderr)
            return code
        print(f"train/run.py: wrote {args.out}/summary.json, tb/" + (", frames/" if args.frames else ""))
        return 0
    finally:
        os.close(lock)


@contextlib.contextmanager
def _sigint_ignored():
    """A second Ctrl-C (or SIGTERM, SIGHUP) must not interrupt the clean-up after the first (only the main thread may
    set handlers)."""
    main = threading.current_thread() is threading.main_thread()
    previous = {sig: signal.signal(sig, signal.SIG_IGN) for sig in (signal.SIGINT, *ENDING)} if main else {}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _fresh_line() -> str:
    """A newline on a terminal, where a progress bar (or ^C) may have left the cursor mid-line; nothing in a log."""
    return "\n" if sys.stdout.isatty() else ""


def _os_error(e: OSError) -> str:
    where = f" {e.filename}" if e.filename else ""
    return f"cannot write{where}: {e.strerror or e}"


def run(args, exp, objects, resumed: bool) -> int:
    out, t0 = args.out, time.time()
    ckpt = out / "checkpoints" / "latest.pt"
    saved = {"t": exp.t if resumed else None}   # episodes in the last checkpoint written (None: none yet)

    def last_checkpoint() -> str:
        if saved["t"] is None:
            return "no checkpoint was written yet: run the same command again (with another --out, or remove it)"
        return (f"the last checkpoint ({ckpt}, {saved['t']} of {exp.n_episodes} episodes) is intact: "
                f"continue with the same flags and --resume --out {out}")

    from train.physics import WorkerDied, WorldBuildError

    try:
        return _run(args, exp, objects, resumed, out, ckpt, saved, t0)
    except WorkerDied as e:   # killed (by a person, the OOM killer): its job would never be answered
        with _sigint_ignored():
            _close_quietly()
            print(f"{_fresh_line()}train/run.py: error: {e}; {last_checkpoint()}", file=sys.stderr)
        return 1
    except WorldBuildError as e:   # a world config the scene does not admit, found by the workers building it
        with _sigint_ignored():
            _close_quietly()
            print(f"{_fresh_line()}train/run.py: error: {e} (check the config's world keys); {last_checkpoint()}",
                  file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        by, code = _how(e)
        with _sigint_ignored():
            _close_quietly()
            print(f"{_fresh_line()}train/run.py: interrupted{by}; {last_checkpoint()}", file=sys.stderr)
        return code
    except OSError as e:   # a full disk (ENOSPC) or another write error: the checkpoint is written atomically
        with _sigint_ignored():
            _close_quietly()
            print(f"{_fresh_line()}train/run.py: error: {_os_error(e)}; {last_checkpoint()}", file=sys.stderr)
        return 1
    finally:
        _close_quietly()


_OPEN: dict = {"physics": None, "drawer": None, "logs": []}   # what the run has open, closed whatever way it ends


def _close_quietly() -> None:
    physics, drawer, logs = _OPEN["physics"], _OPEN["drawer"], _OPEN["logs"]
    _OPEN["physics"], _OPEN["drawer"], _OPEN["logs"] = None, None, []
    for pool in (physics, drawer):
        try:
            if pool is not None:
                pool.close()
        except Exception:  # noqa: BLE001  the run is ending; its one line has been said
            pass
    for log in logs:
        try:
            log.close()
        except Exception:  # noqa: BLE001
            pass


def _run(args, exp, objects, resumed, out, ckpt, saved, t0) -> int:
    import json

    import torch

    from sim.objects import archimedes_cm3
    from train.checkpoint import save_atomic, write_text_atomic
    from train.experiment import draw_orders, outcome_record, plain_measurement, senses_floor
    from train.drawing import Drawer
    from train.physics import Physics, WorkerDied
    from train.progress import Step
    from train.summary import build_summary, knowledge_table
    from train.config import RunConfig, config_dict
    run_meta = {"objects": objects.canonical(), "seed": args.seed, "physics": args.physics,
                "orders_arg": args.orders, "model": args.model, "ablate": args.ablate}
    # the whole config as the run uses it: the agents' as the experiment holds it (seed, buffers sized), the world's
    config = config_dict(RunConfig(exp.config, args.run_config.world))

    def checkpoint():
        save_atomic({"run": run_meta, "experiment": exp.state_dict()}, ckpt)
        saved["t"] = exp.t

    if not resumed:
        write_config(config, out / CONFIG_NAME)   # what --resume compares; before the first checkpoint
        write_text_atomic(json.dumps(run_settings(args, objects), indent=1) + "\n", out / RUN_NAME)
        checkpoint()  # from here on the run can be resumed, even if it is killed during the first simulations
    physics = _OPEN["physics"] or Physics(objects, seed=args.seed, gui=args.gui, **world_kw(args))   # main() made it
    _OPEN["physics"] = physics
    specs = {o.name: o for o in objects.train + objects.probe}
    # probes are inspected once; with cached physics every distinct train object is dropped once, all up front. A
    # probe that waits on a trial's stand is measured by a drop instead: the same look, take, lift and weigh as an
    # inspection, so the same measurement bit for bit (tests/test_world.py), and a trial's first drop of it (the
    # agent learns nothing from it here)
    todo = [n for n in dict.fromkeys(exp.train_names) if n not in exp.outcomes] if exp.physics == "cached" else []
    probes = [n for n in exp.probe_names if n not in exp.probes]
    on_stands = {n for stand in objects.trials for n in stand}
    jobs = [("drop", n, args.frames) for n in todo] + [("drop" if n in on_stands else "inspect", n, None)
                                                        for n in probes]
    probe_drops = {}
    submitted = physics.submit(jobs)   # the workers start on them while the logs open
    from train.tensorboard_log import OrderLog, trial_line   # tensorboard's import (0.2 s) too
    from train.trials import planner_sequences
    logs = _OPEN["logs"] = [OrderLog(out / "tb" / f"order_{b + 1:02d}", purge_step=(exp.t + 1) if resumed else None)
                            for b in range(min(len(exp.orders), FULL_TB_ORDERS))]
    if not resumed:
        hp = {"seed": args.seed, "physics": args.physics, "orders": args.orders,
              "objects": str(args.objects), **_flat("agent", exp.config.to_dict())}
        for b, log in enumerate(logs):
            log.hparams({**hp, "order": " ".join(exp.train_names[i] for i in exp.orders[b])},
                        {"prediction/probe_rel_error": float("nan")})

    def keep(outcome, tag: str) -> dict:
        if args.frames and outcome.frames:
            from sim.episode import save_frames_png
            with Step(f"frames of {tag}", len(outcome.frames), "frame", announce=False) as bar:
                save_frames_png(outcome.frames, out / "frames" / tag)
                for i, frame in enumerate(outcome.frames):  # a slider per drop in tensorboard's Images tab
                    logs[0].image(f"frames/{tag}", frame, i)
                    bar.update()
        return outcome_record(outcome)

    if jobs:
        with Step(f"simulating {len(todo)} drop(s) and {len(probes)} probe measurement(s) on {physics.workers} "
                  f"process(es)", len(jobs), "simulation") as bar:
            results = physics.run(jobs, progress=lambda job: bar.update(1, job[1]), submitted=submitted)
        for name, outcome in zip(todo, results):
            exp.outcomes[name] = keep(outcome, name)
        for name, m in zip(probes, results[len(todo):]):
            if name in on_stands:
                probe_drops[name], m = outcome_record(m), m.measurement
            exp.probes[name] = {"measurement": plain_measurement(m),
                                "archimedes_cm3": float(archimedes_cm3(specs[name], objects.jar))}
        checkpoint()
    # the goal trials' multi-drop sequences a planner would drop, simulated while the workers would idle (the
    # agents learn here, Figure 2 and the trials follow): a well-taught agent drops them; others are simulated then
    ahead = {s: physics.ahead(("trial", s, None)) for s in planner_sequences(objects)[:physics.workers]} \
        if physics.workers > 1 else {}
    print(f"{'resuming' if resumed else 'running'}: {len(exp.orders)} order(s) x {exp.n_episodes} episodes, "
          f"physics {exp.physics}" + (" (each distinct object simulated once, its measured outcome reused by "
                                       "every order: the jar is reset between episodes)" if exp.physics == "cached"
                                       else ""), flush=True)
    per_episode = exp.physics == "per-episode"
    units = len(exp.orders) if per_episode else 1     # per-episode physics: the bar counts drops
    with Step("episodes", (exp.n_episodes - exp.t) * units, "drop" if per_episode else "episode",
              announce=False) as bar:
        while not exp.done:
            t = exp.t
            if per_episode:
                names = [exp.train_names[o[t]] for o in exp.orders]
                drops = physics.drops(names, args.frames, progress=lambda job: bar.update(1, f"episode {t + 1}: "
                                                                                             f"{job[1]}"))
                fresh = [keep(o, f"order{b + 1:02d}_ep{t + 1:02d}_{n}") for b, (n, o) in enumerate(zip(names, drops))]
                recs = exp.step(lambda name, b, t: fresh[b])
            else:
                recs = exp.step(lambda name, b, t: exp.outcomes[name])
            for b, log in enumerate(logs):
                log.episode(t, recs[b])
            checkpoint()
            fired = " ".join(f"{p}:{r}" for p, r in recs[0]["rules"].items())
            bar.line(f"episode {exp.t}/{exp.n_episodes}: {recs[0]['object']} {fired}")
            if not per_episode:
                bar.update(1, recs[0]["object"])
    population = None
    orders = draw_orders(len(exp.train_names), args.orders, args.seed)
    if len(orders) > len(exp.orders):
        from train.population import run_population
        print(f"population: {len(orders)} orders side by side (the first {len(exp.orders)} also ran in detail)",
              flush=True)
        with Step("population", len(orders), "order") as bar:
            population = run_population(exp.train_names, exp.probe_names, orders, exp.outcomes, exp.probes,
                                        exp.config, progress=bar.to, curves=True)
    # Figure 2 shows the exploration (a population's error bands over all its orders): drawn and written by the
    # drawer while the goal trials run
    drawer = _OPEN["drawer"] = _OPEN["drawer"] or Drawer()   # main() started it
    figure = drawer.draw("train.figures:save_figure2", exp.records, out / "figure2.png", 110, senses_floor(exp.probes),
                         population and {k: population[k] for k in ("orders", "agree_fraction",
                                                                    "most_common_knowledge", "curves")})
    if objects.trials:
        from train.trials import play_trials
        print(f"goal trials: {len(objects.trials)} trial(s) with each of {len(exp.orders)} order(s)' agents, the jar "
              "not reset between the drops of a trial (each new sequence of drops simulated from a fresh jar)",
              flush=True)
        with Step("goal trials", None, "drop", announce=False) as bar:
            # a trial's first drop of an object is the drop that measured it here (a fresh jar, the same noise seed)
            exp.trials = play_trials(exp, objects, physics, first_drops={**exp.outcomes, **probe_drops},
                                     progress=lambda seq: bar.update(1, " > ".join(seq)), ahead=ahead)
        for i, r in enumerate(exp.trials[0]):
            print(trial_line(i, r), flush=True)
        for b, log in enumerate(logs):
            for i, r in enumerate(exp.trials[b]):
                log.trial(i, r)
    summary = build_summary(exp, population, config)
    try:
        image = figure.get()
    except WorkerDied as e:   # the drawer's pool names its process generically
        raise WorkerDied("the figure process", e.pid, e.exitcode) from None
    for log in logs:
        log.image("figure2", image, exp.n_episodes)
        log.close()
    _OPEN["logs"] = []
    _close_quietly()   # the workers and the drawer: every result is in
    write_text_atomic(json.dumps(summary, indent=1) + "\n", out / "summary.json")
    print(f"\nwrote {out}/: summary.json, config.json, figure2.png, tb/ (tensorboard --logdir {out / 'tb'}), "
          f"checkpoints/latest.pt" + (", frames/" if args.frames else "") + f"  [{time.time() - t0:.1f} s]")
    print(knowledge_table(summary))
    return 0


def _flat(prefix: str, d: dict) -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(f"{prefix}.{k}", v))
        else:
            out[f"{prefix}.{k}"] = v
    return out


if __name__ == "__main__":
    code = main()
    # everything is written, flushed and closed (checkpoints and summary.json fsynced and renamed, the logs closed,
    # the worker processes ended): spare the interpreter's teardown, a walk over torch's objects and modules that
    # took 0.25 s of the default run's wall time (0.03 s this way; the memory goes back to the system either way)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError):   # a reader that went away (| head) has what it wanted
            stream.flush()
    os._exit(code)
