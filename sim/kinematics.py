"""Batched forward and inverse kinematics of the iCub's torso + right arm, on pytorch-kinematics.

The chain is root_link -> HAND_LINK (the palm) through the 10 joints of ARM_JOINTS, read from the same URDF that
pybullet loads, so FK here equals pybullet's link state (tests/test_kinematics.py checks to 1 mm / 1 degree).

IK is our own damped least squares on pytorch-kinematics' geometric Jacobian (`SerialChain.jacobian_tensor`), not
pk.PseudoInverseIK: pk's solver wants a full 6-D pose (we mostly want position only, or position plus "palm
down", which leaves the spin about the palm normal free), and it samples restarts from torch's global RNG. Ours
solves all targets from q0 as one batch, then the unsolved ones from random restarts as a second, retiring rows as
they converge or stall; it clamps each step to the joint limits (projected DLS) and draws the restarts from a local
torch.Generator. benches/reach_speed.py compares it with pk.PseudoInverseIK and pybullet on
the same 1,000 wrist targets: ~6-10x the speed of pk's solver with the same 8 starts, 94 % success against its 88 %
and pybullet's 65 % (ours finds every target either of them does).

Frames: everything is in the robot's ROOT frame (root_link: x backward, y to the robot's right, z up) unless a
function says world. Quaternions here are wxyz (pytorch-kinematics); pybullet's are xyzw: see `xyzw_to_wxyz`.
The palm frame: +z is the palm normal (out of the palm), +x runs from the wrist towards the fingers.
"""

from __future__ import annotations

import importlib.util
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import torch


def _unrun_package(name: str):
    """Register package `name` as it is, its __init__ not run yet: its first attribute nothing defines yet runs
    that __init__ (a submodule is imported as such), so `import name; name.X` works as ever, with the same module
    objects. None if it is imported already."""
    if name in sys.modules:
        return None
    spec = importlib.util.find_spec(name)
    if spec is None:
        raise ImportError(f"{name} is not installed (`make test` or `make run` installs it)")
    package = importlib.util.module_from_spec(spec)

    def rest(attr: str):
        if importlib.util.find_spec(f"{spec.name}.{attr}") is not None:   # a submodule: `from . import chain`
            return importlib.import_module(f"{spec.name}.{attr}")
        del package.__getattr__          # once: the __init__ defines what the package offers
        spec.loader.exec_module(package)
        return getattr(package, attr)
    package.__getattr__ = rest
    sys.modules[spec.name] = package
    return package


def _lazy_module(name: str) -> None:
    """Register module `name` to be executed at its first attribute access (importlib.util.LazyLoader)."""
    if name in sys.modules:
        return
    spec = importlib.util.find_spec(name)
    if spec is None:
        raise ImportError(f"{name} is not installed (`make test` or `make run` installs it)")
    spec.loader = importlib.util.LazyLoader(spec.loader)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    parent, _, child = name.rpartition(".")
    if parent:   # `from parent import child` finds it there, without the import system's look at it (which loads it)
        setattr(sys.modules[parent], child, module)


def _chain_modules():
    """pytorch-kinematics' URDF chain builder and rotation conversions, without running its package __init__ yet.

    That __init__ also imports its IK and SDF modules and, with them, matplotlib: 0.36 s of the package's 0.58 s
    import, on the critical path of every run (the runner imports the simulator before it forks its workers).
    Only the chain and the rotations are used here. Its transforms import arm_pytorch_utilities' linalg, whose
    import of scipy.linalg (and through it numpy.f2py and charset_normalizer) took another 0.46 s, for a function
    (batch_batch_product, Transform3d.transform_points) the simulator never calls: that module is loaded when it is
    first used, and arm_pytorch_utilities' __init__ (which imports it) when the package is first asked for a name."""
    _unrun_package("pytorch_kinematics")
    if _unrun_package("arm_pytorch_utilities") is not None:
        _lazy_module("arm_pytorch_utilities.linalg")
    from pytorch_kinematics.transforms import rotation_conversions
    from pytorch_kinematics.urdf import build_serial_chain_from_urdf
    return build_serial_chain_from_urdf, rotation_conversions


build_serial_chain_from_urdf, rc = _chain_modules()

from sim.robot import ARM_JOINTS, HAND_LINK, ROOT_LINK, RobotConfig, icub_urdf_path, parsed_urdf


