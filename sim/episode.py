"""One drop episode, as the paper's iCub lives it, and the camera frames that show it.

    goal check (is the ball reachable?) -> look at the object on the stand -> reach above it -> take it (palm on
    its top, a fixed constraint: the model's fingers do not move) -> lift it and feel its weight (the load on the
    hand: the constraint's force while held still, plus the sensor's noise) -> carry it above the jar -> let go ->
    the arm withdraws while physics does the rest -> wait until everything in the water is still -> read the
    level -> goal check again.

Every arm motion is IK (sim.kinematics) waypoints driven by pybullet's position motors, never a teleport. Probe
objects go through `inspect_object`: the same look, take, lift and weigh, then they are put back.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pybullet as p

from sim.objects import archimedes_cm3
from sim.perception import render, rests_on_bottom
from sim.water import CM


@dataclass
class EpisodeOutcome:
    name: str
    measurement: dict             # rgb, extent_cm, fill, mass_g (sim/perception.py)
    observed_cm3: float           # (level after - level before) x the jar's cross-section, as read
    level_before_cm: float
    level_after_cm: float
    archimedes_cm3: float         # the closed-form yardstick (sim/objects.py), never shown to the agent
    goal_reachable_before: bool
    goal_reached_after: bool      # the ball reachable once everything settled
    sank: bool                    # the object came to rest on the jar's bottom (False: it floats)
    settled: bool                 # False if the settle timeout ran out
    wall_s: float
    frames: list = field(default_factory=list)  # (H, W, 3) uint8 images if recording was asked
    # the file's values beside what was perceived (extent_cm, fill, mass_g), for the logs; never shown to the agent
    true: dict = field(default_factory=dict)
    # the object came to rest inside the jar (False: the arm never got it there, and the rise is not its)
    delivered: bool = True


@dataclass
class FrameRecorder:
    """Renders a side view (robot, jar and ball) every `every_n_steps` physics steps into `frames`.

    TinyRenderer draws nothing translucent, so the glass and the water are composited: each frame is rendered
    three times (all; without the jar; without jar and water) and blended with their alphas where they show.
    """
    # 10 frames per simulated second at 240 Hz: ~45 per episode, each ~0.15 s to render (three TinyRenderer passes
    # over the iCub's meshes), so recording adds ~7 s to an episode
    every_n_steps: int = 24
    width: int = 240
    height: int = 180
    fov_deg: float = 45.0
    eye: tuple = (0.85, 0.45, 0.90)     # in front of the robot, to its left, above the table: robot, stand, jar
    target: tuple = (0.18, -0.04, 0.60)
    frames: list = field(default_factory=list)
    _count: int = field(default=0, repr=False)   # steps seen

    def __post_init__(self):
        if self.every_n_steps < 1 or self.width < 8 or self.height < 8:
            raise ValueError("FrameRecorder needs every_n_steps >= 1 and an image of at least 8 x 8")

    def on_step(self, world):
        self._count += 1
        if self._count % self.every_n_steps == 0:
            self.capture(world)

    def capture(self, world):
        tank, cl = world.tank, world.client
        tank.sync_visuals()
        shot = lambda: render(cl, self.eye, self.target, self.width, self.height, self.fov_deg, flat=False)
        jar_rgba, water_rgba = tank.config.jar_rgba, tank.config.water_rgba
        full, seg_full = shot()
        p.changeVisualShape(tank.jar_body, -1, rgbaColor=[*jar_rgba[:3], 0], physicsClientId=cl)
        no_jar, seg_no_jar = shot()
        p.changeVisualShape(tank.water_visual, -1, rgbaColor=[*water_rgba[:3], 0], physicsClientId=cl)
        inside, _ = shot()
        p.changeVisualShape(tank.jar_body, -1, rgbaColor=list(jar_rgba), physicsClientId=cl)
        p.changeVisualShape(tank.water_visual, -1, rgbaColor=list(water_rgba), physicsClientId=cl)
        out = inside.astype(np.float32)
        water = seg_no_jar == tank.water_visual
        a = water_rgba[3]
        out[water] = a * no_jar[water] + (1 - a) * out[water]
        glass = seg_full == tank.jar_body
        a = jar_rgba[3]
        out[glass] = a * full[glass] + (1 - a) * out[glass]
        rest = ~(glass | water)
        out[rest] = full[rest]
        self.frames.append(np.clip(out + 0.5, 0, 255).astype(np.uint8))


def save_frames_png(frames, directory) -> list[Path]:
    """Write frames as frame_0000.png, ... into directory (created); returns the paths."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, f in enumerate(frames):
        f = np.asarray(f)
        if f.ndim != 3 or f.shape[2] != 3 or f.dtype != np.uint8:
            raise ValueError(f"frame {i} must be an (H, W, 3) uint8 array, not {f.dtype} {f.shape}")
        path = d / f"frame_{i:04d}.png"
        plt.imsave(path, f)
        paths.append(path)
    return paths


def _recorder(record):
    if record is None or record is False:
        return None
    if record is True:
        return FrameRecorder()
    if isinstance(record, FrameRecorder):
        return record
    raise ValueError(f"record must be None, True/False or a FrameRecorder, not {type(record).__name__}")


