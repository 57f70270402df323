"""The iCub in pybullet: the official `icub-models` URDF, loaded fast and held in a fixed posture.

What loading the stock model takes, and what this module does about it:

- Meshes are `package://iCub/meshes/...`, relative to icub-models' `share` directory. We write a resolved copy of
  the URDF (absolute mesh paths) to a cache file outside the repo, named by a hash of the source and of what we
  changed, written atomically. (pybullet's search path would also find them, but it is one global per client and the
  world may point it at pybullet_data, so we do not rely on it.)
- 174 of the 213 links (skin patches, IMUs, force sensors, DH frames) have no <inertial>; pybullet gives each a
  default 1 kg, which adds ~174 kg of phantom mass, ~25 kg of it on the right forearm. We give them `phantom_mass_kg`.
- pybullet's getLinkState fails for every link of the stock model (212 links besides the base: more than its
  shared-memory state holds), so we always load with URDF_MERGE_FIXED_LINKS (32 links), which also halves the cost
  of a physics step. The palm frame
  HAND_LINK is a fixed frame, so it is merged into its parent `r_hand`; `Robot.hand_pose` adds the fixed offset back.
- Legs, head and left arm play no part in the task. With `freeze_body=True` (default) their joints are turned into
  fixed joints at the posture in `RobotConfig.body_posture` (baked into the URDF), and their collision shapes are
  dropped: 10 DOF instead of 32, and a physics step ~8x cheaper (~0.05 ms instead of ~0.38 ms for the bare robot).
  With `freeze_body=False` they stay joints and POSITION_CONTROL motors hold the same posture.
- Self-collision is off (pybullet's default without URDF_USE_SELF_COLLISION): the arm's own links never collide.
  Only the links in `RobotConfig.colliding_links` (pelvis, torso and the right arm) collide with the world.

Frames (root_link, the pelvis): x points BACKWARD, y to the robot's RIGHT, z UP; the robot faces -x. To face world
+x, use base orientation FACING_PLUS_X.

All joint vectors are float64 torch tensors in ARM_JOINTS order, radians.
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p
import torch

from sim.output_files import write_atomic
from sim.quiet import quiet_c_output  # noqa: F401  (re-exported: the world uses it)

ROBOT_MODEL = "iCubGazeboV2_5"
ROOT_LINK = "root_link"
# torso + right arm, root to hand: the chain the iCub reaches with (and pytorch-kinematics' serial chain).
ARM_JOINTS = ("torso_pitch", "torso_roll", "torso_yaw",
              "r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow",
              "r_wrist_prosup", "r_wrist_pitch", "r_wrist_yaw")
# iCub's own end-effector frame (what its Cartesian controller moves): the centre of the palm, a fixed frame on
# r_hand. This model has no finger joints, so the palm is where a held object sits.
HAND_LINK = "r_hand_dh_frame"
HAND_PARENT_LINK = "r_hand"  # the moving link HAND_LINK is merged into in pybullet
FACING_PLUS_X = (0.0, 0.0, 1.0, 0.0)  # xyzw, yaw by pi: root -x (the robot's front) onto world +x

_CACHE_VERSION = "1"  # bump when the URDF rewriting below changes, so stale cache files are not reused


@dataclass(frozen=True)
class RobotConfig:
    # Posture of everything outside the arm chain (radians; joints not listed are at 0, i.e. standing straight).
    # Left arm hanging at the side, abducted 20 deg so it clears the hip, elbow just above its 15 deg lower limit
    # (the straightest it goes); head pitched 0.5 rad down, towards the table in front.
    body_posture: tuple = (("l_shoulder_pitch", 0.0), ("l_shoulder_roll", 0.35), ("l_shoulder_yaw", 0.0),
                           ("l_elbow", 0.27), ("neck_pitch", -0.5))
    # A relaxed ready pose for the arm chain (ARM_JOINTS order): upper arm down and slightly forward, forearm
    # forward, palm facing inwards. Inside every limit (shoulder_roll and elbow have lower limits above 0).
    home_arm: tuple = (0.0, 0.0, 0.0, -0.3, 0.3, 0.0, 1.2, 0.0, 0.0, 0.0)
    # Motor torque limits (N m), ARM_JOINTS order; the URDF's 50000 is a placeholder. Round numbers, strongest at
    # the torso, weakest at the wrist: holding the heaviest allowed object (1 kg) palm down at arm's length takes
    # at most a quarter of each (measured: torso 11, shoulder 5, elbow 1.5, wrist 0.6 N m; tracking error < 1 mrad).
    arm_max_force: tuple = (100.0, 100.0, 100.0, 40.0, 40.0, 30.0, 20.0, 5.0, 5.0, 5.0)
    body_max_force: float = 100.0  # N m, holds the unfrozen legs/head/left arm (freeze_body=False only)
    # pybullet POSITION_CONTROL gains: kp 0.1 / kd 1 are pybullet's defaults, a stiff stable servo at 240 Hz.
    position_gain: float = 0.1
    velocity_gain: float = 1.0
    # rad/s per joint: slow enough not to fling a held object, fast enough that a reach takes a second or two of
    # simulated time.
    max_velocity: float = 1.0
    freeze_body: bool = True
    # Links that keep their collision shapes (the rest lose them): what can touch the table, stand and jar.
    colliding_links: tuple = ("root_link", "torso_1", "torso_2", "chest",
                              "r_shoulder_1", "r_shoulder_2", "r_shoulder_3", "r_upper_arm",
                              "r_elbow_1", "r_forearm", "r_wrist_1", "r_hand")
    # kg given to links the URDF leaves without <inertial> (pybullet's default would be 1 kg each): 0.1 g is
    # < 0.3 % of the lightest real link (r_wrist_1, 36 g), and not zero, which pybullet reads as "static".
    phantom_mass_kg: float = 1e-4


# ------------------------------------------------------------------------------------------------ URDF handling

def _source_urdf() -> tuple[Path, Path]:
    """(model.urdf of ROBOT_MODEL, the `share` directory its package:// paths are relative to)."""
    import icub_models
    src = Path(icub_models.get_model_file(ROBOT_MODEL))
    share = Path(icub_models.get_models_path()).parent.parent
    return src, share


def _rpy_to_matrix(rpy) -> np.ndarray:
    """URDF rpy (fixed-axis x, then y, then z): R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, pch, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(pch), math.sin(pch), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _matrix_to_rpy(m: np.ndarray) -> tuple[float, float, float]:
    pitch = math.atan2(-m[2, 0], math.hypot(m[0, 0], m[1, 0]))
    if math.cos(pitch) < 1e-9:  # gimbal lock: put everything in yaw
        return 0.0, pitch, math.atan2(-m[0, 1], m[1, 1])
    return math.atan2(m[2, 1], m[2, 2]), pitch, math.atan2(m[1, 0], m[0, 0])


def _axis_angle_matrix(axis, angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def _floats(text: str | None, n: int) -> list[float]:
    return [float(v) for v in text.split()] if text else [0.0] * n


def _rewrite(root: ET.Element, share: Path, config: RobotConfig | None) -> None:
    """Edit the parsed URDF in place: absolute mesh paths, small phantom masses; with `config`, keep only its
    colliding links' collision shapes and (freeze_body) turn the body's joints into fixed ones at its posture."""
    for mesh in root.iter("mesh"):
        name = mesh.get("filename", "")
        if name.startswith("package://"):
            mesh.set("filename", str(share / name[len("package://"):]))
    mass_default = RobotConfig.phantom_mass_kg if config is None else config.phantom_mass_kg
    inertia = f"{mass_default * 1e-4:.3e}"  # a 1 cm radius of gyration: tiny, positive, well-conditioned
    for link in root.findall("link"):
        if link.find("inertial") is None:
            inertial = ET.SubElement(link, "inertial")
            ET.SubElement(inertial, "origin", xyz="0 0 0", rpy="0 0 0")
            ET.SubElement(inertial, "mass", value=f"{mass_default:g}")
            ET.SubElement(inertial, "inertia", ixx=inertia, ixy="0", ixz="0", iyy=inertia, iyz="0", izz=inertia)
    if config is None:
        return
    keep = set(config.colliding_links)
    for link in root.findall("link"):
        if link.get("name") not in keep:
            for col in link.findall("collision"):
                link.remove(col)
    if not config.freeze_body:
        return
    posture = dict(config.body_posture)
    for joint in root.findall("joint"):
        name = joint.get("name")
        if joint.get("type") == "fixed" or name in ARM_JOINTS:
            continue
        # child frame at angle q = origin * Rot(axis, q): bake q into the origin and make the joint fixed.
        origin = joint.find("origin")
        if origin is None:
            origin = ET.SubElement(joint, "origin", xyz="0 0 0", rpy="0 0 0")
        axis = _floats(joint.find("axis").get("xyz") if joint.find("axis") is not None else "1 0 0", 3)
        rot = _rpy_to_matrix(_floats(origin.get("rpy"), 3)) @ _axis_angle_matrix(axis, posture.get(name, 0.0))
        origin.set("rpy", " ".join(f"{v:.17g}" for v in _matrix_to_rpy(rot)))
        joint.set("type", "fixed")
        for tag in ("axis", "limit", "dynamics", "safety_controller"):
            for el in joint.findall(tag):
                joint.remove(el)


def _cached_urdf(config: RobotConfig | None) -> Path:
    src, share = _source_urdf()
    text = src.read_bytes()
    key = hashlib.sha256(b"\0".join([_CACHE_VERSION.encode(), str(src).encode(), str(share).encode(), text,
                                     repr(config).encode()])).hexdigest()[:16]
    out_dir = Path(tempfile.gettempdir()) / "aesop_torch"
    out = out_dir / f"{ROBOT_MODEL}_{'sim' if config else 'full'}_{key}.urdf"
    if out.exists():
        return out
    root = ET.fromstring(text)
    _rewrite(root, share, config)
    out_dir.mkdir(parents=True, exist_ok=True)
    # atomic: a concurrent reader sees the old file or the whole new one
    write_atomic(out, ET.tostring(root, encoding="utf-8", xml_declaration=True))
    return out


def icub_urdf_path() -> Path:
    """The full iCub URDF (every joint movable) with absolute mesh paths: what kinematics reads. Cached."""
    return _cached_urdf(None)


def parsed_urdf(path: Path) -> ET.Element:
    """The parsed URDF at path, parsed once per process while the file is unchanged (~0.07 s for the iCub).
    Shared between callers: read it, never change it."""
    st = os.stat(path)
    return _parse(str(path), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=8)
def _parse(path: str, _mtime_ns: int, _size: int) -> ET.Element:
    return ET.parse(path).getroot()


def palm_offset(urdf_path: Path | None = None) -> tuple[tuple, tuple]:
    """(xyz, quat xyzw) of HAND_LINK in HAND_PARENT_LINK's frame, read from the URDF's fixed joint."""
    root = parsed_urdf(urdf_path or icub_urdf_path())
    for joint in root.findall("joint"):
        if joint.find("child").get("link") == HAND_LINK:
            if joint.find("parent").get("link") != HAND_PARENT_LINK or joint.get("type") != "fixed":
                raise ValueError(f"{HAND_LINK} is not a fixed child of {HAND_PARENT_LINK} in this URDF")
            origin = joint.find("origin")
            xyz = tuple(_floats(origin.get("xyz"), 3))
            return xyz, tuple(p.getQuaternionFromEuler(_floats(origin.get("rpy"), 3)))
    raise ValueError(f"no joint with child link {HAND_LINK} in the URDF")


# ------------------------------------------------------------------------------------------------------ Robot

def _as_q(q, n: int, what: str) -> torch.Tensor:
    q = torch.as_tensor(q, dtype=torch.float64).detach().cpu().reshape(-1)
    if q.numel() != n:
        raise ValueError(f"{what} must have {n} joint values (ARM_JOINTS order), got {q.numel()}")
    if not torch.isfinite(q).all():
        raise ValueError(f"{what} has non-finite values: {q.tolist()}")
    return q


class Robot:
    """A loaded iCub: body id, joint/link indices, arm limits, and the few calls the world makes on the arm."""

    def __init__(self, client_id: int, body: int, config: RobotConfig, palm: tuple[tuple, tuple]):
        self.client, self.body, self.config = client_id, body, config
        n = p.getNumJoints(body, physicsClientId=client_id)
        infos = [p.getJointInfo(body, i, physicsClientId=client_id) for i in range(n)]
        self.joint_index = {info[1].decode(): i for i, info in enumerate(infos)}  # joint name -> pybullet index
        self.link_index = {info[12].decode(): i for i, info in enumerate(infos)}  # child link name -> index
        self.link_index[ROOT_LINK] = -1
        self.arm_joints = tuple(self.joint_index[j] for j in ARM_JOINTS)
        self.hand_link = self.link_index[HAND_PARENT_LINK]
        self.palm_offset = palm
        self.lower = torch.tensor([infos[i][8] for i in self.arm_joints], dtype=torch.float64)
        self.upper = torch.tensor([infos[i][9] for i in self.arm_joints], dtype=torch.float64)
        self.max_force = torch.tensor(config.arm_max_force, dtype=torch.float64)
        if self.max_force.numel() != len(ARM_JOINTS):
            raise ValueError(f"RobotConfig.arm_max_force needs {len(ARM_JOINTS)} values, got {self.max_force.numel()}")

    def _check_limits(self, q: torch.Tensor, what: str) -> None:
        bad = (q < self.lower - 1e-6) | (q > self.upper + 1e-6)
        if bad.any():
            i = int(bad.nonzero()[0])
            raise ValueError(f"{what}: {ARM_JOINTS[i]}={q[i]:.4f} rad is outside "
                             f"[{self.lower[i]:.4f}, {self.upper[i]:.4f}]")

    def set_arm(self, q) -> None:
        """Teleport the arm to q (resetJointState) and hold it there. For setup and tests, not for acting."""
        q = _as_q(q, len(ARM_JOINTS), "set_arm q")
        self._check_limits(q, "set_arm q")
        for j, v in zip(self.arm_joints, q.tolist()):
            p.resetJointState(self.body, j, v, 0.0, physicsClientId=self.client)
        self.drive_arm(q)

    def arm_q(self) -> torch.Tensor:
        """Current arm joint angles (10,)."""
        states = p.getJointStates(self.body, self.arm_joints, physicsClientId=self.client)
        return torch.tensor([s[0] for s in states], dtype=torch.float64)

    def arm_torques(self) -> torch.Tensor:
        """Torques the arm motors applied in the last step (10,), N m: what the robot feels when it lifts."""
        states = p.getJointStates(self.body, self.arm_joints, physicsClientId=self.client)
        return torch.tensor([s[3] for s in states], dtype=torch.float64)

    def drive_arm(self, q_target, max_force=None, max_velocity: float | None = None) -> None:
        """Set the arm's POSITION_CONTROL motor targets; the motors move there as the world steps physics.

        max_force: None (config), a scalar, or 10 values (N m); max_velocity: rad/s per joint (None: config)."""
        q = _as_q(q_target, len(ARM_JOINTS), "drive_arm q_target")
        self._check_limits(q, "drive_arm q_target")
        force = self.max_force if max_force is None else torch.as_tensor(max_force, dtype=torch.float64).reshape(-1)
        if force.numel() not in (1, len(ARM_JOINTS)):
            raise ValueError(f"drive_arm max_force must be a scalar or {len(ARM_JOINTS)} values, got {force.numel()}")
        force = force.expand(len(ARM_JOINTS))
        vel = self.config.max_velocity if max_velocity is None else float(max_velocity)
        if vel <= 0 or (force < 0).any():
            raise ValueError(f"drive_arm needs max_velocity > 0 and max_force >= 0, got {vel} and {force.tolist()}")
        cfg = self.config
        for j, qt, f in zip(self.arm_joints, q.tolist(), force.tolist()):
            p.setJointMotorControl2(self.body, j, p.POSITION_CONTROL, targetPosition=qt, force=f,
                                    positionGain=cfg.position_gain, velocityGain=cfg.velocity_gain,
                                    maxVelocity=vel, physicsClientId=self.client)

    def hand_pose(self) -> tuple[torch.Tensor, torch.Tensor]:
        """World pose of the palm (HAND_LINK): (pos (3,), quat xyzw (4,)), from the link frame (not the inertial)."""
        s = p.getLinkState(self.body, self.hand_link, computeForwardKinematics=True, physicsClientId=self.client)
        pos, orn = p.multiplyTransforms(s[4], s[5], *self.palm_offset, physicsClientId=self.client)
        return torch.tensor(pos, dtype=torch.float64), torch.tensor(orn, dtype=torch.float64)

    def base_pose(self) -> tuple[torch.Tensor, torch.Tensor]:
        """World pose of root_link: (pos (3,), quat xyzw (4,)); maps kinematics' root frame into the world."""
        pos, orn = p.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
        return torch.tensor(pos, dtype=torch.float64), torch.tensor(orn, dtype=torch.float64)

    def home(self) -> torch.Tensor:
        """The config's ready pose for the arm (10,)."""
        return torch.tensor(self.config.home_arm, dtype=torch.float64)


def load_icub(client_id: int, base_position=(0.0, 0.0, 0.0), base_orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
              fixed_base: bool = True, config: RobotConfig | None = None) -> Robot:
    """Load the iCub into a pybullet client, body in its fixed posture and arm at `config.home_arm`, held by motors.

    base_position / base_orientation_xyzw place root_link (the pelvis) in the world."""
    config = config or RobotConfig()
    if len(tuple(base_position)) != 3 or len(tuple(base_orientation_xyzw)) != 4:
        raise ValueError("load_icub needs base_position (x, y, z) and base_orientation_xyzw (x, y, z, w)")
    names = dict(config.body_posture)
    limits = _joint_limits(icub_urdf_path())
    bad = sorted(n for n in names if n in ARM_JOINTS or n not in limits)
    if bad:
        raise ValueError(f"RobotConfig.body_posture must name movable non-arm joints of the model, got {bad}")
    for n, q in names.items():
        if not limits[n][0] <= q <= limits[n][1]:
            raise ValueError(f"RobotConfig.body_posture: {n}={q} rad is outside "
                             f"[{limits[n][0]:.4f}, {limits[n][1]:.4f}]")
    if len(config.home_arm) != len(ARM_JOINTS):
        raise ValueError(f"RobotConfig.home_arm needs {len(ARM_JOINTS)} values, got {len(config.home_arm)}")
    path = _cached_urdf(config)
    with quiet_c_output():
        body = p.loadURDF(str(path), list(base_position), list(base_orientation_xyzw), useFixedBase=fixed_base,
                          flags=p.URDF_MERGE_FIXED_LINKS, physicsClientId=client_id)
    if body < 0:
        raise ValueError(f"pybullet could not load {path}")
    robot = Robot(client_id, body, config, palm_offset(path))
    if not config.freeze_body:
        for name, idx in robot.joint_index.items():
            info = p.getJointInfo(body, idx, physicsClientId=client_id)
            if info[2] == p.JOINT_FIXED or name in ARM_JOINTS:
                continue
            q = names.get(name, 0.0)
            p.resetJointState(body, idx, q, 0.0, physicsClientId=client_id)
            p.setJointMotorControl2(body, idx, p.POSITION_CONTROL, targetPosition=q, force=config.body_max_force,
                                    positionGain=config.position_gain, velocityGain=config.velocity_gain,
                                    physicsClientId=client_id)
    robot.set_arm(robot.home())
    return robot


def _joint_limits(path: Path) -> dict[str, tuple[float, float]]:
    """Movable joint name -> (lower, upper) from the URDF."""
    return {j.get("name"): (float(j.find("limit").get("lower")), float(j.find("limit").get("upper")))
            for j in parsed_urdf(path).findall("joint") if j.get("type") in ("revolute", "prismatic")}
