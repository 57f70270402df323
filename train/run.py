"""The experiment runner: cumulative causal learning in the pybullet world, with checkpoints and tensorboard.

    python train/run.py [--objects FILE] [--orders N|listed|all] [--seed S] [--out DIR] [--resume]
                        [--config FILE.toml] [--set KEY=VALUE ...]
                        [--model paper|contextual|extended] [--ablate PART ...]
                        [--explore teacher|active] [--physics cached|per-episode] [--frames] [--gui]

The model's and the world's config (train/common/config.py): the defaults, then the --config file, then each --set in
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

import os
import sys

if __package__ in (None, ""):  # run as a script: make the project importable without installing it
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))

# Signals first: from here on a Ctrl-C, SIGTERM or SIGHUP waits for main() to say its one line (exits.early_signals)
from train.common import exits  # noqa: E402

if __name__ == "__main__":
    exits.early_signals()
    from train.common.collector import imports_begin
    imports_begin()   # the collector off while torch and the rest are imported (train/common/collector.py)

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

# Only light imports up here: torch takes about a second to import; everything the first line needs is checked
# without it. The parts: train/runner/settings.py (the settings and the config), train/runner/out_dir.py (--out, its lock),
# train/common/exits.py (signals, the one line, exit codes), train/runner/loop.py (the run itself).
from train.common.exits import (UsageError, console, ending_signals, exit_now, fresh_line, how, os_error,  # noqa: E402
                                raise_pending, sigint_ignored)
from train.runner.out_dir import check_out, lock_out  # noqa: E402, F401
from train.common.models import ABLATION_HELP, ABLATIONS, EXPLORE, MODEL_HELP, MODELS, check_capacity  # noqa: E402
from train.runner.settings import (DEFAULT_OBJECTS, DEFAULT_ORDERS, FULL_RUNS, MAX_ORDERS,  # noqa: E402, F401
                                   adopt_run, count_orders, gather_config, load_objects_or_fail,
                                   load_run_objects, orders_arg, resolve_config, seed_arg, world_kw)

DEFAULT_OUT = "runs/run-<date-time>"


class Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints usage + message; we promise one clear line
        raise UsageError(message)


class Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows defaults, except the None / False / [] of options whose help says what they default to."""

    def _get_help_string(self, action):
        none = action.default is None or action.default is False or action.default == []
        return action.help if none else super()._get_help_string(action)


CONFIG_HELP = """The config: every field of the agent's (aesop_torch.agent.AgentConfig: top-level keys such as
recall_sharpness, model, ablate, seed, and its parts encoder., hub., memory., rules.) and of the world's
(sim.world.WorldConfig under world.: world.mass_noise_g, world.tank..., world.tank.water..., world.robot...,
world.ik..., world.camera...). Applied in this order, a later value of a key replacing an earlier one: the
defaults, the --config file, each --set in the order given, then --model, --ablate and --seed (shorthands for the
keys model, ablate and seed): when the file and a flag both give a value, the flag wins. An unknown key, a value of
the wrong type or out of range: one line, exit 2, nothing written. CONTRACTS.md has the details."""


def model_help() -> str:
    """--model's help from the tables (train/common/models.py MODELS, MODEL_HELP): every model, so none is left out."""
    return "; ".join(f"{m}: {MODEL_HELP.get(m, 'see CONTRACTS.md')}" for m in MODELS) + \
        " (default: paper, or the config's model)"


def ablate_help() -> str:
    """--ablate's help from the tables (ABLATIONS, ABLATION_HELP): each part, and the models that have it."""
    parts = list(dict.fromkeys(p for m in MODELS for p in ABLATIONS[m]))
    said = []
    for part in parts:
        having = [m for m in MODELS if part in ABLATIONS[m]]
        only = "" if len(having) == len(MODELS) else f"{', '.join(having)} only: "
        said.append(f"{part} ({only}{ABLATION_HELP.get(part, 'see CONTRACTS.md')})")
    return "switch a part off (repeatable; replaces the config's ablate): " + ", ".join(said)


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
    ap.add_argument("--model", choices=MODELS, default=None, help=model_help())
    ap.add_argument("--ablate", action="append", default=None, metavar="PART", help=ablate_help())
    ap.add_argument("--explore", choices=EXPLORE, default=None,
                    help="who chooses the next object: teacher (the order given) or active (the robot: the object "
                         "on the stand whose comparison with a remembered episode would be cleanest for what is "
                         "still unknown; cached physics only) (default: teacher, or the config's explore)")
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


