"""One task of the Aesop battery with physics: `train/run.py --objects sim/tasks/<task>.json`.

The task's tubes are built in pybullet (sim/tubes.py) and seen from the camera (sim.perception.perceive_tube): each
tube's width, level and the look of what fills it become the agent's context properties, as train/battery/tasks.py's
agents have them, but measured from images instead of read from the file. Every (tube, object) option, and every
exploration drop, is simulated from the task's starting levels (each trial is set up afresh, as in the studies), and
its reward tube's rise is measured from the simulation. pybullet is deterministic, so each distinct drop is simulated
once and its measured outcome replayed on every trial that repeats it. Then `--orders` naive subjects of `--seed`,
pre-trained on stones in a jar-like tube (the closed form's: the pre-training is no part of the task), meet the task
on trial 1 and play its 20 trials, its tubes mirrored on half of them (train.battery.tasks.run_task).

Writes into --out: summary.json (the perceived tubes, each option's simulated and closed-form rise, every agent's
choices, the scores), tb/ (per trial: the share of agents choosing right, the mean rise they got) and, with
--frames, frames/ (a side view of each option's drop at rest, and each tube seen from above).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

REWARD_TRIALS_TAG = "battery"
PASS_P = 0.05   # train/battery/tasks.py Score.passed: p below it passes (said in the verdict)


def is_task_file(path) -> bool:
    """Whether an --objects file is a task file (it has an "apparatus"): read with the objects file's bounded reader."""
    from sim.apparatus import _read_json
    from sim.objects import ObjectsFileError
    try:
        data = _read_json(path)
    except ObjectsFileError:
        return False   # the objects file's loader reports what is wrong with it
    return isinstance(data, dict) and "apparatus" in data


def look(rgb) -> float:
    """A surface's look as one value in 0..1: its mean brightness in flat light (what the camera gives, not what
    the substrate is)."""
    return min(max(sum(rgb) / 3.0, 0.0), 1.0)


class PhysicsWorld:
    """The task in pybullet: the tubes as the camera sees them, and each drop's measured outcome (cached: the
    simulation of a drop from the starting levels is deterministic)."""

    def __init__(self, task, frames: Path | None = None):
        self.task, self.frames, self._drops = task, frames, {}
        self.seen = self._perceive()

    def _perceive(self) -> dict:
        import pybullet as p

        from sim.perception import perceive_tube
        from sim.tubes import Apparatus
        cl = p.connect(p.DIRECT)
        try:
            ap = Apparatus(cl, self.task)
            seen = {}
            for t in self.task.tubes:
                body = ap.beds.get(t.name, ap.visuals.get(t.name))
                seen[t.name] = perceive_tube(cl, body, ap.centers[t.name], ap.bottom_z,
                                             ap.bottom_z + t.height_cm / 100.0)
                if self.frames is not None:
                    self._save(self._top_view(cl, ap, t), f"tube_{t.name}_from_above.png")
            if self.frames is not None:
                self._save(self._side_view(cl, ap), "start.png")
            return seen
        finally:
            p.disconnect(cl)

    def measurement(self, task, tube, obj) -> dict:
        """An option as the agent perceives it: the object's measurement and the tube's context from the camera."""
        from train.battery.tasks import WIDTH_RANGE_CM
        from train.battery.tasks import reward_gap_cm
        m = dict(obj.exact_measurement())
        m["gap_cm"] = reward_gap_cm(task, tube, {k: v["level_cm"] for k, v in self.seen.items()})
        s = self.seen[tube.name]
        lo, hi = WIDTH_RANGE_CM
        d = min(max(s["width_cm"], lo), hi)
        names = [t.name for t in task.tubes]   # the task as laid out on this trial (train.battery.tasks.mirrored)
        m["context"] = {"surface": look(s["substrate_rgb"]),
                        "width": (math.log(d) - math.log(lo)) / (math.log(hi) - math.log(lo)),
                        "level": min(max(s["level_cm"] / tube.height_cm, 0.0), 1.0),   # the rim is the workspace's
                        "place": names.index(tube.name) / max(len(names) - 1, 1)}
        return m

    def outcome(self, task, levels, tube, obj) -> dict:
        """sim.apparatus.outcome's contract, measured: one drop from the starting levels in a fresh world."""
        key = (tube.name, obj.name)
        if key not in self._drops:
            self._drops[key] = self._simulate(tube, obj)
        return self._drops[key]

    def _simulate(self, tube, obj) -> dict:
        import pybullet as p

        from sim.tubes import Apparatus
        cl = p.connect(p.DIRECT)
        try:
            ap = Apparatus(cl, self.task)
            start = ap.levels_cm()
            out = ap.drop(tube.name, obj)
            if self.frames is not None:
                self._save(self._side_view(cl, ap), f"drop_{tube.name}_{obj.name}.png")
        finally:
            p.disconnect(cl)
        levels = {k: float(v) for k, v in out["levels"].items()}
        rewards = [t for t in self.task.tubes if t.reward]
        rises = {k: levels[k] - float(start[k]) for k in levels}
        return {"levels": levels, "rise_cm": rises, "settled": bool(out["settled"]),
                "reward_rise_cm": max((rises[t.name] for t in rewards), default=0.0),
                "reached": any(levels[t.name] >= t.height_cm - self.task.reach_cm for t in rewards)}

    # -- frames ------------------------------------------------------------------------------------------------
    def _side_view(self, cl, ap):
        from sim.perception import take_view
        ys = [c[1] for c in ap.centers.values()]
        x, y = float(next(iter(ap.centers.values()))[0]), (min(ys) + max(ys)) / 2
        top = ap.bottom_z + max(t.height_cm for t in self.task.tubes) / 100.0
        v = take_view(cl, [x + 0.30, y, top + 0.30], [x, y, top * 0.6], [0, 0, 1], 40.0, 320, 240, 0.05, 3.0,
                      flat=False)
        return v.rgb

    def _top_view(self, cl, ap, t):
        from sim.perception import take_view
        x, y = (float(c) for c in ap.centers[t.name])
        rim = ap.bottom_z + t.height_cm / 100.0
        v = take_view(cl, [x, y, rim + 0.30], [x, y, ap.bottom_z], [1, 0, 0], 25.0, 160, 160, 0.05, 3.0)
        return v.rgb

    def _save(self, rgb, name: str) -> None:
        import matplotlib
        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
        self.frames.mkdir(parents=True, exist_ok=True)
        plt.imsave(self.frames / name, rgb)


