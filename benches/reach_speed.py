"""Reachability checks per second: our batched DLS IK (pytorch-kinematics) against pybullet's
calculateInverseKinematics and pk.PseudoInverseIK, like for like.

Matched: the targets (1,000 per seed, drawn uniformly from a box in front of the iCub, root frame, running past the
edge of its reach), the end point (pybullet's IK moves a link's origin and has no tool offset, so every peer row
targets the r_hand link origin, the wrist, and ours is built on the same link), the tolerance (1 cm, the world's
reach check: ours stops there, pybullet's residualThreshold is set to it, pk's pos_tolerance too), the iteration
cap (60 per start) and the starts: one (home) for all, then eight (home and the same seven random postures, tried in
turn until one succeeds). Success is judged the same way for every solver: FK of the returned joints within the
tolerance, every joint inside its limits. pybullet's IK starts from the arm's current joint state, so each of its
calls is preceded by setting that state, and followed (with 8 starts) by a check whether to try the next start:
its time counts the IK calls only (setting up and checking are free for it; ours does both inside its time).
Our palm (HAND_LINK, what the world uses) has no peer: no other solver here can target it.
Medians over SEEDS target sets x REPEATS repeats.

    .venv/bin/python benches/reach_speed.py [--record]

Last line: reach_speedup_1=X reach_speedup_8=Y (ours / pybullet, wrist, 1 and 8 starts). `--record` writes the
output into BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import datetime
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import pybullet as p
import pytorch_kinematics as pk
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from aesop_torch.malloc import keep_freed_memory  # noqa: E402

from sim.kinematics import ArmKinematics, IKConfig  # noqa: E402
from sim.robot import HAND_PARENT_LINK, load_icub, quiet_c_output  # noqa: E402
from cli_args import record_flag  # noqa: E402
from record import run_main  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current (--record)
from train.learning.sim_pool import cores  # noqa: E402

N_TARGETS = 1000
# Root frame (x backward, y right, z up): 15-45 cm in front, 15 cm left to 40 cm right, 20 cm below to 30 cm above
# the pelvis. The inner part is comfortably reachable, the far corners are not.
BOX_LO = (-0.45, -0.15, -0.20)
BOX_HI = (-0.15, 0.40, 0.30)
SEEDS, REPEATS = (0, 1, 2), 3
TOL = IKConfig().reach_tol


def targets(seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    lo, hi = torch.tensor(BOX_LO, dtype=torch.float64), torch.tensor(BOX_HI, dtype=torch.float64)
    return lo + torch.rand(N_TARGETS, 3, generator=g, dtype=torch.float64) * (hi - lo)


def fk_check(kin: ArmKinematics, q: torch.Tensor, tgt: torch.Tensor) -> torch.Tensor:
    """Success of a solution: inside the joint limits and FK within TOL of the target."""
    inside = ((q >= kin.lower - 1e-9) & (q <= kin.upper + 1e-9)).all(dim=1)
    pos, _ = kin.fk(q)
    return inside & ((pos - tgt).norm(dim=1) < TOL)


def quiet(fn, *args):
    with quiet_c_output():   # pybullet's C-level warnings
        return fn(*args)


def median_run(fn) -> tuple[float, torch.Tensor]:
    """fn() -> (seconds, success); the median seconds over REPEATS (after a warm-up) and the success."""
    fn()
    runs = [fn() for _ in range(REPEATS)]
    return statistics.median(r[0] for r in runs), runs[-1][1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    record_flag(ap)
    ap.parse_args()
    keep_freed_memory()   # freed tensors reused, for the peers in this process too (aesop_torch/malloc.py)
    torch.set_num_threads(1)
    print(f"{datetime.date.today()}, {cores()} cores, torch {torch.__version__}, 1 thread; {N_TARGETS} targets per "
          f"seed in box {BOX_LO}..{BOX_HI} (root frame, m), seeds {SEEDS}, {REPEATS} repeats; success = within "
          f"{TOL * 100:.0f} cm and inside the joint limits")
    one = replace(IKConfig(), restarts=0)
    ours = {1: ArmKinematics(config=one, end_link=HAND_PARENT_LINK), 8: ArmKinematics(end_link=HAND_PARENT_LINK)}
    palm = {1: ArmKinematics(config=one), 8: ArmKinematics()}
    kin = ours[8]
    g = torch.Generator().manual_seed(kin.config.seed)   # the restarts ours draws: lower + U(0, 1) x range
    starts = torch.cat([kin.home[None], kin.lower + torch.rand(kin.config.restarts, 10, generator=g,
                                                               dtype=torch.float64) * (kin.upper - kin.lower)])
    client = p.connect(p.DIRECT)
    robot = load_icub(client)   # base at the origin, identity: world frame = root frame
    lower, upper = robot.lower.tolist(), robot.upper.tolist()
    ranges, rest = [u - lo for lo, u in zip(lower, upper)], robot.home().tolist()

    def pybullet(tgt, n_starts):
        total, qs = 0.0, []
        for x in tgt.tolist():
            for s in starts[:n_starts].tolist():
                for j, v in zip(robot.arm_joints, s):   # its start: the current joint state (untimed)
                    p.resetJointState(robot.body, j, v, 0.0, physicsClientId=client)
                t = time.perf_counter()
                q = p.calculateInverseKinematics(robot.body, robot.hand_link, x, lowerLimits=lower,
                                                 upperLimits=upper, jointRanges=ranges, restPoses=rest,
                                                 maxNumIterations=kin.config.max_iters, residualThreshold=TOL,
                                                 physicsClientId=client)
                total += time.perf_counter() - t
                for j, v in zip(robot.arm_joints, q):   # did it get there? (untimed)
                    p.resetJointState(robot.body, j, v, 0.0, physicsClientId=client)
                at = p.getLinkState(robot.body, robot.hand_link, computeForwardKinematics=True,
                                    physicsClientId=client)[4]
                inside = all(lo - 1e-9 <= v <= hi + 1e-9 for v, lo, hi in zip(q, lower, upper))
                if inside and sum((a - b) ** 2 for a, b in zip(at, x)) < TOL * TOL:
                    break
            qs.append(q)
        return total, fk_check(kin, torch.tensor(qs, dtype=torch.float64), tgt)

    def pk_solver(tgt):
        limits = torch.stack([kin.lower, kin.upper], 1)
        solver = pk.PseudoInverseIK(kin.chain, retry_configs=starts, joint_limits=limits, pos_tolerance=TOL,
                                    rot_tolerance=1e9, orientation_weight=0.0,
                                    max_iterations=kin.config.max_iters, early_stopping_any_converged=True)
        goal = pk.Transform3d(pos=tgt, dtype=torch.float64)
        t = time.perf_counter()
        sol = solver.solve(goal)
        q = sol.solutions[torch.arange(N_TARGETS), sol.err_pos.argmin(dim=1)]
        return time.perf_counter() - t, fk_check(kin, q, tgt)

    def ours_run(k, tgt):
        t = time.perf_counter()
        res = k.ik(tgt, pos_tol=TOL)   # what k.reachable(tgt) does
        return time.perf_counter() - t, fk_check(k, res.q, tgt)

    rows: dict[str, list] = {}
    for seed in SEEDS:
        tgt = targets(seed)
        for n in (1, 8):
            for name, fn in ((f"ours (DLS), wrist, {n} start(s)", lambda: ours_run(ours[n], tgt)),
                             (f"pybullet calculateInverseKinematics, wrist, {n} start(s)",
                              lambda: quiet(pybullet, tgt, n))):
                rows.setdefault(name, []).append(median_run(fn))
        rows.setdefault("pk.PseudoInverseIK, wrist, 8 starts", []).append(median_run(lambda: pk_solver(tgt)))
        for n in (1, 8):
            rows.setdefault(f"ours (DLS), palm, {n} start(s) (no peer)", []).append(
                median_run(lambda: ours_run(palm[n], tgt)))
    p.disconnect(client)
    rate = {}
    for name, runs in rows.items():
        rate[name] = statistics.median(N_TARGETS / t for t, _ in runs)
        success = statistics.median(float(ok.float().mean()) for _, ok in runs)
        print(f"  {name:58s} {rate[name]:8.0f} checks/s   success {success:.3f}")
    s1 = rate["ours (DLS), wrist, 1 start(s)"] / rate["pybullet calculateInverseKinematics, wrist, 1 start(s)"]
    s8 = rate["ours (DLS), wrist, 8 start(s)"] / rate["pybullet calculateInverseKinematics, wrist, 8 start(s)"]
    print(f"  ours / pybullet, wrist targets, same tolerance: {s1:.2f}x with 1 start, {s8:.2f}x with 8 starts")
    print(f"reach_speedup_1={s1:.2f} reach_speedup_8={s8:.2f}")


if __name__ == "__main__":
    run_main("reach_speed", main)
