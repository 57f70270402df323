"""The physics' speed (one headless drop episode, the water's share of a step) and the runner's, side by side with a
commit: the default run and all 9! orders of nine objects.

    python benches/episode_speed.py [--baseline COMMIT] [--runs N] [--nine-runs M] [--skip-nine] [--record]

1. The world's build time, one drop episode (the paper's heavy red cylinder, pick to settle) and a goal check.
2. Per physics step of that episode: the water model (`Water.step`) beside pybullet's own `stepSimulation`.
3. `python train/run.py` (the default run, `make run`) of this tree beside the same command at --baseline (default
   10e7246, the main before issue 47), checked out by `git worktree` into a temporary directory: N runs each,
   alternately, so both see the same machine; median wall times and their ratio (baseline / this tree: above 1,
   this tree is faster), the same for the run's wait for its 13 exploration simulations (as the run reports it),
   and which top-level keys of summary.json differ (its `commit`, the code's name, aside; against 10e7246 only
   `config`, which gained keys since), with the 1-minute load average while they ran: the ratio depends on the
   machine's other jobs.
4. `python train/run.py --objects nine.json --orders all` (nine.json: the default set and a ninth train object, a
   blue heavy sphere, as benches/population.py: 9! = 362,880 orders as a population) the same way, M runs each.
Skipped (said so) when git or the commit is not available. Printed, never asserted; the last line is
`default_s=X default_s_base=Y nine_all_s=Z nine_all_s_base=W ratio_default=Y/X ratio_nine=W/Z` (n/a where skipped).
`--record` writes the output into BENCHMARKS.md.
"""

import argparse
import datetime
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from aesop_torch.malloc import keep_freed_memory  # noqa: E402

import torch  # noqa: E402

from sim.objects import DEFAULT_OBJECTS_FILE, load_objects  # noqa: E402
from sim.water import Water  # noqa: E402
from sim.world import World  # noqa: E402
from cli_args import count, record_flag  # noqa: E402
from record import run_main  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current (--record)
from train.learning.sim_pool import cores  # noqa: E402


def episode() -> float:
    t0 = time.perf_counter()
    world = World(load_objects(DEFAULT_OBJECTS_FILE))
    build = time.perf_counter() - t0
    world.run_episode("red_light_cylinder")  # warm-up: first-call costs (IK graph, caches) out of the figure
    water_s, step = [0.0], Water.step

    def timed_step(self):
        t = time.perf_counter()
        step(self)
        water_s[0] += time.perf_counter() - t
    Water.step = timed_step
    steps0, t0 = world.steps, time.perf_counter()
    try:
        out = world.run_episode("red_heavy_cylinder")
    finally:
        Water.step = step
    steps = world.steps - steps0
    world._ik_memory.clear()   # asked afresh: palm_ik remembers the episode's own last goal check
    t0 = time.perf_counter()
    world.goal_reachable()
    reach = time.perf_counter() - t0
    import pybullet as p
    t0 = time.perf_counter()
    for _ in range(steps):   # the same scene, settled: pybullet's step alone
        p.stepSimulation(physicsClientId=world.client)
    bullet = time.perf_counter() - t0
    world.close()
    sim_s = steps * world.config.tank.timestep_s
    print(f"world build            {build:7.2f} s")
    print(f"episode                {out.wall_s:7.2f} s wall for {sim_s:.1f} s simulated ({steps} steps, "
          f"{1e3 * out.wall_s / steps:.2f} ms per step incl. IK, cameras and goal checks)")
    print(f"  water per step       {1e6 * water_s[0] / steps:7.1f} us (Water.step; pybullet's stepSimulation of the "
          f"settled scene: {1e6 * bullet / steps:.1f} us)")
    print(f"goal check             {1e3 * reach:7.1f} ms")
    print(f"observed {out.observed_cm3:.2f} cm^3, Archimedes {out.archimedes_cm3:.2f} cm^3, "
          f"felt {out.measurement['mass_g']:.1f} g, goal before/after {out.goal_reachable_before}/"
          f"{out.goal_reached_after}, settled {out.settled}")
    return out.wall_s


NINTH = {"name": "blue_heavy_sphere", "shape": "sphere", "color": "blue", "dims_cm": [5.5], "mass_g": 350}