def _take(world, body: int, seen) -> float:
    """Reach above the object where the eye saw its top (`seen`: a sim.perception.Percept), put the palm on it,
    hold it, lift it, weigh it: grams felt."""
    c = world.config
    top = np.asarray(seen.top_centre, dtype=float)
    touch = top + [0, 0, (c.palm_face_cm + c.grasp_gap_cm) * CM]
    world.move_palm(touch + [0, 0, c.hover_cm * CM])
    world.move_palm(touch, waypoints=3)
    world.grasp(body)
    carry_z = world.tank.rim_z + c.carry_clearance_cm * CM + seen.height_m + (c.palm_face_cm + c.grasp_gap_cm) * CM
    world.move_palm([touch[0], touch[1], max(carry_z, touch[2] + c.hover_cm * CM)], waypoints=3)
    return world.weigh()


def drop_episode(world, name: str, record=None) -> EpisodeOutcome:
    """The full episode for the named object (sim.world.World.run_episode), from a reset jar."""
    t0 = time.perf_counter()
    world.reset(name)
    return drop_into_jar(world, name, record, t0)


def drop_into_jar(world, name: str, record=None, t0: float | None = None) -> EpisodeOutcome:
    """Put the named object on the stand, look, take, weigh, carry and drop it into the jar as it is (a goal trial
    does not reset it between drops); observed_cm3 is this drop's rise of the level alone. The caller seeds the
    sensor noise (World.reset(name) or World.seed_noise(name))."""
    t0 = time.perf_counter() if t0 is None else t0
    rec = _recorder(record)
    spec = world.spec(name)
    world.recorder = rec
    try:
        body = world.place_on_stand(name)
        world.settle()                                  # the ball and the object at rest before anything is read
        level_before = world.level_reading_cm()
        reachable_before = world.goal_reachable()
        seen = world.look(body)                         # colour, size, shape, where: before touching it
        mass = _take(world, body, seen)
        palm = world.robot.hand_pose()[0].numpy()
        drop = world.drop_xy()
        world.move_palm([drop[0], drop[1], palm[2]])
        world.release()
        world.move_palm(world.robot.hand_pose()[0].numpy() + [0, 0, world.config.hover_cm * CM], waypoints=2)
        world.go_home()
        settled = world.settle()
        sank = _rests_on_bottom(world, body)
        delivered = in_jar(world, body)
        level_after = world.level_reading_cm()
        reached_after = world.goal_reachable()
    finally:
        world.recorder = None
    area = world.objects.jar.area_cm2
    return EpisodeOutcome(
        name=name, measurement={**seen.measurement, "mass_g": mass}, observed_cm3=(level_after - level_before) * area,
        level_before_cm=level_before, level_after_cm=level_after,
        archimedes_cm3=archimedes_cm3(spec, world.objects.jar, world.config.tank.water.density / 1000.0),
        goal_reachable_before=reachable_before, goal_reached_after=reached_after, sank=sank, settled=settled,
        wall_s=time.perf_counter() - t0, frames=rec.frames if rec is not None else [], true=spec.true_values(),
        delivered=delivered)


def in_jar(world, body: int) -> bool:
    """Whether the body is in the jar: its centre within the jar's inner wall, its lowest point between the jar's
    bottom and its rim (a tall float may stick out above the rim; an object the arm never carried is on the stand or
    in the hand, outside the wall)."""
    tank, cl = world.tank, world.client
    pos = p.getBasePositionAndOrientation(body, physicsClientId=cl)[0]
    low = p.getAABB(body, physicsClientId=cl)[0][2]
    radius = tank.jar.inner_diameter_cm / 2 * CM
    off = math.hypot(pos[0] - tank.center[0], pos[1] - tank.center[1])
    return off <= radius and tank.bottom_z - 0.01 <= low <= tank.rim_z   # 1 cm: the AABB's margin and the plate


def _rests_on_bottom(world, body: int) -> bool:
    """Did it sink? Seen through the glass by a camera (sim.perception.rests_on_bottom), from the robot's left."""
    tank, (ax, ay) = world.tank, world.away            # world.away: unit vector from the robot to the jar
    with world.robot_unseen():
        return rests_on_bottom(world.client, body, (tank.jar_body, tank.water_visual), world.config.jar_xy,
                               tank.bottom_z, (-ay, ax))


def inspect_object(world, name: str) -> dict:
    """Look at, take, lift and weigh the named object, then put it back on the stand: its measurement dict."""
    world.spec(name)
    world.reset(name)
    body = world.place_on_stand(name)
    world.settle()
    seen = world.look(body)
    mass = _take(world, body, seen)
    c = world.config
    above_stand = 0.3 * CM  # let go with the object 3 mm above where it stood
    x, y, top = seen.top_centre
    world.move_palm([x, y, top + (c.palm_face_cm + c.grasp_gap_cm) * CM + above_stand], waypoints=3)
    world.release()
    world.move_palm(world.robot.hand_pose()[0].numpy() + [0, 0, c.hover_cm * CM], waypoints=2)
    return {**seen.measurement, "mass_g": mass}
