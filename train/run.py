"""The experiment runner: cumulative causal learning in the pybullet world, with checkpoints and tensorboard.

    python train/run.py [--objects FILE] [--orders N|listed|all] [--seed S] [--out DIR] [--resume]
                        [--physics cached|per-episode] [--frames] [--gui]

Writes into DIR: tensorboard runs (tb/order_<i>/), checkpoints/latest.pt (after every episode, atomic),
figure2.png, frames/ (with --frames) and summary.json (SPEC.md). Bad input: one line on stderr, exit code 2, nothing
written.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the project importable without installing it
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from train.checkpoint import load, save_atomic, write_text_atomic  # noqa: E402
from train.experiment import Experiment, draw_orders, outcome_record, plain_measurement  # noqa: E402
from train.progress import Progress  # noqa: E402
from train.summary import FULL_RUNS, build_summary, knowledge_table  # noqa: E402

DEFAULT_OBJECTS = Path(__file__).resolve().parents[1] / "sim" / "default_objects.json"
DEFAULT_ORDERS = "4"     # the paper's Figure 2: four random orders of the eight objects
FULL_TB_ORDERS = 16      # tensorboard run directories beyond this would drown a person; see README


class UsageError(Exception):
    """Bad input: reported as one line and exit code 2."""


class Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints usage + message; we promise one clear line
        raise UsageError(message)


def parse_args(argv):
    ap = Parser(prog="train/run.py", description=__doc__.split("\n")[0])
    ap.add_argument("--objects", type=Path, default=DEFAULT_OBJECTS, help="objects file (JSON, SPEC.md schema)")
    ap.add_argument("--orders", default=DEFAULT_ORDERS, help="N random orders, 'listed' or 'all' permutations")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="output directory (default runs/<date-time>)")
    ap.add_argument("--resume", action="store_true", help="continue the interrupted run in --out")
    ap.add_argument("--physics", choices=("cached", "per-episode"), default="cached",
                    help="simulate each distinct object once (cached) or every episode of every order")
    ap.add_argument("--frames", action="store_true", help="save camera frames of each simulated drop")
    ap.add_argument("--gui", action="store_true", help="pybullet GUI (needs a display)")
    a = ap.parse_args(argv)
    if a.orders not in ("listed", "all"):
        if not a.orders.isdigit() or int(a.orders) < 1:
            raise UsageError(f"--orders must be a positive number, 'listed' or 'all', not {a.orders!r}")
    if a.seed < 0:
        raise UsageError(f"--seed must be >= 0, not {a.seed}")
    if a.gui:
        from sim.world import gui_unavailable
        if why := gui_unavailable():
            raise UsageError(f"--gui: {why}")
    if a.resume and a.out is None:
        raise UsageError("--resume needs --out DIR (the run to continue)")
    if a.out is None:
        a.out = Path("runs") / time.strftime("run-%Y%m%d-%H%M%S")
    return a


def load_objects_or_fail(path: Path):
    from sim.objects import ObjectsFileError, load_objects
    try:
        return load_objects(path)
    except ObjectsFileError as e:
        raise UsageError(f"{path}: {e}") from None


def prepare(args):
    """Validate everything and return (experiment, objects, resumed) before a single byte is written."""
    objects = load_objects_or_fail(args.objects)
    ckpt_path = args.out / "checkpoints" / "latest.pt"
    train_names = [o.name for o in objects.train]
    probe_names = [o.name for o in objects.probe]
    if args.resume:
        if not ckpt_path.is_file():
            raise UsageError(f"--resume: no checkpoint at {ckpt_path}")
        try:
            state = load(ckpt_path)
        except Exception as e:  # a foreign or damaged file: say so in one line
            raise UsageError(f"--resume: cannot read {ckpt_path}: {type(e).__name__}") from None
        wanted = {"objects": objects.canonical(), "seed": args.seed, "physics": args.physics,
                  "orders_arg": args.orders}
        for key, value in wanted.items():
            if state["run"].get(key) != value:
                raise UsageError(f"--resume: {key} differs from the interrupted run in {args.out}")
        return Experiment.from_state_dict(state["experiment"]), objects, True
    if args.out.exists() and any(args.out.iterdir()):
        raise UsageError(f"--out {args.out} already holds files; use --resume to continue it or another --out")
    orders = draw_orders(len(train_names), args.orders, args.seed)
    if len(orders) > FULL_RUNS and args.physics == "per-episode":
        raise UsageError(f"--physics per-episode with {len(orders)} orders would simulate "
                         f"{len(orders) * len(train_names)} drops; more than {FULL_RUNS} orders run as a population "
                         "on cached physics")
    # more than FULL_RUNS orders: the first FULL_RUNS run in detail here, every order as a population at the end
    detailed = orders[:FULL_RUNS]
    return Experiment(train_names, probe_names, detailed, seed=args.seed, physics=args.physics), objects, False


def main(argv=None) -> int:
    try:
        args = parse_args(sys.argv[1:] if argv is None else argv)
        exp, objects, resumed = prepare(args)
    except UsageError as e:
        print(f"train/run.py: error: {e}", file=sys.stderr)
        return 2
    return run(args, exp, objects, resumed)


def run(args, exp: Experiment, objects, resumed: bool) -> int:
    import torch

    from sim.objects import archimedes_cm3
    from train.physics import Physics
    from train.tensorboard_log import OrderLog
    # small tensors (a few agents) run faster on one thread than on two fighting each other; a large population's
    # big tensors use both cores
    torch.set_num_threads(1 if len(exp.orders) <= 256 else 2)

    out, t0 = args.out, time.time()
    ckpt = out / "checkpoints" / "latest.pt"
    run_meta = {"objects": objects.canonical(), "seed": args.seed, "physics": args.physics,
                "orders_arg": args.orders}

    def checkpoint():
        save_atomic({"run": run_meta, "experiment": exp.state_dict()}, ckpt)

    if not resumed:
        checkpoint()  # from here on the run can be resumed, even if it is killed during the first simulations
    logs = [OrderLog(out / "tb" / f"order_{b + 1:02d}", purge_step=(exp.t + 1) if resumed else None)
            for b in range(min(len(exp.orders), FULL_TB_ORDERS))]
    if not resumed:
        hp = {"seed": args.seed, "physics": args.physics, "orders": args.orders,
              "objects": str(args.objects), **_flat("agent", exp.config.to_dict())}
        for b, log in enumerate(logs):
            log.hparams({**hp, "order": " ".join(exp.train_names[i] for i in exp.orders[b])},
                        {"prediction/probe_rel_error": float("nan")})

    physics = Physics(objects, seed=args.seed, gui=args.gui)
    specs = {o.name: o for o in objects.train + objects.probe}

    def keep(outcome, tag: str) -> dict:
        if args.frames and outcome.frames:
            from sim.episode import save_frames_png
            save_frames_png(outcome.frames, out / "frames" / tag)
            for i, frame in enumerate(outcome.frames):  # a slider per drop in tensorboard's Images tab
                logs[0].writer.add_image(f"frames/{tag}", frame, i, dataformats="HWC")
        return outcome_record(outcome)

    # probes are inspected once; with cached physics every distinct train object is dropped once, all up front
    todo = [n for n in dict.fromkeys(exp.train_names) if n not in exp.outcomes] if exp.physics == "cached" else []
    probes = [n for n in exp.probe_names if n not in exp.probes]
    if todo or probes:
        print(f"simulating {len(todo)} drop(s) and {len(probes)} probe inspection(s) on {physics.workers} "
              f"process(es)", flush=True)
        results = physics.run([("drop", n, args.frames) for n in todo] + [("inspect", n, None) for n in probes])
        for name, outcome in zip(todo, results):
            exp.outcomes[name] = keep(outcome, name)
        for name, m in zip(probes, results[len(todo):]):
            exp.probes[name] = {"measurement": plain_measurement(m),
                                "archimedes_cm3": float(archimedes_cm3(specs[name], objects.jar))}
        checkpoint()
    print(f"{'resuming' if resumed else 'running'}: {len(exp.orders)} order(s) x {exp.n_episodes} episodes, "
          f"physics {exp.physics}" + (" (each distinct object simulated once, its measured outcome reused by "
                                       "every order: the jar is reset between episodes)" if exp.physics == "cached"
                                       else ""), flush=True)
    progress = Progress(exp.n_episodes)
    while not exp.done:
        t = exp.t
        if exp.physics == "per-episode":
            names = [exp.train_names[o[t]] for o in exp.orders]
            fresh = [keep(o, f"order{b + 1:02d}_ep{t + 1:02d}_{n}")
                     for b, (n, o) in enumerate(zip(names, physics.drops(names, args.frames)))]
            recs = exp.step(lambda name, b, t: fresh[b])
        else:
            recs = exp.step(lambda name, b, t: exp.outcomes[name])
        for b, log in enumerate(logs):
            log.episode(t, recs[b])
        checkpoint()
        progress.update(exp.t, recs[0]["object"], recs[0]["rules"])
    physics.close()

    population = None
    orders = draw_orders(len(exp.train_names), args.orders, args.seed)
    if len(orders) > len(exp.orders):
        from train.population import run_population
        print(f"population: {len(orders)} orders side by side (the first {len(exp.orders)} also ran in detail)",
              flush=True)
        population = run_population(exp.train_names, exp.probe_names, orders, exp.outcomes, exp.probes,
                                    exp.config)
    summary = build_summary(exp, population)
    from train.figures import figure2
    fig = figure2(exp.records)
    fig.savefig(out / "figure2.png", dpi=110)
    from torch.utils.tensorboard._utils import figure_to_image
    image = figure_to_image(fig)   # drawn once, written to every order's log (add_figure would draw it per log)
    for log in logs:
        log.writer.add_image("figure2", image, exp.n_episodes)
        log.close()
    write_text_atomic(json.dumps(summary, indent=1) + "\n", out / "summary.json")
    print(f"\nwrote {out}/: summary.json, figure2.png, tb/ (tensorboard --logdir {out / 'tb'}), "
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
    sys.exit(main())
