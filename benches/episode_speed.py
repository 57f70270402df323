"""The physics' speed: one headless drop episode, the water's share of a step, and the default run against a commit.

    python benches/episode_speed.py [--baseline COMMIT] [--runs N] [--record]

1. The world's build time, one drop episode (the paper's heavy red cylinder, pick to settle) and a goal check.
2. Per physics step of that episode: the water model (`Water.step`) beside pybullet's own `stepSimulation`.
3. `python train/run.py` (the default run, `make run`) of this tree beside the same command at --baseline (default
   19ce05e, before the physics was made faster), checked out by `git worktree` into a temporary directory: N runs
   each, alternately, so both see the same machine; median wall times and their ratio, the same for the run's wait
   for its 13 exploration simulations (as the run reports it: since the runner hands them to its workers before it
   opens its logs, the wait leaves out the part that overlaps), and whether summary.json is the same byte for byte
   (it is not against 19ce05e, which played no goal trials), with the 1-minute load average while they ran: the
   ratio depends on the machine's other jobs (19ce05e needs more CPU, so it loses more on a busy machine). Skipped
   (said so) when git or the commit is not available.
Printed, never asserted; the last line is `episode_wall_s=X run_ratio=Y`. `--record` writes the output into
BENCHMARKS.md.
"""

import argparse
import datetime
import filecmp
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


def default_run(tree: Path, out: Path) -> tuple[float, float]:
    """(wall s, s the run waited for its exploration's simulations, as it reports them)."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    t0 = time.perf_counter()
    log = subprocess.run([sys.executable, "train/run.py", "--out", str(out)], cwd=tree, env=env, check=True,
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    sims = re.search(r"simulating .*: done in ([0-9.]+) s", log.stdout + log.stderr)
    return wall, float(sims.group(1)) if sims else float("nan")


def against(commit: str, runs: int) -> float | None:
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        add = subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base), commit],
                             capture_output=True, text=True)
        if add.returncode != 0:
            print(f"default run: baseline {commit} not available ({add.stderr.strip().splitlines()[-1:]}): skipped")
            return None
        try:
            times = {"this tree": [], commit: []}
            load = [os.getloadavg()[0]]   # the other jobs on the machine: the ratio depends on them
            for i in range(runs):
                for name, tree in (("this tree", ROOT), (commit, base)):
                    times[name].append(default_run(tree, Path(tmp) / f"{name.replace(' ', '_')}_{i}"))
                    load.append(os.getloadavg()[0])
            same = filecmp.cmp(Path(tmp) / f"this_tree_{runs - 1}" / "summary.json",
                               Path(tmp) / f"{commit}_{runs - 1}" / "summary.json", shallow=False)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)], capture_output=True)
    med = {k: statistics.median(w for w, _ in v) for k, v in times.items()}
    sims = {k: statistics.median(s for _, s in v) for k, v in times.items()}
    ratio = med["this tree"] / med[commit]
    print(f"default run (python train/run.py), {runs} runs each, alternately (1-minute load average "
          f"{min(load):.1f}-{max(load):.1f}); median wall (all runs), and of it the wait for the exploration's "
          f"simulations (workers started, worlds built, 13 simulations):")
    for name, v in times.items():
        print(f"  {name:10s} {med[name]:6.2f} s   ({', '.join(f'{w:.2f}' for w, _ in v)});   simulations "
              f"{sims[name]:5.2f} s   ({', '.join(f'{x:.2f}' for _, x in v)})")
    print(f"  ratio this tree / {commit}: {ratio:.2f} (simulations {sims['this tree'] / sims[commit]:.2f}); "
          f"summary.json {'identical' if same else 'DIFFERS'}")
    return ratio


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", default="19ce05e", help="commit to run the default experiment against")
    ap.add_argument("--runs", type=count, default=3, help="default runs of each tree (medians)")
    record_flag(ap)
    args = ap.parse_args()
    keep_freed_memory()   # freed tensors reused, for the peers in this process too (aesop_torch/malloc.py)
    torch.set_num_threads(1)   # as in the runner's workers
    print(f"{datetime.date.today()}, {cores()} cores, torch {torch.__version__}")
    wall = episode()
    ratio = against(args.baseline, args.runs)
    print(f"episode_wall_s={wall:.3f} run_ratio={'n/a' if ratio is None else f'{ratio:.2f}'}")


if __name__ == "__main__":
    run_main("episode_speed", main)
