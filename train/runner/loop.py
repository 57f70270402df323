"""A run from its checked settings to summary.json: the experiment built (or resumed from its checkpoint), the
simulations on the physics workers, the episodes with a checkpoint after each, the population, Figure 2 and the goal
trials, and how it ends if it does not finish (one line on stderr naming the last checkpoint, the exit code).

What the run has open (the physics workers, the figure process, the tensorboard logs) is in _OPEN, and closed
whatever way the run ends (close_quietly), with signals held so that a pool is never left half-ended.
"""

from __future__ import annotations

import copy
import sys
import time

from train.common.collector import imports_done
from train.common.exits import UsageError, fresh_line, how, os_error, sigint_ignored, signals_held
from train.runner.out_dir import CONFIG_NAME, RUN_NAME, holds_a_run, lock_out, remove_leftovers, unlock_created
from train.runner.settings import agent_keys_set, check_same_config, check_same_run, run_settings, world_kw

FULL_TB_ORDERS = 16      # tensorboard run directories beyond this would drown a person; see README
_OPEN: dict = {"physics": None, "drawer": None, "logs": []}   # what the run has open, closed whatever way it ends


def close_quietly() -> None:
    """Close what the run has open, each once; a signal meanwhile takes effect after (signals_held)."""
    with signals_held():
        physics, drawer, logs = _OPEN["physics"], _OPEN["drawer"], _OPEN["logs"]
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
        _OPEN["physics"], _OPEN["drawer"], _OPEN["logs"] = None, None, []


def start_drawer(population: tuple | None = None) -> None:
    """The figure process (train/runner/figure_process.py), started now and kept in _OPEN in one step (a pool dropped
    halfway would be ended only by its finaliser). population: (n_objects, orders, seed) of the population it will
    run (_start_population), so that it imports that too and prepares its orders at its start; None: none."""
    from train.runner.figure_process import Drawer
    with signals_held():
        _OPEN["drawer"] = _OPEN["drawer"] or Drawer(population)


def prepare(args, objects, n_orders: int, physics=None):
    """Validate the rest (needs torch) and return (experiment, resumed, lock fd). Locks --out first, so that a
    checkpoint is read and verified only by the run that owns it; nothing else is written before everything is
    checked. physics (train.learning.sim_pool.Physics, optional): a new run forks its workers once everything is checked and
    before the experiment is built (the world built once, train/learning/sim_pool.py), so they simulate while the
    maps train."""
    import torch

    from aesop_torch.malloc import keep_freed_memory
    from train.learning.experiment import Experiment, draw_orders
    from train.runner.settings import FULL_RUNS

    keep_freed_memory()   # freed tensors are reused rather than faulted in again (aesop_torch/malloc.py)

    # small tensors (at most 64 agents in detail) run faster on one thread than on two fighting each other, and so
    # does building the experiment (its maps' training took 6.9 s on 2 threads of a busy machine, 0.3 s on 1); a
    # population of many orders sets its own (train/learning/population.py)
    torch.set_num_threads(1)
    if args.run_config.agent.explore == "active" and args.physics == "per-episode":
        raise UsageError("--explore active looks at every object on the stand before choosing, from its measurement "
                         "on cached physics: it does not run with --physics per-episode")
    if n_orders > FULL_RUNS and args.physics == "per-episode":
        raise UsageError(f"--physics per-episode with {n_orders} orders would simulate "
                         f"{n_orders * len(objects.train)} drops; more than {FULL_RUNS} orders run as a population "
                         "on cached physics")
    created = [d for d in [args.out, *args.out.parents] if not d.exists()]   # innermost first
    lock = lock_out(args.out)
    try:
        if args.resume:
            return resume_experiment(args, objects), True, lock
        if holds_a_run(args.out):   # filled since check_out: another run's
            raise UsageError(f"--out {args.out} already holds files; use --resume to continue it or another --out")
        remove_leftovers(args.out)
        # more than FULL_RUNS orders: the first FULL_RUNS run in detail here, every order as a population at the end
        orders = draw_orders(len(objects.train), args.orders, args.seed, limit=FULL_RUNS)
        if physics is not None:
            physics.start()
            # the measurements are handed over now: the workers simulate while the experiment is built (its maps'
            # training) and its first checkpoint written, which they waited for before (_run takes them up)
            physics.submit_early(measurement_jobs(objects, [o.name for o in objects.train],
                                                  [o.name for o in objects.probe], {}, {}, args.physics,
                                                  args.frames)[-1])
        # a copy: the experiment sizes its agents' buffers to the train objects in its config (train.learning.experiment)
        config = copy.deepcopy(args.run_config.agent)
        try:
            return Experiment([o.name for o in objects.train], [o.name for o in objects.probe], orders,
                              seed=args.seed, physics=args.physics, config=config), False, lock
        except (ValueError, TypeError, IndexError, RuntimeError, OverflowError) as e:
            if not agent_keys_set(args):
                raise   # the defaults must build: a bug, with its traceback
            lines = str(e).strip().splitlines()
            raise UsageError(f"the agents cannot be built with this config ({type(e).__name__}: "
                             f"{lines[0] if lines else ''})") from None
    except BaseException:
        # refused or interrupted after all: leave nothing behind
        unlock_created(args.out, lock, created)
        raise
    finally:
        imports_done()   # the collector on for the run, whichever way it was prepared (train/common/collector.py)