@dataclass(frozen=True)
class IKConfig:
    # 1 mm: the hand must let go within a few mm of the jar's axis (sim/objects.py); DLS converges fast near a
    # solution, so 1 mm costs few iterations more than 1 cm.
    pos_tol: float = 1e-3
    # 2 degrees of palm orientation: a "palm down" hand tilted by 2 degrees drops an object just the same.
    rot_tol: float = 0.035
    # Reachability answers the task's "can the hand touch the ball?": 1 cm is well under the ball's size (a few cm),
    # so a palm that gets that close to the target point on it touches it, and 10x the IK's own 1 mm, so a target is
    # not called unreachable for a slow last millimetre. It counts a target up to 1 cm beyond the reach as reachable.
    reach_tol: float = 0.01
    # metres per radian: weighs orientation against position errors, so 0.1 rad of tilt costs like 1 cm.
    rot_weight: float = 0.1
    # Levenberg-Marquardt damping: lambda^2 = damping + lm * |e|^2. The constant (m^2; lambda = 3 cm) keeps steps
    # bounded at singularities (the straight arm); the error-proportional term damps large first steps and vanishes
    # at the end. On the bench box, 1e-3 / 1.0 miss no target a 40-restart, 300-iteration solve reaches (1e-4 and
    # 1e-5 miss 3-5 of 1000; lm 10 misses none either but is half as fast).
    damping: float = 1e-3
    lm_damping: float = 1.0
    # The torso's share of each step, relative to the arm's (weighted least-norm DLS): people and the iCub reach with
    # the arm and lean only for what it cannot do (0.5: torso angles -30 % against 1.0, no reach lost; 0.3 and
    # below start losing edge targets, measured on the bench box).
    torso_scale: float = 0.5
    # Task error clamp (m): a far target pulls like one 10 cm away in its direction, so the arm stretches towards
    # it at full speed instead of crawling under the LM damping of a 1 m error (and a failed target's answer is
    # the closest point the palm gets to).
    max_err: float = 0.1
    max_step: float = 0.3  # rad per joint per iteration: one step may not swing the arm through half its range
    # 60 iterations: 30 already lose no target of the bench box; 60 leave margin for starts far from the target.
    max_iters: int = 60
    check_every: int = 5  # retire solved and stalled rows from the batch every few iterations
    # A start whose error fell by less than 1 % over the last `check_every` iterations has stalled (against a joint
    # limit or the workspace's edge): it leaves the batch as failed, so unreachable targets cost little.
    stall_ratio: float = 0.01
    # Random restarts (uniform within limits) per target beside q0: targets near the workspace edge or behind a
    # joint limit from q0 need another start; 7 + q0 = 8 starts per target (measured: more gains < 0.5 % success).
    restarts: int = 7
    seed: int = 0  # for the restarts' local generator when the caller passes none


@dataclass
class IKResult:
    q: torch.Tensor         # (B, 10) best solution per target, within the joint limits
    pos_err: torch.Tensor   # (B,) metres
    rot_err: torch.Tensor   # (B,) radians (0 when no orientation was asked)
    success: torch.Tensor   # (B,) bool: pos_err < pos_tol and rot_err < rot_tol


def xyzw_to_wxyz(q: torch.Tensor) -> torch.Tensor:
    return torch.cat([q[..., 3:], q[..., :3]], dim=-1)


def wxyz_to_xyzw(q: torch.Tensor) -> torch.Tensor:
    return torch.cat([q[..., 1:], q[..., :1]], dim=-1)


def _kinematic_urdf(path: Path, end_link: str) -> str:
    """The links and joints from ROOT_LINK to end_link, nothing else: pk builds (and deep-copies) every frame it is
    given, ~0.5 s for the whole iCub against ~0.02 s for the chain, and its parser prints a line per <sensor> /
    <gazebo> tag. The chain's frames are the same either way. (Without a path to end_link, every link and joint:
    pk then says what is missing.)"""
    root = parsed_urdf(path)
    joints = root.findall("joint")
    parent = {j.find("child").get("link"): j for j in joints}
    keep, link = [], end_link
    while link != ROOT_LINK and link in parent:
        keep.append(parent[link])
        link = parent[link].find("parent").get("link")
    names = {ROOT_LINK, end_link} | {j.find("child").get("link") for j in keep}
    if link != ROOT_LINK:
        keep, names = joints, {el.get("name") for el in root.findall("link")}
    parts = [el for el in root.findall("link") if el.get("name") in names] + keep[::-1]
    return f'<robot name="{root.get("name")}">' + "".join(ET.tostring(el, encoding="unicode") for el in parts) + \
        "</robot>"


def _check_batch(x: torch.Tensor, width: int, what: str) -> None:
    if x.dim() != 2 or x.shape[1] != width:
        raise ValueError(f"{what} must have shape (B, {width}), got {tuple(x.shape)}")
    if not torch.isfinite(x).all():
        raise ValueError(f"{what} has non-finite values")