def timed_run(tree: Path, out: Path, extra: list[str]) -> tuple[float, float]:
    """`python train/run.py EXTRA --out OUT` in `tree` (its own code): (wall s, s the run waited for its
    exploration's simulations, as it reports them)."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    t0 = time.perf_counter()
    log = subprocess.run([sys.executable, "train/run.py", *extra, "--out", str(out)], cwd=tree, env=env, check=False,
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if log.returncode != 0:
        print(log.stdout[-2000:], log.stderr[-2000:], sep="\n")
        raise SystemExit(f"train/run.py {' '.join(extra)} in {tree} failed with exit code {log.returncode}")
    sims = re.search(r"simulating .*: done in ([0-9.]+) s", log.stdout + log.stderr)
    return wall, float(sims.group(1)) if sims else float("nan")


def summary_differs(a: Path, b: Path) -> list[str]:
    """The top-level keys whose values differ between two runs' summary.json, but `commit` (which names the tree
    that wrote it): [] when they are the same (a `config` of another commit may hold keys added since)."""
    x, y = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    return sorted(k for k in x.keys() | y.keys() if k != "commit" and x.get(k) != y.get(k))


def side_by_side(what: str, extra: list[str], base: Path, commit: str, runs: int, tmp: Path) -> tuple[float, float]:
    """`runs` runs of this tree and of `base`, alternately: prints them, returns (median s here, median s base)."""
    names = ("this tree", commit)
    times = {n: [] for n in names}
    load = [os.getloadavg()[0]]   # the other jobs on the machine: the ratio depends on them
    for i in range(runs):
        for name, tree in zip(names, (ROOT, base)):
            times[name].append(timed_run(tree, tmp / f"{what}_{name.replace(' ', '_')}_{i}", extra))
            load.append(os.getloadavg()[0])
    differs = summary_differs(*(tmp / f"{what}_{n.replace(' ', '_')}_{runs - 1}" for n in names))
    med = {k: statistics.median(w for w, _ in v) for k, v in times.items()}
    sims = {k: statistics.median(s for _, s in v) for k, v in times.items()}
    print(f"{what} (python {' '.join(['train/run.py', *extra])}), {runs} runs each, alternately (1-minute load average "
          f"{min(load):.1f}-{max(load):.1f}); median wall (all runs), and of it the wait for the exploration's "
          f"simulations:")
    for name, v in times.items():
        print(f"  {name:10s} {med[name]:6.2f} s   ({', '.join(f'{w:.2f}' for w, _ in v)});   simulations "
              f"{sims[name]:5.2f} s   ({', '.join(f'{x:.2f}' for _, x in v)})")
    print(f"  speed-up {commit} / this tree: {med[commit] / med['this tree']:.2f}x (simulations "
          f"{sims[commit] / sims['this tree']:.2f}x); summary.json "
          + (f"differs in {', '.join(differs)}" if differs else "the same") + " (its commit aside)", flush=True)
    return med["this tree"], med[commit]


def against(commit: str, runs: int, nine_runs: int) -> dict:
    """{"default": (s, s base), "nine": (s, s base)} of the runs made (none when the commit is not available)."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = tmp / "base"
        add = subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base), commit], check=False,
                             capture_output=True, text=True)
        if add.returncode != 0:
            print(f"runs: baseline {commit} not available ({add.stderr.strip().splitlines()[-1:]}): skipped")
            return out
        try:
            out["default"] = side_by_side("default run", [], base, commit, runs, tmp)
            if nine_runs:
                spec = json.loads(Path(DEFAULT_OBJECTS_FILE).read_text())
                spec["train"].append(NINTH)
                nine = tmp / "nine.json"
                nine.write_text(json.dumps(spec))
                out["nine"] = side_by_side("9! orders", ["--objects", str(nine), "--orders", "all"], base, commit,
                                           nine_runs, tmp)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)], check=False,
                           capture_output=True)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", default="10e7246", help="commit to run the experiments against")
    ap.add_argument("--runs", type=count, default=3, help="default runs of each tree (medians)")
    ap.add_argument("--nine-runs", type=count, default=3, help="9! runs of each tree (medians)")
    ap.add_argument("--skip-nine", action="store_true", help="without the 9! runs")
    record_flag(ap)
    args = ap.parse_args()
    keep_freed_memory()   # freed tensors reused, for the peers in this process too (aesop_torch/malloc.py)
    torch.set_num_threads(1)   # as in the runner's workers
    print(f"{datetime.date.today()}, {cores()} cores, torch {torch.__version__}")
    episode()
    runs = against(args.baseline, args.runs, 0 if args.skip_nine else args.nine_runs)
    d, b = runs.get("default", (None, None))
    n, nb = runs.get("nine", (None, None))
    f = lambda x: "n/a" if x is None else f"{x:.2f}"
    print(f"default_s={f(d)} default_s_base={f(b)} nine_all_s={f(n)} nine_all_s_base={f(nb)} "
          f"ratio_default={f(d and b / d)} ratio_nine={f(n and nb / n)}")


if __name__ == "__main__":
    run_main("episode_speed", main)