def resume_experiment(args, objects):
    from train.learning.checkpoint import CheckpointError, load
    from train.learning.experiment import Experiment

    ckpt_path = args.out / "checkpoints" / "latest.pt"
    if not ckpt_path.is_file():
        raise UsageError(f"--resume: no checkpoint at {ckpt_path}: the run ended before it wrote one, so there is "
                         f"nothing to continue; start it again without --resume (with another --out, or remove "
                         f"{args.out})")
    try:
        state = load(ckpt_path)
    except CheckpointError as e:
        raise UsageError(f"--resume: {e}; nothing was changed") from None
    check_same_run(args, objects, state["run"])
    check_same_config(args, objects, state["experiment"]["config"])
    return Experiment.from_state_dict(state["experiment"])


def write_config(config: dict, path) -> None:
    """config.json, atomically (train.learning.checkpoint's writer: a temporary file beside it, fsynced, renamed over it)."""
    import json

    from train.learning.checkpoint import write_text_atomic
    write_text_atomic(json.dumps(config, indent=1) + "\n", path)


def run(args, exp, objects, resumed: bool) -> int:
    """The run, to its exit code: 0, or one line on stderr and 1 (a dead worker, a world its workers could not
    build, a write error) or 128 + the signal (Ctrl-C, SIGTERM, SIGHUP), naming the last checkpoint."""
    out, t0 = args.out, time.time()
    ckpt = out / "checkpoints" / "latest.pt"
    saved = {"t": exp.t if resumed else None}   # episodes in the last checkpoint written (None: none yet)

    def last_checkpoint() -> str:
        if saved["t"] is None:
            return "no checkpoint was written yet: run the same command again (with another --out, or remove it)"
        # a run's settings are in its run.json (a run from before it: the flags must be given again)
        how_on = (f"--resume --out {out}" if (out / RUN_NAME).is_file() else
                  f"the same flags and --resume --out {out}")
        return (f"the last checkpoint ({ckpt}, {saved['t']} of {exp.n_episodes} episodes) is intact: "
                f"continue with {how_on}")

    from sim.errors import WorldBuildError
    from train.learning.sim_pool import WorkerDied

    def ended(line: str, code: int) -> int:
        with sigint_ignored():
            close_quietly()
            print(f"{fresh_line()}train/run.py: {line}", file=sys.stderr)
        return code

    try:
        return _run(args, exp, objects, resumed, out, ckpt, saved, t0)
    except WorkerDied as e:   # killed (by a person, the OOM killer): its job would never be answered
        return ended(f"error: {e}; {last_checkpoint()}", 1)
    except WorldBuildError as e:   # a world config the scene does not admit, found by the workers building it
        return ended(f"error: {e} (check the config's world keys); {last_checkpoint()}", 1)
    except KeyboardInterrupt as e:
        by, code = how(e)
        return ended(f"interrupted{by}; {last_checkpoint()}", code)
    except OSError as e:   # a full disk (ENOSPC) or another write error: the checkpoint is written atomically
        return ended(f"error: {os_error(e)}; {last_checkpoint()}", 1)
    finally:
        close_quietly()