def main(argv=None) -> int:
    console()
    with ending_signals():
        return _main(argv)


def _main(argv=None) -> int:
    run_loop = None
    ran = None   # the run's exit code once it has returned
    try:
        raise_pending()   # a signal that came before main() (early_signals)
        from train.runner import loop as run_loop
        try:
            args = parse_args(sys.argv[1:] if argv is None else argv)
            if args.objects is not None and _is_task_file(args.objects):
                return run_task(args)
            objects = load_run_objects(args)
            n_orders = count_orders(len(objects.train), args.orders)
            check_out(args.out, args.resume)
            # before torch's import: it imports the figure's modules on the idle core (and the population's, when
            # one will run there: more orders than run in detail, on cached physics)
            run_loop.start_drawer((len(objects.train), args.orders, args.seed)
                                  if n_orders > FULL_RUNS and args.physics == "cached" else None)
            # every key of the config and the capacity are checked before the first line (that imports torch and
            # the simulator: about a second), so a refused one never follows a "starting"
            args.run_config = resolve_config(args, objects)
            if why := check_capacity(args.run_config.agent, len(objects.train)):
                raise UsageError(why)
            print(f"train/run.py: {'resuming' if args.resume else 'starting'} {n_orders:,} order(s) of "
                  f"{len(objects.train)} object(s), physics {args.physics}, seed {args.seed} -> {args.out}",
                  flush=True)
            from train.learning.sim_pool import Physics
            run_loop._OPEN["physics"] = physics = Physics(objects, seed=args.seed, gui=args.gui,
                                                          **world_kw(args))   # forked in prepare
            exp, resumed, lock = run_loop.prepare(args, objects, n_orders, physics)
        except UsageError as e:
            run_loop.close_quietly()
            print(f"train/run.py: error: {e}", file=sys.stderr)
            return 2
        except OSError as e:   # creating --out or its lock failed (a full disk, a race with another program)
            run_loop.close_quietly()
            print(f"train/run.py: error: {os_error(e)}", file=sys.stderr)
            return 1
        try:
            ran = run_loop.run(args, exp, objects, resumed)
            return ran
        finally:
            os.close(lock)   # the kernel would at exit; a caller of main() in-process may start another run
    except KeyboardInterrupt as e:
        by, code = how(e)
        with sigint_ignored():
            if run_loop is not None:
                run_loop.close_quietly()
            when = "before the run started" if ran is None else f"as the run ended (exit code {ran} otherwise)"
            print(f"{fresh_line()}train/run.py: interrupted{by} {when}", file=sys.stderr)
        return code


def _is_task_file(path: Path) -> bool:
    from train.battery.task_run import is_task_file
    return is_task_file(path)


def run_task(args) -> int:
    """--objects is a task file of the Aesop battery (sim/tasks/): --orders N agents of --seed explore and play it in
    the apparatus built in pybullet (train/battery/task_run.py). It has no checkpoints: an interrupted task run starts again."""
    from train.common.collector import imports_done
    imports_done()   # the collector on for the run (train/common/collector.py)
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
        from train.battery.task_run import run_task_file
        try:
            run_task_file(task, args.out, args.model, args.seed, int(args.orders), tuple(args.ablate), args.frames)
        except OSError as e:
            print(f"{fresh_line()}train/run.py: error: {os_error(e)}", file=sys.stderr)
            return 1
        except KeyboardInterrupt as e:
            by, code = how(e)
            print(f"{fresh_line()}train/run.py: interrupted{by}; a task run keeps no checkpoint: run it again "
                  f"(with another --out, or remove {args.out})", file=sys.stderr)
            return code
        print(f"train/run.py: wrote {args.out}/summary.json, tb/" + (", frames/" if args.frames else ""))
        return 0
    finally:
        os.close(lock)


def console_main() -> None:
    """`python train/run.py` and the console command aesop-run: the run, then its exit without the interpreter's
    teardown (everything is written and closed; train/common/exits.py exit_now)."""
    from train.common.collector import imports_begin
    exits.early_signals()   # aesop-run's (the script's already, before its imports)
    imports_begin()   # aesop-run's (the script's already): train/common/collector.py
    exit_now(main())


if __name__ == "__main__":
    console_main()
