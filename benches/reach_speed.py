"""Reachability checks per second: our batched DLS IK (pytorch-kinematics) against pk.PseudoInverseIK and pybullet.

1,000 targets drawn uniformly (fixed generator) from a box in front of the iCub, root frame, that runs past the
edge of its reach so that some targets are unreachable. A check succeeds when the hand gets within
IKConfig.reach_tol (1 cm) of the target, with every joint inside its limits, measured by FK of the returned
solution. pybullet's calculateInverseKinematics moves a link's origin and has no tool offset, so the comparison
with it targets the r_hand link origin (wrist) with our solver built on the same end link; our headline rate is
for the palm (HAND_LINK), what the world uses.

    .venv/bin/python benches/reach_speed.py [--threads N]

Last line: reach_checks_per_s=X (ours, palm targets).
"""

from __future__ import annotations

import argparse
import time

import pybullet as p
import pytorch_kinematics as pk
import torch

from sim.kinematics import ArmKinematics
from sim.robot import HAND_PARENT_LINK, load_icub, quiet_c_output
from record import recorded   # benches/record.py: keeps BENCHMARKS.md current

N_TARGETS = 1000
# Root frame (x backward, y right, z up): 15-45 cm in front, 15 cm left to 40 cm right, 20 cm below to 30 cm above
# the pelvis. The inner part is comfortably reachable, the far corners are not.
BOX_LO = (-0.45, -0.15, -0.20)
BOX_HI = (-0.15, 0.40, 0.30)
SEED = 0


def targets(n: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(SEED)
    lo, hi = torch.tensor(BOX_LO, dtype=torch.float64), torch.tensor(BOX_HI, dtype=torch.float64)
    return lo + torch.rand(n, 3, generator=g, dtype=torch.float64) * (hi - lo)


def timed(fn, repeats: int = 1):
    fn()  # warm-up (allocations, first-call paths)
    t = time.perf_counter()
    for _ in range(repeats):
        out = fn()
    return out, (time.perf_counter() - t) / repeats


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=1,
                    help="torch threads (1: on a shared 2-core machine, more threads mostly spin)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    tgt = targets(N_TARGETS)
    tol = ArmKinematics().config.reach_tol
    print(f"{N_TARGETS} targets in box {BOX_LO}..{BOX_HI} (root frame, m); success = within {tol * 100:.0f} cm, "
          f"inside joint limits; torch threads={args.threads}")

    # ours, palm: the figure the world relies on
    palm = ArmKinematics()
    ok, dt = timed(lambda: palm.reachable(tgt))
    rate_palm = N_TARGETS / dt
    report("ours (DLS on pk Jacobian), palm, float64", rate_palm, ok)
    palm32 = ArmKinematics(dtype=torch.float32)
    ok32, dt32 = timed(lambda: palm32.reachable(tgt.float()))
    report("ours, palm, float32", N_TARGETS / dt32, ok32)
    down = torch.tensor([[0.0, 0.0, -1.0]]).expand(N_TARGETS, 3)
    okd, dtd = timed(lambda: palm.reachable(tgt, target_normal=down))
    report("ours, palm facing down (-z), float64", N_TARGETS / dtd, okd)

    # wrist (r_hand origin): ours, pk.PseudoInverseIK and pybullet on the same targets
    wrist = ArmKinematics(end_link=HAND_PARENT_LINK)
    okw, dtw = timed(lambda: wrist.reachable(tgt))
    report("ours, wrist, float64", N_TARGETS / dtw, okw)

    g = torch.Generator().manual_seed(SEED)
    starts = torch.cat([wrist.home[None], wrist.lower + torch.rand(wrist.config.restarts, 10, generator=g,
                                                                   dtype=torch.float64) * (wrist.upper - wrist.lower)])
    # position only: orientation weighted 0 and any rotation error accepted; the same 8 starts for every target
    solver = pk.PseudoInverseIK(wrist.chain, retry_configs=starts,
                                joint_limits=torch.stack([wrist.lower, wrist.upper], 1),
                                pos_tolerance=wrist.config.pos_tol, rot_tolerance=1e9, orientation_weight=0.0,
                                max_iterations=wrist.config.max_iters, early_stopping_any_converged=True)
    goal = pk.Transform3d(pos=tgt, dtype=torch.float64)

    def pk_check():
        sol = solver.solve(goal)
        q = sol.solutions[torch.arange(N_TARGETS), sol.err_pos.argmin(dim=1)]
        return fk_check(wrist, q, tgt, tol)

    okp, dtp = timed(pk_check)
    report("pk.PseudoInverseIK (8 starts), wrist, float64", N_TARGETS / dtp, okp)

    client = p.connect(p.DIRECT)
    robot = load_icub(client)  # base at the origin, identity: world frame = root frame
    lower, upper = robot.lower.tolist(), robot.upper.tolist()
    ranges = [u - l for l, u in zip(lower, upper)]
    rest = robot.home().tolist()

    def pb_check():
        qs = []
        for x in tgt.tolist():
            robot.set_arm(robot.home())  # same start as ours: pybullet's IK starts from the current joint state
            # null-space IK with the joint limits, 100 iterations (pybullet's default is 20)
            qs.append(p.calculateInverseKinematics(robot.body, robot.hand_link, x, lowerLimits=lower,
                                                   upperLimits=upper, jointRanges=ranges, restPoses=rest,
                                                   maxNumIterations=100, residualThreshold=1e-4,
                                                   physicsClientId=client))
        return fk_check(wrist, torch.tensor(qs, dtype=torch.float64), tgt, tol)

    with quiet_c_output():
        okb, dtb = timed(pb_check)
    report("pybullet calculateInverseKinematics, wrist", N_TARGETS / dtb, okb)
    print(f"  ours (wrist) succeeds on {int((okw & ~okb).sum())} targets pybullet misses, "
          f"pybullet on {int((okb & ~okw).sum())} we miss")
    p.disconnect(client)
    print(f"reach_checks_per_s={rate_palm:.0f}")


def report(name: str, rate: float, ok: torch.Tensor) -> None:
    print(f"{name:46s} {rate:8.0f} checks/s   success {ok.float().mean():.3f}")


def fk_check(kin: ArmKinematics, q: torch.Tensor, tgt: torch.Tensor, tol: float) -> torch.Tensor:
    """Success of a solution: inside the joint limits and FK within tol of the target."""
    inside = ((q >= kin.lower - 1e-9) & (q <= kin.upper + 1e-9)).all(dim=1)
    pos, _ = kin.fk(q)
    return inside & ((pos - tgt).norm(dim=1) < tol)


if __name__ == "__main__":
    with recorded("reach_speed"):
        main()