def _run(args, exp, objects, resumed, out, ckpt, saved, t0) -> int:
    import json

    from sim.objects import archimedes_cm3
    from train.learning.checkpoint import save_atomic, write_text_atomic
    from train.common.config import RunConfig, config_dict
    from train.learning.experiment import draw_orders, outcome_record, plain_measurement
    from train.learning.sim_pool import Physics, WorkerDied
    from train.common.progress import Step
    from train.runner.summary import build_summary, knowledge_table, summary_text
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
    physics = _OPEN["physics"] = _OPEN["physics"] or Physics(objects, seed=args.seed, gui=args.gui,
                                                             **world_kw(args))   # main() made it
    specs = {o.name: o for o in objects.train + objects.probe}
    density = args.run_config.world.tank.water.density / 1000.0   # g/cm^3: Archimedes' figure in the world's water
    # probes are inspected once; with cached physics every distinct train object is dropped once, all up front. A
    # probe that waits on a trial's stand is measured by a drop instead: the same look, take, lift and weigh as an
    # inspection, so the same measurement bit for bit (tests/test_world.py), and a trial's first drop of it (the
    # agent learns nothing from it here)
    todo, probes, on_stands, jobs = measurement_jobs(objects, exp.train_names, exp.probe_names, exp.outcomes,
                                                     exp.probes, exp.physics, args.frames)
    probe_drops = {}
    submitted = physics.submit(jobs)   # the workers start on them while the logs open (a new run's: since prepare)
    from train.runner.tensorboard_log import OrderLog, trial_line   # tensorboard's import (0.2 s) too
    from train.learning.goal_trials import planner_sequences
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
                                "archimedes_cm3": float(archimedes_cm3(specs[name], objects.jar, density))}
        checkpoint()
    # every order as a population (more than the detailed ones) runs on the figure process beside the detailed
    # orders and the goal trials: it needs only the measured outcomes (cached physics: all in by now)
    population_job = _start_population(args, exp)
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
    population = figure = None
    if population_job is None:
        orders = draw_orders(len(exp.train_names), args.orders, args.seed)
        if len(orders) > len(exp.orders):   # not started above (outcomes measured per episode): here, in line
            from train.learning.population import run_population
            print(f"population: {len(orders)} orders side by side (the first {len(exp.orders)} also ran in "
                  "detail)", flush=True)
            with Step("population", len(orders), "order") as bar:
                population = run_population(exp.train_names, exp.probe_names, orders, exp.outcomes, exp.probes,
                                            exp.config, progress=bar.to, curves=True)
        # Figure 2 shows the exploration: drawn and written by the drawer while the goal trials run
        figure = _draw_figure(exp, out, population)
    if objects.trials:
        from train.learning.goal_trials import play_trials
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
    if population_job is not None:   # the figure process runs it beside the trials: Figure 2 next there, its result
        figure = _draw_population_figure(exp, out)
        with Step("population", None, "order", announce=False):
            try:
                population = population_job.get()
            except WorkerDied as e:
                raise WorkerDied("the figure process", e.pid, e.exitcode) from None
        print(f"population: done ({population['timing_s']['total']:.1f} s on the figure process)", flush=True)
    # summary.json's text is made while the figure process draws (9! orders: 8.7 MB, ~0.3 s), written last
    summary = build_summary(exp, population, config)
    text = summary_text(summary) + "\n"
    try:
        image = figure.get()
    except WorkerDied as e:   # the drawer's pool names its process generically
        raise WorkerDied("the figure process", e.pid, e.exitcode) from None
    shown, now = logs and logs[0].encoded("figure2", image), time.time()
    for log in logs:
        log.shown(shown, exp.n_episodes, now)   # one wall time: the same event bytes, checksummed once
        log.close()   # not quietly: a write error here is the run's (one line, exit code 1)
    _OPEN["logs"] = []
    close_quietly()   # the workers and the drawer: every result is in
    write_text_atomic(text, out / "summary.json")
    print(f"\nwrote {out}/: summary.json, config.json, figure2.png, tb/ (tensorboard --logdir {out / 'tb'}), "
          f"checkpoints/latest.pt" + (", frames/" if args.frames else "") + f"  [{time.time() - t0:.1f} s]")
    print(knowledge_table(summary))
    return 0