class ArmKinematics:
    """FK, Jacobian-based IK and reachability for the torso + right arm chain, batched over a leading dimension."""

    def __init__(self, urdf_path: str | Path | None = None, dtype: torch.dtype = torch.float64,
                 device: str | torch.device = "cpu", config: IKConfig | None = None, end_link: str = HAND_LINK):
        self.dtype, self.device, self.config = dtype, torch.device(device), config or IKConfig()
        text = _kinematic_urdf(Path(urdf_path) if urdf_path else icub_urdf_path(), end_link)
        self.chain = build_serial_chain_from_urdf(text, end_link, ROOT_LINK).to(dtype=dtype, device=self.device)
        names = tuple(self.chain.get_joint_parameter_names())
        if names != ARM_JOINTS:
            raise ValueError(f"chain {ROOT_LINK}->{end_link} has joints {names}, expected {ARM_JOINTS}")
        lo, hi = self.chain.get_joint_limits()
        self.lower = torch.tensor(lo, dtype=dtype, device=self.device)
        self.upper = torch.tensor(hi, dtype=dtype, device=self.device)
        self.home = torch.tensor(RobotConfig().home_arm, dtype=dtype, device=self.device)
        self._scale = torch.tensor([self.config.torso_scale] * 3 + [1.0] * 7, dtype=dtype, device=self.device)

    # ------------------------------------------------------------------------------------------------ FK
    def _q(self, q) -> torch.Tensor:
        q = torch.as_tensor(q, dtype=self.dtype, device=self.device)
        _check_batch(q, len(ARM_JOINTS), "q")
        return q

    def fk(self, q) -> tuple[torch.Tensor, torch.Tensor]:
        """q (B, 10) -> palm (pos (B, 3), quat_wxyz (B, 4)) in the root frame."""
        m = self.fk_matrix(self._q(q))
        return m[:, :3, 3], rc.matrix_to_quaternion(m[:, :3, :3])

    def fk_matrix(self, q: torch.Tensor) -> torch.Tensor:
        """q (B, 10), of this object's dtype and device -> palm pose as (B, 4, 4) matrices in the root frame."""
        return self.chain.forward_kinematics_tensor(q)[self.chain._serial_eef_frame_idx]

    def fk_frames(self, q) -> dict[str, torch.Tensor]:
        """Every frame of the chain (shoulder, elbow, wrist, ...) as name -> (B, 4, 4): for clearance checks."""
        return {name: t.get_matrix() for name, t in self.chain.forward_kinematics(self._q(q), end_only=False).items()}

    # ------------------------------------------------------------------------------------------------ IK
    def ik(self, target_pos, target_quat_wxyz=None, q0=None, target_normal=None,
           generator: torch.Generator | None = None, pos_tol: float | None = None) -> IKResult:
        """Joint angles putting the palm at target_pos (B, 3), root frame.

        Orientation is optional, one of: target_quat_wxyz (B, 4), the full palm orientation; target_normal (B, 3),
        only the direction the palm faces (its +z axis; (0, 0, -1) is "palm down"), spin about it left free.
        q0 (B, 10) or (10,): the start and preferred solution (default: home). Targets not solved from q0 are
        retried from `config.restarts` random configurations drawn from `generator` (default: a fresh one seeded
        config.seed), the same for every target, so a target's answer does not depend on the rest of the batch.
        The converged solution nearest q0 wins; failed targets return the start that got closest."""
        cfg = self.config
        tp = self._rows(target_pos, 3, "target_pos")
        B, n = tp.shape[0], len(ARM_JOINTS)
        if target_quat_wxyz is not None and target_normal is not None:
            raise ValueError("give target_quat_wxyz or target_normal, not both")
        tq = None if target_quat_wxyz is None else self._rows(target_quat_wxyz, 4, "target_quat_wxyz", B, unit=True)
        tn = None if target_normal is None else self._rows(target_normal, 3, "target_normal", B, unit=True)
        q0 = self.home if q0 is None else torch.as_tensor(q0, dtype=self.dtype, device=self.device)
        q0 = self._rows(q0.expand(B, n) if q0.dim() == 1 else q0, n, "q0", B)
        q0 = torch.minimum(torch.maximum(q0, self.lower), self.upper)
        pos_tol = cfg.pos_tol if pos_tol is None else float(pos_tol)
        if not pos_tol > 0:
            raise ValueError(f"pos_tol must be > 0 m, got {pos_tol}")
        if generator is None:
            generator = torch.Generator(device=self.device).manual_seed(cfg.seed)
        # one set of restarts shared by all targets: a target's answer does not depend on its batch-mates
        starts = self.lower + torch.rand(cfg.restarts, n, generator=generator, dtype=self.dtype,
                                         device=self.device) * (self.upper - self.lower)

        # candidates per target, (B, M) with M = 1 + restarts: column 0 from q0 (pass 1), the rest from the random
        # starts, run only for the targets pass 1 left unsolved (pass 2); candidates not run stay failed at inf
        M, idx = 1 + cfg.restarts, torch.arange(B, device=self.device)
        q = q0.unsqueeze(1).repeat(1, M, 1)
        pe = torch.full((B, M), float("inf"), dtype=self.dtype, device=self.device)
        re, ok = pe.clone(), torch.zeros(B, M, dtype=torch.bool, device=self.device)
        q[:, 0], pe[:, 0], re[:, 0], ok[:, 0] = self._solve(q0, idx, tp, tq, tn, pos_tol)
        todo = (~ok[:, 0]).nonzero().squeeze(1)
        if cfg.restarts and todo.numel():
            k = todo.numel()
            q2, pe2, re2, ok2 = self._solve(starts.repeat(k, 1), todo.repeat_interleave(cfg.restarts),
                                            tp, tq, tn, pos_tol)
            q[todo, 1:] = q2.reshape(k, cfg.restarts, n)
            pe[todo, 1:], re[todo, 1:], ok[todo, 1:] = (x.reshape(k, cfg.restarts) for x in (pe2, re2, ok2))
        # converged candidates ranked by distance from q0, the others after them by error
        rank = torch.where(ok, (q - q0.unsqueeze(1)).norm(dim=2), 1e6 + pe + cfg.rot_weight * re)
        best = rank.argmin(dim=1)
        return IKResult(q=q[idx, best], pos_err=pe[idx, best], rot_err=re[idx, best], success=ok[idx, best])

    def _rows(self, x, width: int, what: str, batch: int | None = None, unit: bool = False) -> torch.Tensor:
        x = torch.as_tensor(x, dtype=self.dtype, device=self.device)
        _check_batch(x, width, what)
        if batch is not None and x.shape[0] != batch:
            raise ValueError(f"{what} has {x.shape[0]} rows for {batch} targets")
        if unit:
            norm = x.norm(dim=1, keepdim=True)
            if (norm < 1e-9).any():
                raise ValueError(f"{what} has a zero row; it must be a direction / unit quaternion")
            x = x / norm
        return x

    @torch.no_grad()
    def _solve(self, q, pid, tp, tq, tn, pos_tol):
        """Projected DLS on rows q (R, n) for targets pid (R,). A row leaves the batch once it or another row of
        its target converges, or once it stalls; returns per row (q, pos_err, rot_err, converged)."""
        cfg = self.config
        R = q.shape[0]
        out_q, out_pe = q.clone(), torch.full((R,), float("inf"), dtype=self.dtype, device=self.device)
        out_re, out_ok = out_pe.clone(), torch.zeros(R, dtype=torch.bool, device=self.device)
        best = out_pe.clone()
        solved = torch.zeros(tp.shape[0], dtype=torch.bool, device=self.device)
        act = torch.arange(R, device=self.device)
        t_p, t_q, t_n = tp[pid], None if tq is None else tq[pid], None if tn is None else tn[pid]
        eye = torch.eye(3 if (tq is None and tn is None) else 6, dtype=self.dtype, device=self.device)
        for it in range(cfg.max_iters + 1):
            J, m = self.chain.jacobian_tensor(q, True)
            e, Jt, pe, re = self._task(J, m, t_p, t_q, t_n)
            if it % cfg.check_every == 0 or it == cfg.max_iters:
                ok = (pe < pos_tol) & (re < cfg.rot_tol)
                err = pe + cfg.rot_weight * re
                stalled = err > best[act] * (1.0 - cfg.stall_ratio)  # never true at the first check (best = inf)
                best[act] = torch.minimum(best[act], err)
                solved[pid[act[ok]]] = True
                leave = ok | solved[pid[act]] | stalled | (it == cfg.max_iters)
                rows = act[leave]
                out_q[rows], out_pe[rows], out_re[rows], out_ok[rows] = q[leave], pe[leave], re[leave], ok[leave]
                keep = ~leave
                if not keep.any():
                    break
                act, q, e, Jt, t_p = act[keep], q[keep], e[keep], Jt[keep], t_p[keep]
                t_q = None if t_q is None else t_q[keep]
                t_n = None if t_n is None else t_n[keep]
            e = e * (cfg.max_err / e.norm(dim=1, keepdim=True).clamp_min(1e-12)).clamp(max=1.0)
            lam = cfg.damping + cfg.lm_damping * (e * e).sum(dim=1)[:, None, None]
            Js = Jt * self._scale  # weighted least norm: a joint with scale s moves like one s times "stiffer"
            A = Js @ Js.transpose(1, 2) + lam * eye
            dq = (Js.transpose(1, 2) @ torch.linalg.solve(A, e.unsqueeze(2))).squeeze(2) * self._scale
            scale = (cfg.max_step / dq.abs().amax(dim=1, keepdim=True).clamp_min(1e-12)).clamp(max=1.0)
            q = torch.minimum(torch.maximum(q + dq * scale, self.lower), self.upper)
        return out_q, out_pe, out_re, out_ok

    def _task(self, J, m, tp, tq, tn):
        """Task error e, task Jacobian (weighted), position error norm and orientation error angle."""
        cfg = self.config
        e_pos = tp - m[:, :3, 3]
        pe = e_pos.norm(dim=1)
        if tq is None and tn is None:
            return e_pos, (None if J is None else J[:, :3]), pe, torch.zeros_like(pe)
        if tq is not None:
            diff = rc.quaternion_multiply(tq, rc.quaternion_invert(rc.matrix_to_quaternion(m[:, :3, :3])))
            diff = diff * torch.where(diff[:, :1] < 0, -1.0, 1.0)  # the short way round (angle <= pi)
            e_rot = rc.quaternion_to_axis_angle(diff)  # rotation taking the palm onto the target, root frame
            Jr = None if J is None else J[:, 3:]
        else:
            z = m[:, :3, 2]
            c = torch.cross(z, tn, dim=1)
            ang = torch.atan2(c.norm(dim=1), (z * tn).sum(dim=1))
            e_rot = c / c.norm(dim=1, keepdim=True).clamp_min(1e-12) * ang.unsqueeze(1)
            # spin about the palm normal does not move the normal: drop that direction from the task
            Jr = None if J is None else J[:, 3:] - z.unsqueeze(2) * (z.unsqueeze(1) @ J[:, 3:])
        re = e_rot.norm(dim=1)
        e = torch.cat([e_pos, cfg.rot_weight * e_rot], dim=1)
        Jt = None if J is None else torch.cat([J[:, :3], cfg.rot_weight * Jr], dim=1)
        return e, Jt, pe, re

    def reachable(self, target_pos, tol: float | None = None, target_normal=None, q0=None,
                  generator: torch.Generator | None = None) -> torch.Tensor:
        """(B,) bool: IK brings the palm within `tol` (default config.reach_tol) of each target."""
        tol = self.config.reach_tol if tol is None else tol
        return self.ik(target_pos, q0=q0, target_normal=target_normal, generator=generator, pos_tol=tol).success