def run_task_file(task, out: Path, model: str, seed: int, orders: int, ablate=(), frames: bool = False,
                  log=print) -> dict:
    """Run one task (sim.apparatus.Task) with physics into `out` (a directory this run owns); returns the summary."""
    from sim.apparatus import outcome
    from train.battery.tasks import run_task
    from train.learning.checkpoint import write_text_atomic

    t0 = time.time()
    world = PhysicsWorld(task, out / "frames" if frames else None)
    for name, s in world.seen.items():
        log(f"  seen {name}: {s['width_cm']:.2f} cm wide, level {s['level_cm']:.2f} cm, look "
            f"{look(s['substrate_rgb']):.2f}")
    result = run_task(task, model, [seed], orders, tuple(ablate), outcome=world.outcome, perceive=world.measurement)
    start = task.start_levels()
    options = []
    for i, (tube, obj) in enumerate(task.options()):
        sim_out, closed = world.outcome(task, start, tube, obj), outcome(task, dict(start), tube, obj)
        options.append({"option": f"{tube.name}:{obj.name}", "correct": i in result["correct"],
                        "simulated_rise_cm": round(sim_out["reward_rise_cm"], 4),
                        "closed_form_rise_cm": round(float(closed["reward_rise_cm"]), 4),
                        "reached": sim_out["reached"], "settled": sim_out["settled"]})
        log(f"  {options[-1]['option']}: the reward rises {options[-1]['simulated_rise_cm']:+.3f} cm simulated, "
            f"{options[-1]['closed_form_rise_cm']:+.3f} cm closed form" + (" (correct)" if options[-1]["correct"]
                                                                           else ""))
    _tensorboard(out / "tb", result, options)
    scores = {k: {"correct": s.correct, "n": s.n, "percent": round(s.percent, 1), "p": s.p, "passed": s.passed}
              for k, s in result["scores"].items()}
    summary = {"task": task.name, "model": model, "ablate": list(ablate), "seed": seed, "agents": orders,
               "chance": result["chance"], "perceived": world.seen, "options": options,
               "choices": [[result["options"][i] for i in c] for c in result["choices"]], "scores": scores,
               "seconds": round(time.time() - t0, 1)}
    write_text_atomic(json.dumps(summary, indent=1) + "\n", out / "summary.json")
    for k, s in scores.items():
        log(f"  {k}: {s['correct']}/{s['n']} correct ({s['percent']:.0f} %), p = {s['p']:.3g}"
            + verdict(s["passed"], s["n"], result["chance"]))
    return summary


def verdict(passed: bool, n: int, chance: float) -> str:
    """What a score's p-value says: " -> pass", " -> fail", or, when even n correct of n would not pass (2 trials at
    chance 0.5 give p = 0.25 at best), that the test cannot pass on so few trials: not a failure of the agents."""
    from train.battery.tasks import Score

    if passed:
        return " -> pass"
    if not Score(n, n, chance).passed:
        return f" (too few trials to pass at {PASS_P:g})"
    return " -> fail"


def _tensorboard(logdir: Path, result: dict, options: list) -> None:
    from torch.utils.tensorboard import SummaryWriter
    w = SummaryWriter(log_dir=str(logdir))
    try:
        rise = [o["simulated_rise_cm"] for o in options]
        for i in range(len(result["right"][0])):
            right = [r[i] for r in result["right"]]
            w.add_scalar(f"{REWARD_TRIALS_TAG}/correct_share", sum(right) / len(right), i + 1)
            got = [rise[c[i]] for c in result["choices"]]
            w.add_scalar(f"{REWARD_TRIALS_TAG}/reward_rise_cm", sum(got) / len(got), i + 1)
        w.flush()
    finally:
        w.close()