def measurement_jobs(objects, train_names, probe_names, outcomes: dict, probes_done: dict, physics: str,
                     frames: bool) -> tuple[list, list, set, list]:
    """(train objects to drop, probes to measure, the objects on a trial's stand, the physics jobs) a run still
    needs before its episodes: with cached physics each distinct train object not yet in `outcomes` dropped once,
    each probe not yet in `probes_done` inspected (dropped, when it waits on a trial's stand)."""
    todo = [n for n in dict.fromkeys(train_names) if n not in outcomes] if physics == "cached" else []
    probes = [n for n in probe_names if n not in probes_done]
    on_stands = {n for stand in objects.trials for n in stand}
    jobs = [("drop", n, frames) for n in todo] + [("drop" if n in on_stands else "inspect", n, None)
                                                  for n in probes]
    return todo, probes, on_stands, jobs


def _start_population(args, exp):
    """Every order (when there are more than the detailed ones) as a population
    (train.learning.population.run_orders) on the figure process, started now: an object whose get() waits for its
    result; None when there is no population or its outcomes are not all measured yet (per-episode physics: _run
    runs it in line at the end). The runner's own process then runs the detailed orders and the goal trials
    meanwhile: all 9! orders of 9 objects took 23 of the run's 40 s, and the detailed orders and the trials another
    9 s after it."""
    from train.runner.settings import count_orders

    if count_orders(len(exp.train_names), args.orders) <= len(exp.orders) or \
            any(n not in exp.outcomes for n in exp.train_names):
        return None
    print(f"population: {count_orders(len(exp.train_names), args.orders)} orders side by side on the figure process "
          f"(the first {len(exp.orders)} also run in detail here)", flush=True)
    start_drawer()   # main() started it
    # the experiment's developed maps go along (as arrays: plain pickles), not developed there again
    maps = {k: v.numpy() for k, v in exp.agent.maps.state_dict().items()}
    return _OPEN["drawer"].draw("train.learning.population:run_orders", exp.train_names, exp.probe_names,
                                args.orders, args.seed, exp.outcomes, exp.probes, exp.config, maps)


def _draw_figure(exp, out, population):
    """Figure 2 (the exploration; a population's error bands over all its orders), drawn and written by the figure
    process: an object whose get() waits for its image."""
    from train.learning.experiment import senses_floor
    from train.runner.figure_process import POPULATION_FIGURE_KEYS

    start_drawer()   # main() started it
    return _OPEN["drawer"].draw("train.runner.figures:save_figure2", exp.records, out / "figure2.png", 110,
                                senses_floor(exp.probes),
                                population and {k: population[k] for k in POPULATION_FIGURE_KEYS})


def _draw_population_figure(exp, out):
    """Figure 2 with the population the figure process is running (_start_population), asked for now: drawn there
    once the population is done, from its answer in that process (figure_process.figure_of_the_population)."""
    from train.learning.experiment import senses_floor

    return _OPEN["drawer"].draw("train.runner.figure_process:figure_of_the_population", exp.records,
                                out / "figure2.png", 110, senses_floor(exp.probes))


def _flat(prefix: str, d: dict) -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(f"{prefix}.{k}", v))
        else:
            out[f"{prefix}.{k}"] = v
    return out
