"""The scene: an iCub at a table with a stand for the objects, a glass jar of water and a floating green ball.

Layout (world frame, metres; the robot stands at the origin facing +x, its right arm on the -y side):

    table top 0.40 m high; stand (a short pedestal) at the robot's right, jar at its left front.

The goal "reach the green ball" (`World.goal_reachable`): IK (sim.kinematics, palm facing down) puts the palm on
the ball's top, and at that pose no robot link penetrates the jar (checked in a scratch state with
p.getClosestPoints). The iCub's hand cannot go into the jar: its collision hull is 13 cm across and 5 cm thick
(icub-models' r_hand), the mouth 12 cm. So the ball is reachable once its top floats up to the rim: measured over
ball positions across the jar, from 0-2 mm below the rim on. That is the threshold. With the default jar (12 cm
wide, 19.5 cm tall, 14 cm of water) and the 4 cm ping-pong ball (0.7 cm draft) the ball's top starts 2.2 cm below
the rim, so a rise of 2.0-2.2 cm (230-250 cm^3 displaced) makes it reachable: the paper's heavy cylinder
(365 cm^3, +3.2 cm) does, with 1 cm to spare; a 14 g float (+0.1 cm) never does; every other default object stays
at least 0.8 cm short.

The observed displacement is what the robot reads off the jar: (level once settled - level before) x the jar's
cross-section, the level read to `level_resolution_cm` (0.01 mm: 0.11 cm^3 in the default jar, under 1 % of the
smallest default displacement, 14 cm^3) plus optional gaussian noise from the world's own numpy Generator.
"""

from __future__ import annotations

import math
import os
import sys
import time
import zlib
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import pybullet as p
import torch

from sim.kinematics import ArmKinematics, IKConfig, world_to_root
from sim.objects import ObjectSet, ObjectSpec, ObjectsConfig
from sim.perception import CameraConfig, Percept, Workspace, look
from sim.robot import FACING_PLUS_X, RobotConfig, load_icub, quiet_c_output
from sim.sensor_model import SensorModel
from sim.errors import WorldBuildError
from sim.water import CM, G, Tank, TankConfig