# ---------------------------------------------------------------------------------------------- frames

def _rotate(quat_wxyz: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    return (rc.quaternion_to_matrix(quat_wxyz) @ v.unsqueeze(-1)).squeeze(-1)


def root_to_world(pos, quat_wxyz, base_pos, base_quat_xyzw) -> tuple[torch.Tensor, torch.Tensor]:
    """Root-frame pose(s) -> world, given the robot's base pose as pybullet reports it (xyzw)."""
    pos = torch.as_tensor(pos)
    bp = torch.as_tensor(base_pos, dtype=pos.dtype, device=pos.device)
    bq = xyzw_to_wxyz(torch.as_tensor(base_quat_xyzw, dtype=pos.dtype, device=pos.device))
    out_pos = bp + _rotate(bq.expand(pos.shape[:-1] + (4,)), pos)
    out_q = None if quat_wxyz is None else rc.quaternion_multiply(bq, torch.as_tensor(quat_wxyz, dtype=pos.dtype))
    return out_pos, out_q


def world_to_root(pos, quat_wxyz, base_pos, base_quat_xyzw) -> tuple[torch.Tensor, torch.Tensor]:
    """World pose(s) -> the robot's root frame (what `ArmKinematics.ik` takes)."""
    pos = torch.as_tensor(pos)
    bp = torch.as_tensor(base_pos, dtype=pos.dtype, device=pos.device)
    inv = rc.quaternion_invert(xyzw_to_wxyz(torch.as_tensor(base_quat_xyzw, dtype=pos.dtype, device=pos.device)))
    out_pos = _rotate(inv.expand(pos.shape[:-1] + (4,)), pos - bp)
    out_q = None if quat_wxyz is None else rc.quaternion_multiply(inv, torch.as_tensor(quat_wxyz, dtype=pos.dtype))
    return out_pos, out_q