@dataclass
class WorldConfig:
    tank: TankConfig = field(default_factory=TankConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    ik: IKConfig = field(default_factory=IKConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    # the iCub's pelvis 0.6 m up puts its feet on the floor; facing +x
    robot_base: tuple = (0.0, 0.0, 0.6)
    # a table at the robot's hip: the jar's rim (0.61 m) is then just below the shoulder (0.78 m), where the palm
    # reaches it from above with the elbow bent.
    table_top_z: float = 0.40
    table_x: tuple = (0.12, 0.55)        # the front edge clears the robot's pelvis (x <= 0.05)
    table_y: tuple = (-0.42, 0.30)
    table_thickness: float = 0.03
    # jar at the left front, clear of the arm's rest pose (palm at 0.28, -0.14); stand at the right, as far from
    # the jar as from the robot, so a held object never swings over the rim on the way.
    jar_xy: tuple = (0.27, 0.06)
    stand_xy: tuple = (0.20, -0.25)
    stand_height: float = 0.06
    stand_radius: float = 0.045
    # the ball starts floating against the far wall (seen from the robot) with this gap; objects are dropped
    # centred in the room left beside it, so they never land on it (sim/objects.py checks they fit).
    ball_gap_cm: float = 0.1
    # the hand's collision hull reaches 1.3 cm below the palm frame along the palm normal (icub-models' r_hand
    # mesh): the palm frame sits this far above whatever the palm rests on.
    palm_face_cm: float = 1.3
    grasp_gap_cm: float = 0.2            # the palm stops 2 mm above the object's top when it takes it
    hover_cm: float = 6.0                # approach and retreat from this far above
    # per straight palm move: the motors go joint-space between IK waypoints, so the palm sags between them; with
    # 8 the 31 cm carry from the stand to the jar stays within ~2 cm of the line (measured), hence the clearance.
    waypoints: int = 8
    carry_clearance_cm: float = 4.0      # a carried object's bottom passes this far above the rim
    joint_tol_rad: float = 0.004         # a move is done when every joint is this close (~1 mm at the palm)
    via_tol_rad: float = 0.05            # passing tolerance at intermediate waypoints
    move_timeout_s: float = 4.0
    # weighing: hold still for weigh_wait_steps (the lift's last few mm/s die out: 0.15 s brings the felt load
    # within 0.05 g of m g), then average the load over weigh_steps
    weigh_wait_steps: int = 36
    weigh_steps: int = 24
    # a wrist force/torque sensor reads ~0.01 N: 1 g of noise on the felt mass (0 for exact readings)
    mass_noise_g: float = 1.0
    # the least weight the hand reports: the noise would make a light object's felt mass zero or negative, which a
    # hand never feels (the same floor as the no-physics paths', SensorModel.min_felt_mass_g, which says why)
    min_felt_mass_g: float = SensorModel.min_felt_mass_g
    level_resolution_cm: float = 0.001   # see the module docstring
    level_noise_cm: float = 0.0


# Opens the X display named by DISPLAY in a child process: exit 0 it opened, 3 no libX11, 4 no X server answered.
_X_PROBE = """
import ctypes, ctypes.util, sys
try:
    x = ctypes.CDLL("libX11.so.6")
except OSError:
    try:
        x = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so")
    except OSError:
        sys.exit(3)
x.XOpenDisplay.restype = ctypes.c_void_p
x.XOpenDisplay.argtypes = [ctypes.c_char_p]
sys.exit(0 if x.XOpenDisplay(None) else 4)
"""
# palm_ik's answers kept (oldest out first): a drop asks ~7 questions; 256 hold every question of many drops in
# a few MB, so the questions that recur (the goal check from the ball at rest) are found
IK_MEMORY = 256
X_PROBE_TIMEOUT_S = 10.0   # a local X server answers in milliseconds; a remote one that never answers must not hang


def gui_unavailable() -> str | None:
    """Why pybullet's GUI cannot open here, or None. Without an X server pybullet does not fail: it hangs, deaf to
    Ctrl-C, so the display is opened first in a child process that a timeout can end."""
    if not sys.platform.startswith("linux"):
        return None
    display = os.environ.get("DISPLAY")
    headless = "(without --gui the world runs headless)"
    if not display:
        return f"the pybullet GUI needs an X display and DISPLAY is not set {headless}"
    import subprocess
    try:
        code = subprocess.run([sys.executable, "-c", _X_PROBE], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, timeout=X_PROBE_TIMEOUT_S).returncode
    except subprocess.TimeoutExpired:
        return f"the X server of DISPLAY={display!r} did not answer within {X_PROBE_TIMEOUT_S:g} s {headless}"
    if code == 3:
        return f"the pybullet GUI needs libX11, which this machine does not have {headless}"
    if code != 0:
        return f"no X server answers at DISPLAY={display!r} {headless}"
    return None


def _palm_down_root() -> torch.Tensor:
    """The palm normal pointing down, in the robot's root frame (its z is up, like the world's)."""
    return torch.tensor([[0.0, 0.0, -1.0]], dtype=torch.float64)


class World:
    """The pybullet scene for one ObjectSet; `run_episode` drops an object, `inspect` lifts and weighs one."""

    def __init__(self, objects: ObjectSet, config: WorldConfig | None = None, gui: bool = False, seed: int = 0):
        self.objects = objects
        self.config = c = config or WorldConfig()
        ball_room = objects.jar.inner_diameter_cm - c.tank.ball_diameter_cm - 2 * ObjectsConfig.fit_clearance_cm
        for o in objects.train + objects.probe:
            if o.footprint_cm > ball_room + 1e-9:
                raise ValueError(f"object '{o.name}' does not fit beside the world's {c.tank.ball_diameter_cm} cm "
                                 f"ball in the jar (footprint {o.footprint_cm:.2f} cm > {ball_room:.2f} cm)")
        if c.table_top_z <= 0 or c.stand_height <= 0:
            raise ValueError("table_top_z and stand_height must be > 0")
        self.seed = seed
        self.rng = np.random.default_rng(seed)   # re-seeded per episode from (seed, object name): see reset()
        self.gui = gui
        if gui and (why := gui_unavailable()):
            raise RuntimeError(why)
        self.client = p.connect(p.GUI if gui else p.DIRECT)
        self.kin = ArmKinematics(config=c.ik)
        self._ik_memory = {}   # palm_ik's answers by question
        self.steps = 0
        self.recorder = None
        self._build()

    # -- scene -------------------------------------------------------------------------------------------------
    def _build(self):
        """The whole scene from scratch: robot, floor, table, stand, jar with water and ball."""
        c, cl = self.config, self.client
        p.resetSimulation(physicsClientId=cl)
        self.held = None          # (body, constraint id) while the hand holds an object
        self.body = None          # the episode's object on the stand / in the jar
        with quiet_c_output():
            self.robot = load_icub(cl, base_position=c.robot_base, base_orientation_xyzw=FACING_PLUS_X,
                                   config=c.robot)
        self.base_pos, self.base_quat = self.robot.base_pose()
        floor = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cl)
        floor_vis = p.createVisualShape(p.GEOM_BOX, halfExtents=[1.5, 1.5, 0.001], rgbaColor=[0.82, 0.82, 0.8, 1],
                                        physicsClientId=cl)
        self._underneath = [p.createMultiBody(0, floor, floor_vis, [0, 0, 0], physicsClientId=cl)]
        x0, x1 = c.table_x
        y0, y1 = c.table_y
        half = [(x1 - x0) / 2, (y1 - y0) / 2, c.table_thickness / 2]
        self.table = p.createMultiBody(
            0, p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cl),
            p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[0.62, 0.45, 0.3, 1], physicsClientId=cl),
            [(x0 + x1) / 2, (y0 + y1) / 2, c.table_top_z - c.table_thickness / 2], physicsClientId=cl)
        legs = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.02, 0.02, (c.table_top_z - c.table_thickness) / 2],
                                   rgbaColor=[0.5, 0.36, 0.24, 1], physicsClientId=cl)
        for x in (x0 + 0.03, x1 - 0.03):
            for y in (y0 + 0.03, y1 - 0.03):
                self._underneath.append(p.createMultiBody(0, -1, legs, [x, y, (c.table_top_z - c.table_thickness) / 2],
                                                          physicsClientId=cl))
        self._underneath.append(self.table)   # the floor, the legs and the table: nothing of them above its top
        self.stand_top = c.table_top_z + c.stand_height
        self.stand = p.createMultiBody(
            0, p.createCollisionShape(p.GEOM_CYLINDER, radius=c.stand_radius, height=c.stand_height,
                                      physicsClientId=cl),
            p.createVisualShape(p.GEOM_CYLINDER, radius=c.stand_radius, length=c.stand_height,
                                rgbaColor=[0.35, 0.35, 0.38, 1], physicsClientId=cl),
            [c.stand_xy[0], c.stand_xy[1], c.table_top_z + c.stand_height / 2], physicsClientId=cl)
        p.changeDynamics(self.stand, -1, lateralFriction=0.8, physicsClientId=cl)  # a rubber top: nothing slides
        self.tank = Tank(cl, self.objects.jar, c.jar_xy, c.table_top_z, c.tank)
        # unit vector from the robot to the jar: the ball floats at the far wall, objects drop on the near side
        away = np.asarray(c.jar_xy, dtype=float) - np.asarray(c.robot_base[:2], dtype=float)
        self.away = away / np.linalg.norm(away)
        self.home_q = self.robot.home()
        p.resetBasePositionAndOrientation(self.tank.ball, self.ball_start_pos(), [0, 0, 0, 1], physicsClientId=cl)
        self.tank.water.update_level()
        self.tank.sync_visuals()
        if self.gui:
            p.resetDebugVisualizerCamera(1.1, 130, -25, [0.2, -0.05, 0.55], physicsClientId=cl)
        # the robot's colour per visual shape, read once: changeVisualShape overwrites what getVisualShapeData
        # reports for every shape of a link, so after a hide it no longer tells the colours apart
        self._robot_colours, seen = [], {}
        for shape in p.getVisualShapeData(self.robot.body, physicsClientId=cl):
            link = shape[1]
            seen[link] = seen.get(link, -1) + 1
            self._robot_colours.append((link, seen[link], shape[7]))
        self._underneath = [(b, p.getVisualShapeData(b, physicsClientId=cl)[0][7]) for b in self._underneath]
        self._scene = set(self._body_ids())
        self._ungrasped = set()   # bodies whose collisions with the robot grasp() switched off
        self._saved = p.saveState(physicsClientId=cl)

    def _body_ids(self) -> list[int]:
        cl = self.client
        return [p.getBodyUniqueId(i, physicsClientId=cl) for i in range(p.getNumBodies(physicsClientId=cl))]

    def _restore(self):
        """The scene as `_build` left it, without rebuilding it (loading the robot is most of a build's ~0.3 s):
        every constraint and body added since removed, newest first, the saved state restored (p.restoreState:
        poses, velocities, contacts), and what it does not hold set again as `_build` set it (the arm's motors,
        the water's level). tests/test_world.py checks that an episode then ends bit for bit as in a new world."""
        cl = self.client
        for i in reversed(range(p.getNumConstraints(physicsClientId=cl))):
            p.removeConstraint(p.getConstraintUniqueId(i, physicsClientId=cl), physicsClientId=cl)
        self.held = None
        for bid in sorted(set(self._body_ids()) - self._scene, reverse=True):
            self._remove(bid)
        self.body = None
        p.restoreState(self._saved, physicsClientId=cl)
        self.robot.set_arm(self.home_q)
        self.tank.water.reset_level()
        self.tank.water.update_level()
        self.tank.sync_visuals()

    def _remove(self, bid: int):
        """Take a body out of the scene and the water. pybullet keeps collision filters by body id and gives the
        next new body this one's id, so the robot's collisions with it, switched off by `grasp`, go back on."""
        cl, rob = self.client, self.robot.body
        if bid in self._ungrasped:
            self._ungrasped.discard(bid)
            for link in range(-1, p.getNumJoints(rob, physicsClientId=cl)):
                p.setCollisionFilterPair(rob, bid, link, -1, 1, physicsClientId=cl)
        self.tank.water.remove_body(bid)
        p.removeBody(bid, physicsClientId=cl)

    def close(self):
        if self.client is not None and p.isConnected(self.client):
            p.disconnect(self.client)
        self.client = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    def spec(self, name: str) -> ObjectSpec:
        return self.objects.get(name)

    def ball_start_pos(self) -> list:
        """The ball floating at rest against the jar's far wall (seen from the robot), `ball_gap_cm` from it."""
        c, jar = self.config, self.objects.jar
        r_off = (jar.inner_diameter_cm - c.tank.ball_diameter_cm) / 2 - c.ball_gap_cm
        pos = self.tank.ball_rest_pos()
        return [pos[0] + self.away[0] * r_off * CM, pos[1] + self.away[1] * r_off * CM, pos[2]]

    def drop_xy(self) -> np.ndarray:
        """Where a dropped object's centre is aimed: the middle of the room beside the ball."""
        c = self.config
        off = (c.tank.ball_diameter_cm + c.ball_gap_cm) / 2 * CM
        return np.asarray(c.jar_xy, dtype=float) - self.away * off

    def reset(self, name: str | None = None):
        """Water back to its start level, the ball back against the far wall, the arm home, no object out.

        The scene goes back to the state saved when it was built (`_restore`, a few ms), so an outcome does not
        depend on which objects went before (presentation orders, --resume). With `name`, the sensor noise is
        re-seeded from (seed, name) for the same reason: each object's episode is then a function of the seed and
        the object alone, bit for bit.
        """
        self._restore()
        if name is not None:
            self.seed_noise(name)

    def seed_noise(self, name: str) -> None:
        """The sensor noise of the named object's drop, seeded from (seed, name): the same whatever went before."""
        self.rng = np.random.default_rng([self.seed, zlib.crc32(name.encode())])

    def place_on_stand(self, name: str, orientation=(0.0, 0.0, 0.0, 1.0)) -> int:
        """Create the named object on the stand, resting on it, in `orientation` (xyzw; default upright and
        unrotated: as its dims describe it); returns its body id."""
        return self.place_object(self.spec(name), orientation)

    def place_object(self, spec: ObjectSpec, orientation=(0.0, 0.0, 0.0, 1.0)) -> int:
        """`place_on_stand` for any ObjectSpec (benches and tests put generated objects on the stand this way):
        its lowest point on the stand's top, centred on the stand's axis."""
        if self.body is not None:
            raise RuntimeError("an object is already out; reset() first")
        rot = np.asarray(p.getMatrixFromQuaternion(list(orientation)), dtype=float).reshape(3, 3)
        half_z = 0.5 * spec.size_xyz_cm * CM @ np.abs(rot[2])   # the rotated box's half height
        if spec.shape == "sphere":
            half_z = spec.size_xyz_cm[0] * CM / 2
        pos = [self.config.stand_xy[0], self.config.stand_xy[1], self.stand_top + half_z]
        self.body = self.tank.add_object(spec, pos, orientation)
        return self.body

    def remove_object(self):
        """Take the object out of the scene (benches measure many objects in one world)."""
        if self.held is not None:
            self.release()
        if self.body is not None:
            self._remove(self.body)
            self.body = None

    # -- stepping ----------------------------------------------------------------------------------------------
    def _after_step(self, _i=None):
        self.steps += 1
        if self.recorder is not None:
            self.recorder.on_step(self)
        if self.gui:  # let a person watch: the water's look follows the level, at about real time
            self.tank.sync_visuals()
            time.sleep(self.config.tank.timestep_s)

    def step(self, n: int = 1):
        for _ in range(n):
            self.tank.step()
            self._after_step()

    def settle(self) -> bool:
        """Step until everything in the water is still (TankConfig's thresholds) or the timeout; True if still."""
        settled, _ = self.tank.run_until_settled(on_step=self._after_step)
        return settled

    # -- robot -------------------------------------------------------------------------------------------------
    def palm_ik(self, targets_world, q0=None) -> tuple[torch.Tensor, torch.Tensor]:
        """Palm-down IK for (B, 3) world targets, near q0 (default: the arm's current posture).

        Returns (q (B, 10), success (B,))."""
        tw = torch.as_tensor(np.asarray(targets_world, dtype=float).reshape(-1, 3), dtype=torch.float64)
        tr, _ = world_to_root(tw, None, self.base_pos, self.base_quat)
        q0 = self.robot.arm_q() if q0 is None else q0
        # IK is a function of its inputs alone (its restarts seeded afresh each call): a question asked before, bit
        # for bit (the goal check from the same ball, an object's reach asked again), is answered from memory
        key = (tuple(tr.shape), tr.numpy().tobytes(), torch.as_tensor(q0, dtype=torch.float64).numpy().tobytes())
        if key not in self._ik_memory:
            if len(self._ik_memory) >= IK_MEMORY:
                del self._ik_memory[next(iter(self._ik_memory))]   # the oldest
            res = self.kin.ik(tr, target_normal=_palm_down_root().expand(len(tr), 3), q0=q0)
            self._ik_memory[key] = (res.q, res.success)
        q, ok = self._ik_memory[key]
        return q.clone(), ok.clone()

    def drive_to(self, q, tol: float, timeout_s: float) -> bool:
        """Motors towards q (POSITION_CONTROL) and step until every joint is within tol, or the timeout."""
        self.robot.drive_arm(q)
        rob, target = self.robot, torch.as_tensor(q, dtype=torch.float64).tolist()
        for _ in range(int(round(timeout_s / self.config.tank.timestep_s))):
            self.step()
            states = p.getJointStates(rob.body, rob.arm_joints, physicsClientId=self.client)
            if max([abs(s[0] - t) for s, t in zip(states, target)]) < tol:   # in floats: no tensor per step
                return True
        return False

    def move_palm(self, target_world, waypoints: int | None = None) -> bool:
        """Palm (facing down) along a straight line to target_world, through IK waypoints driven by the motors.

        RuntimeError if IK finds no way there; False if the motors did not get there in time."""
        c = self.config
        n = c.waypoints if waypoints is None else waypoints
        start = self.robot.hand_pose()[0].numpy()
        target = np.asarray(target_world, dtype=float)
        pts = [start + (target - start) * (k + 1) / n for k in range(n)]
        qs, ok = self.palm_ik(pts)
        if not bool(ok.all()):
            raise RuntimeError(f"the palm cannot reach {np.round(target, 3).tolist()} (IK failed)")
        for q in qs[:-1]:
            self.drive_to(q, c.via_tol_rad, c.move_timeout_s)
        return self.drive_to(qs[-1], c.joint_tol_rad, c.move_timeout_s)

    def go_home(self) -> bool:
        return self.drive_to(self.home_q, self.config.via_tol_rad, self.config.move_timeout_s)

    def _penetrates_jar(self, q) -> bool:
        """Set the arm to q in a scratch state: does any robot link penetrate the jar? (State restored.)"""
        cl, rob = self.client, self.robot
        saved = p.getJointStates(rob.body, rob.arm_joints, physicsClientId=cl)
        for j, v in zip(rob.arm_joints, torch.as_tensor(q).tolist()):
            p.resetJointState(rob.body, j, v, 0.0, physicsClientId=cl)
        p.performCollisionDetection(physicsClientId=cl)
        hits = p.getClosestPoints(rob.body, self.tank.jar_body, 0.0, physicsClientId=cl)
        for j, s in zip(rob.arm_joints, saved):
            p.resetJointState(rob.body, j, s[0], s[1], physicsClientId=cl)
        return any(h[8] < 0.0 for h in hits)

    def goal_reachable(self) -> bool:
        """Can the palm, facing down, rest on the ball's top without the arm or hand entering the jar's walls?

        Asked from the home posture whatever the arm is doing, so the answer depends on the ball alone."""
        c = self.config
        ball = np.asarray(p.getBasePositionAndOrientation(self.tank.ball, physicsClientId=self.client)[0])
        target = ball + [0.0, 0.0, c.tank.ball_diameter_cm / 2 * CM + c.palm_face_cm * CM]
        q, ok = self.palm_ik([target], q0=self.home_q)
        return bool(ok[0]) and not self._penetrates_jar(q[0])

    def grasp(self, body: int):
        """Hold `body` rigidly at its current pose relative to the palm (the model's fingers do not move)."""
        cl, rob = self.client, self.robot
        hs = p.getLinkState(rob.body, rob.hand_link, physicsClientId=cl)  # [0], [1]: the link's inertial frame
        bpos, born = p.getBasePositionAndOrientation(body, physicsClientId=cl)
        inv_pos, inv_orn = p.invertTransform(hs[0], hs[1])
        rel_pos, rel_orn = p.multiplyTransforms(inv_pos, inv_orn, bpos, born)
        for link in range(-1, p.getNumJoints(rob.body, physicsClientId=cl)):
            p.setCollisionFilterPair(rob.body, body, link, -1, 0, physicsClientId=cl)
        self._ungrasped.add(body)
        cid = p.createConstraint(rob.body, rob.hand_link, body, -1, p.JOINT_FIXED, [0, 0, 0], rel_pos, [0, 0, 0],
                                 rel_orn, [0, 0, 0, 1], physicsClientId=cl)
        p.changeConstraint(cid, maxForce=200.0, physicsClientId=cl)  # N: 20x the heaviest allowed object
        self.held = (body, cid)

    def weigh(self) -> float:
        """Hold still and read the load on the hand: grams felt, with the sensor's noise, never less than
        `min_felt_mass_g` (a hand feels no negative weight)."""
        c = self.config
        if self.held is None:
            raise RuntimeError("weigh() needs an object in the hand")
        self.step(c.weigh_wait_steps)
        loads = []
        for _ in range(c.weigh_steps):
            self.step()
            force = p.getConstraintState(self.held[1], physicsClientId=self.client)[:3]
            loads.append(np.linalg.norm(force))  # held still, the hand carries exactly the weight, m g
        grams = float(np.mean(loads)) / c.tank.gravity / G
        grams += float(self.rng.normal(0.0, c.mass_noise_g)) if c.mass_noise_g > 0 else 0.0
        return max(grams, c.min_felt_mass_g)

    def release(self):
        """Let go of the held object (it keeps the hand's velocity, ~0 once a move has ended)."""
        if self.held is not None:
            p.removeConstraint(self.held[1], physicsClientId=self.client)
            self.held = None

    # -- measuring -----------------------------------------------------------------------------------------------
    def level_reading_cm(self) -> float:
        """The water depth as the robot reads it off the jar: quantised, plus optional noise."""
        c = self.config
        level = self.tank.level_cm
        if c.level_noise_cm > 0:
            level += float(self.rng.normal(0.0, c.level_noise_cm))
        return round(level / c.level_resolution_cm) * c.level_resolution_cm

    @property
    def workspace(self) -> Workspace:
        """What the robot knows of its stand (where it is, how high its top is): not of the object on it."""
        return Workspace(tuple(self.config.stand_xy), float(self.stand_top))

    def eyes_above_table(self) -> bool:
        """Whether every perception camera looks from above the table top: the side glance (the lowest of them; the
        top view looks down from above the object, the jar's view from 6 cm above its inner bottom)."""
        c, cam = self.config, self.config.camera
        eye_z = (self.stand_top + cam.side_aim_cm / 100.0
                 + cam.side_distance * math.sin(math.radians(cam.side_elevation_deg)))
        return eye_z > c.table_top_z and self.tank.bottom_z + 0.06 > c.table_top_z

    @contextmanager
    def robot_unseen(self):
        """The robot invisible to the cameras inside the block (TinyRenderer skips a shape of alpha 0), then as it
        was. Its meshes are most of what a render costs, and the perception cameras look at the stand and into the
        jar from where the robot is not in the way (sim/perception.py): the pixels they measure are the same.
        The table, its legs and the floor go too when every eye is above the table top (`eyes_above_table`): they
        lie wholly at or below it, and so does nothing of what a camera measures (the object on the stand or in the
        jar), so no line from an eye to it crosses them; they only fill the background, which a render pays for by
        its area (the table top and the floor cover most of the image: a look cost ~70 ms with them, ~40 without)."""
        cl, body = self.client, self.robot.body
        for link in sorted({link for link, _, _ in self._robot_colours}):
            p.changeVisualShape(body, link, rgbaColor=[0, 0, 0, 0], physicsClientId=cl)
        under = self._underneath if self.eyes_above_table() else []
        for b, rgba in under:
            p.changeVisualShape(b, -1, rgbaColor=[*rgba[:3], 0.0], physicsClientId=cl)
        try:
            yield
        finally:
            for link, index, rgba in self._robot_colours:
                p.changeVisualShape(body, link, shapeIndex=index, rgbaColor=list(rgba), physicsClientId=cl)
            for b, rgba in under:
                p.changeVisualShape(b, -1, rgbaColor=list(rgba), physicsClientId=cl)

    def look(self, body: int) -> Percept:
        """Look at the object on the stand (two camera images, sim/perception.py): its measurement without the
        mass, and where its top is, which is where the hand goes to take it."""
        with self.robot_unseen():
            return look(self.client, body, self.workspace, self.config.camera)

    def perceive(self, body: int, mass_g: float) -> dict:
        return {**self.look(body).measurement, "mass_g": float(mass_g)}

    # -- episodes (sim/episode.py) -----------------------------------------------------------------------------
    def run_episode(self, name: str, record=None):
        """Drop the named object into the jar and measure what happened: an EpisodeOutcome."""
        from sim.episode import drop_episode
        with self._config_failures("drop", name):
            return drop_episode(self, name, record)

    def inspect(self, name: str) -> dict:
        """Perceive, lift, weigh and put back the named object (no drop): its measurement dict."""
        from sim.episode import inspect_object
        with self._config_failures("inspection", name):
            return inspect_object(self, name)

    def drop_next(self, name: str, record=None):
        """A drop of a goal trial (sim/trial.py): the jar is not reset, what was dropped before stays in the water
        (it is no longer this world's `body`, so the stand takes the next object). An EpisodeOutcome."""
        from sim.trial import drop_next
        self.body = None
        with self._config_failures("drop", name):
            return drop_next(self, name, record)

    @contextmanager
    def _config_failures(self, what: str, name: str):
        """An episode that fails (the palm cannot reach, the camera does not see the object) in a world built from
        a config other than the default: WorldBuildError naming the drop and the reason, one line (the
        runner ends on it, exit 1, its last checkpoint kept). Its settings passed every check made up front
        (train/runner/config_checks.py), so this is what the world found out by trying. With the default config the error
        is raised as it is: a failure there is a bug, with its traceback."""
        try:
            yield
        except (RuntimeError, ValueError, ArithmeticError) as e:
            if self.config == WorldConfig() or name not in {o.name for o in self.objects.train + self.objects.probe
                                                               + self.objects.pool}:
                raise
            lines = str(e).strip().splitlines()
            raise WorldBuildError(f"the {what} of '{name}' failed in this world: {type(e).__name__}: "
                                  f"{lines[0] if lines else ''}") from None
