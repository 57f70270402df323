"""Settings that are each in range but together cannot give a run its result, refused before anything is written.

train.common.config checks each key alone (its type, its RANGES); sim.world.World and sim.water.Tank refuse a scene they
cannot build (train.common.config.check_world). What is left is settings that build a world which then measures nothing,
or the wrong thing, or runs for ever:

- the jar or the stand off the table, or through each other;
- the arm cannot reach the stand or the jar (sim.kinematics.ArmKinematics on the palm's targets of an episode);
- the motors cannot get the object to the jar within the move timeout (the palm moves at most the arm's joint
  speed times its levers);
- the cameras' depth range does not hold the object (near >= far, or the object outside it);
- the encoder's range of sizes or masses excludes the objects (an object far outside lights no unit of its map);
- the senses' noise swamps what they measure (the level's against the smallest object's rise, the hand's against
  the heaviest object's mass), or their resolution does (the level read in steps coarser than a quarter of the
  smallest rise), or their floor does (a felt mass floored above the lightest object's mass);
- gravity of the world and of the water's forces not the same (the water's buoyancy assumes the world's);
- water too thin to float the green ball, or light enough that an object's displacement overflows the jar;
- the rules' strengths or tolerances in the wrong order (knowledge that says the reverse of its name);
- a context property on a jar run (the jar shows none: a map that never sees anything);
- the water's explicit buoyancy cannot follow the lightest object the objects file admits (time step and density
  together);
- a wait of the simulator (a move, a settle) longer than WAIT_STEPS steps: hours of stepping, not a result.

`check_run(run_config, objects)` raises train.common.config.ConfigError: one line naming every setting involved (and the
object, where one decides it), `key` the first of them, the one the runner names the origin of.
"""

from __future__ import annotations

import functools
import math

from train.common.agent_checks import Joint, check_knowledge, check_sheet

# the longest wait of the simulator: 1000 s of simulated time at pybullet's default 1/240 s step, 100x the default
# settle timeout and 250x the default move timeout; a step of the default scene with an object out took 0.6 ms
# (World.step(2400) timed, both cores busy), so one wait is at most about 2.5 minutes of stepping
WAIT_STEPS = 240_000
# the water follows a bobbing float while w dt stays below ~1.5, and the lightest object the objects file admits
# (sim.objects.ObjectsConfig.min_mass_per_area_g_cm2) bobs at w dt <= 0.83 at 1/240 s in water of 1000 kg/m^3; w grows
# as sqrt(density), w dt as the time step (sim/objects.py says how both were measured)
BOB_WDT_AT_DEFAULT, BOB_WDT_MAX, DEFAULT_STEP_S, DEFAULT_DENSITY = 0.83, 1.5, 1.0 / 240.0, 1000.0
# a reading of a difference of two levels, each with noise s: s sqrt(2); a rise this many of those deep reads
# negative once in 30,000 drops
NOISE_SIGMAS = 4.0
# an object whose size or mass lies this far outside the encoder's range, in units of the range (its log-unit
# coordinate below -0.5 or above 1.5), lies half the range beyond the map's inputs (developmental samples span 0..1):
# the map answers it with its edge unit at best, and with no activity at all far enough out (encoder.size_min_cm=50
# with the default objects: "a present map has no activity to store", a traceback)
ENCODER_MARGIN = 0.5


def check_run(config, objects, given=()) -> None:
    """Every check of this module on a resolved train.common.config.RunConfig and the run's ObjectSet; ConfigError. `given`:
    the keys the run set (its overrides); a refusal that names several settings takes as its `key` the first of
    them that was given, so that the runner says where it came from."""
    from train.common.config import check_world
    check_world(config.world, objects)
    world = config.world
    try:
        for check in (_check_waits, _check_gravity, _check_buoyancy, _check_water, _check_camera, _check_noise,
                      _check_timeout, _check_reach, _check_layout):
            check(world, objects)
        _check_encoder(config.agent, objects)
        check_knowledge(config.agent)
        check_sheet(config.agent, given)
    except Joint as e:
        raise e.refusal(given) from None


def _plain(v):
    return [float(x) for x in v] if isinstance(v, (tuple, list)) else f"{v:g}"


def _objects(objects) -> list:
    return list(objects.train) + list(objects.probe)


def _check_layout(world, objects) -> None:
    """The jar and the stand stand on the table, apart: a jar over the table's edge or through the stand is a scene
    pybullet builds (static bodies overlap freely) in which nothing the robot does means what it should."""
    from sim.water import CM

    jar_r = (objects.jar.inner_diameter_cm / 2 + world.tank.wall_thickness_cm) * CM
    (x0, x1), (y0, y1) = world.table_x, world.table_y
    for key, (x, y), r in (("world.jar_xy", world.jar_xy, jar_r), ("world.stand_xy", world.stand_xy,
                                                                     world.stand_radius)):
        if not (x0 - 1e-9 <= x - r and x + r <= x1 + 1e-9 and y0 - 1e-9 <= y - r and y + r <= y1 + 1e-9):
            raise Joint([key, "world.table_x", "world.table_y"],
                         f"{key} {_plain((x, y))} puts a footprint of radius {r * 100:.1f} cm off the table "
                         f"(world.table_x {_plain(world.table_x)}, world.table_y {_plain(world.table_y)})")
    gap = math.dist(world.jar_xy, world.stand_xy) - jar_r - world.stand_radius
    if gap < 0:
        raise Joint(["world.jar_xy", "world.stand_xy", "world.stand_radius"],
                     f"world.jar_xy {_plain(world.jar_xy)} and world.stand_xy {_plain(world.stand_xy)} overlap (the "
                     f"jar's outer radius {jar_r * 100:.1f} cm and world.stand_radius {world.stand_radius:g} m)")


def _check_waits(world, objects) -> None:
    tank = world.tank
    for key, seconds in (("world.move_timeout_s", world.move_timeout_s),
                         ("world.tank.settle_timeout_s", tank.settle_timeout_s)):
        steps = seconds / tank.timestep_s
        if steps > WAIT_STEPS:
            raise Joint([key, "world.tank.timestep_s"],
                         f"{key} {seconds:g} s at world.tank.timestep_s {tank.timestep_s:g} s is {steps:,.0f} steps, "
                         f"more than the {WAIT_STEPS:,} a wait of the simulator may take (minutes of stepping)")
    per_wait = tank.settle_window_steps * tank.settle_windows
    if per_wait > tank.settle_timeout_s / tank.timestep_s:
        raise Joint(["world.tank.settle_windows", "world.tank.settle_window_steps", "world.tank.settle_timeout_s",
                      "world.tank.timestep_s"],
                     f"world.tank.settle_windows {tank.settle_windows} of world.tank.settle_window_steps "
                     f"{tank.settle_window_steps} steps of world.tank.timestep_s {tank.timestep_s:g} s take longer "
                     f"than world.tank.settle_timeout_s {tank.settle_timeout_s:g} s: nothing could be seen to settle")


def _check_buoyancy(world, objects) -> None:
    tank = world.tank
    wdt = BOB_WDT_AT_DEFAULT * (tank.timestep_s / DEFAULT_STEP_S) * math.sqrt(tank.water.density / DEFAULT_DENSITY)
    if wdt > BOB_WDT_MAX:
        raise Joint(["world.tank.timestep_s", "world.tank.water.density"],
                     f"world.tank.timestep_s {tank.timestep_s:g} s with world.tank.water.density "
                     f"{tank.water.density:g} kg/m^3: the lightest object the objects file admits would bob at "
                     f"w dt = {wdt:.2f}, and the water follows it only below {BOB_WDT_MAX} (a smaller step or a "
                     "lighter liquid)")


def _check_gravity(world, objects) -> None:
    tank = world.tank
    if tank.water.gravity != tank.gravity:
        raise Joint(["world.tank.water.gravity", "world.tank.gravity"],
                     f"{tank.water.gravity:g} m/s^2 is not world.tank.gravity "
                     f"{tank.gravity:g} m/s^2: the water's buoyancy would hold up another weight than the one that "
                     "pulls the object down (set both)")


def _check_water(world, objects) -> None:
    """The ball floats, and no object's displacement in this water (sim.objects.archimedes_cm3 at its density)
    lifts the level over the rim (the objects file checks that at 1000 kg/m^3)."""
    from sim.objects import archimedes_cm3

    tank, jar = world.tank, objects.jar
    density = tank.water.density / 1000.0   # g/cm^3
    ball_cm3 = math.pi / 6 * tank.ball_diameter_cm ** 3
    if tank.ball_mass_g / density >= ball_cm3:
        raise Joint(["world.tank.water.density", "world.tank.ball_mass_g", "world.tank.ball_diameter_cm"],
                     f"{tank.water.density:g} kg/m^3 cannot float the green ball "
                     f"(world.tank.ball_mass_g {tank.ball_mass_g:g} g in {ball_cm3:.1f} cm^3): the goal would lie on "
                     "the bottom")
    for o in _objects(objects):
        v = archimedes_cm3(o, jar, density)
        level = jar.water_depth_cm + v / jar.area_cm2
        if level > jar.height_cm:
            raise Joint(["world.tank.water.density"],
                         f"in water of {tank.water.density:g} kg/m^3 object '{o.name}' "
                         f"displaces {v:.0f} cm^3, which would raise the water from {jar.water_depth_cm:g} to "
                         f"{level:.1f} cm, over the jar's {jar.height_cm:g} cm rim")


def _check_camera(world, objects) -> None:
    cam = world.camera
    if cam.near >= cam.far:
        raise Joint(["world.camera.near", "world.camera.far"],
                     f"world.camera.near {cam.near:g} m is not nearer than world.camera.far {cam.far:g} m")
    specs = _objects(objects)
    reach = max(o.footprint_cm for o in specs) / 2 / 100.0   # the object's far side from the stand's axis, m
    tall = max(o.height_cm for o in specs) / 100.0
    nearest, farthest = min(cam.side_distance - reach, cam.top_distance), max(cam.side_distance + reach,
                                                                               cam.top_distance + tall)
    if nearest <= cam.near or farthest >= cam.far:
        raise Joint(["world.camera.near", "world.camera.far", "world.camera.side_distance",
                      "world.camera.top_distance"],
                     f"the cameras see the objects from {nearest:.3f} to {farthest:.3f} m (world.camera."
                     f"side_distance {cam.side_distance:g}, world.camera.top_distance {cam.top_distance:g}), outside "
                     f"world.camera.near {cam.near:g} .. world.camera.far {cam.far:g} m")


def _check_noise(world, objects) -> None:
    jar = objects.jar
    specs = _objects(objects)
    # an object displaces its mass of water afloat and its volume sunk (sim.objects.archimedes_cm3, without the
    # bottom's and the wall's few per cent); its rise is that over the jar's cross-section
    density = world.tank.water.density / 1000.0   # g/cm^3: a floater displaces its mass of this water
    smallest = min(specs, key=lambda o: min(o.mass_g / density, o.volume_cm3))
    rise = min(smallest.mass_g / density, smallest.volume_cm3) / jar.area_cm2
    reading = world.level_noise_cm * math.sqrt(2.0)
    if NOISE_SIGMAS * reading > rise:
        raise Joint(["world.level_noise_cm"],
                     f"{world.level_noise_cm:g} cm of noise on each level reading swamps the {rise:.3f} cm rise of "
                     f"object '{smallest.name}' (the smallest): at most {rise / NOISE_SIGMAS / math.sqrt(2.0):.4f} "
                     "cm, or a rise could read negative")
    # a level read in steps of r misreads a rise (two readings, each rounded) by up to r: as with the noise, the
    # smallest rise must be NOISE_SIGMAS of those deep (at 50 cm every reading was 0: every property irrelevant)
    if NOISE_SIGMAS * world.level_resolution_cm > rise:
        raise Joint(["world.level_resolution_cm"],
                     f"a level read in steps of {world.level_resolution_cm:g} cm reads the {rise:.3f} cm rise of "
                     f"object '{smallest.name}' (the smallest) to within a step of itself: at most "
                     f"{rise / NOISE_SIGMAS:.4f} cm")
    lightest = min(specs, key=lambda o: o.mass_g)
    if world.min_felt_mass_g > lightest.mass_g:
        raise Joint(["world.min_felt_mass_g"],
                     f"{world.min_felt_mass_g:g} g is above the mass of object "
                     f"'{lightest.name}' (the lightest, {lightest.mass_g:g} g): the hand would feel the floor, not "
                     f"the object; at most {lightest.mass_g:g} g")
    heaviest = max(specs, key=lambda o: o.mass_g)
    if NOISE_SIGMAS * world.mass_noise_g > heaviest.mass_g:
        raise Joint(["world.mass_noise_g"],
                     f"{world.mass_noise_g:g} g of noise swamps the felt mass of every object, even of "
                     f"'{heaviest.name}' (the heaviest, {heaviest.mass_g:g} g): at most "
                     f"{heaviest.mass_g / NOISE_SIGMAS:g} g")


def _get(obj, dotted: str):
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj


# `arm_levers` of the iCub's arm, 4.72 m (its links' lengths are the URDF's, whatever the settings; a constant, so
# that the check does not import the kinematics, a second or more of the runner's start; tests/test_checks.py
# computes it): the palm moves at most this many metres a second per rad/s of the joints
LEVERS_M = 4.75


def arm_levers(kin) -> float:
    """sum over the arm chain's joints of the longest the joint's distance to the palm can be (the lengths of the
    links between them, which no posture changes): the palm moves at most this x the joints' speed (m per rad)."""
    import torch

    frames = kin.fk_frames(kin.home[None])
    points = [m[0, :3, 3] for m in frames.values()]
    links = [float(torch.linalg.norm(b - a)) for a, b in zip(points, points[1:])]
    return sum(sum(links[i:]) for i in range(len(links)))


def _targets(world, objects):
    """The palm's targets of an episode (sim/episode.py: over the object on the stand, touching it, lifting it to
    the carry height, over the jar's drop point), for the shortest and the tallest object, in world coordinates,
    and the carry's length from the stand to the jar (m)."""
    import numpy as np

    from sim.water import CM

    c, specs = world, _objects(objects)
    palm = (c.palm_face_cm + c.grasp_gap_cm) * CM
    stand_top = c.table_top_z + c.stand_height
    rim = c.table_top_z + c.tank.bottom_thickness_cm * CM + objects.jar.height_cm * CM
    away = np.asarray(c.jar_xy, dtype=float) - np.asarray(c.robot_base[:2], dtype=float)
    away = away / max(float(np.linalg.norm(away)), 1e-12)
    drop = np.asarray(c.jar_xy, dtype=float) - away * (c.tank.ball_diameter_cm + c.ball_gap_cm) / 2 * CM
    sx, sy = c.stand_xy
    points = []
    for h in (min(o.height_cm for o in specs), max(o.height_cm for o in specs)):
        touch = stand_top + h * CM + palm
        carry = max(rim + c.carry_clearance_cm * CM + h * CM + palm, touch + c.hover_cm * CM)
        points += [(sx, sy, touch + c.hover_cm * CM), (sx, sy, touch), (sx, sy, carry), (drop[0], drop[1], carry)]
    return points, float(np.linalg.norm(drop - np.asarray(c.stand_xy, dtype=float)))


@functools.lru_cache(maxsize=4)
def _kin_for(ik_repr: str, ik):
    from sim.kinematics import ArmKinematics
    return ArmKinematics(config=ik)


def _kin(world):
    """The arm's kinematics with the world's IK settings (built once per setting: the chain is read from the URDF)."""
    return _kin_for(repr(world.ik), world.ik)


# what the palm's targets depend on besides the objects file (which is checked against the default world's reach,
# sim.objects.ObjectsConfig): with all of them at their defaults, the reach is the objects file's check
REACH_KEYS = ("robot_base", "table_top_z", "jar_xy", "stand_xy", "stand_height", "ball_gap_cm", "palm_face_cm",
              "grasp_gap_cm", "hover_cm", "carry_clearance_cm", "tank.bottom_thickness_cm", "tank.ball_diameter_cm",
              "ik")


def _check_timeout(world, objects) -> None:
    tank = world.tank
    if round(world.move_timeout_s / tank.timestep_s) < 1:
        raise Joint(["world.move_timeout_s", "world.tank.timestep_s"],
                     f"world.move_timeout_s {world.move_timeout_s:g} s is less than one step of world.tank."
                     f"timestep_s {tank.timestep_s:g} s: the arm would never move")
    _, carry = _targets(world, objects)
    fastest = world.robot.max_velocity * LEVERS_M   # m/s: the palm's speed at most
    need = carry / fastest
    have = world.waypoints * world.move_timeout_s
    if have < need:
        raise Joint(["world.move_timeout_s", "world.waypoints", "world.robot.max_velocity"],
                     f"world.waypoints {world.waypoints} moves of world.move_timeout_s {world.move_timeout_s:g} s "
                     f"cannot carry an object the {carry * 100:.1f} cm from the stand to the jar at world.robot."
                     f"max_velocity {world.robot.max_velocity:g} rad/s (at least {need:.3g} s): it would never be "
                     "delivered")


def _check_reach(world, objects) -> None:
    import torch

    from sim.kinematics import world_to_root
    from sim.robot import FACING_PLUS_X
    from sim.world import WorldConfig, _palm_down_root

    default = WorldConfig()
    if all(_get(world, k) == _get(default, k) for k in REACH_KEYS):
        return
    points, _ = _targets(world, objects)
    names = ["above the stand", "on the shortest object", "lifting it", "over the jar",
             "above the stand", "on the tallest object", "lifting it", "over the jar"]
    where = torch.tensor(points, dtype=torch.float64)
    root, _ = world_to_root(where, None, torch.tensor(world.robot_base, dtype=torch.float64),
                            torch.tensor(FACING_PLUS_X, dtype=torch.float64))
    ok = _kin(world).reachable(root, target_normal=_palm_down_root().expand(len(root), 3))
    if not bool(ok.all()):
        i = int((~ok).nonzero()[0])
        keys = (["world.jar_xy", "world.table_top_z", "world.robot_base"] if names[i] == "over the jar" else
                ["world.stand_height", "world.stand_xy", "world.table_top_z", "world.robot_base"])
        settings = ", ".join(f"{k} {_plain(getattr(world, k.split('.')[1]))}" for k in keys)
        if world.ik != default.ik:
            keys.append("world.ik")
            settings += " and the world.ik settings given"
        x, y, z = points[i]
        raise Joint(keys, f"the arm cannot reach the palm's place {names[i]} ({x:.3f}, {y:.3f}, {z:.3f} m) with "
                           f"{settings} (sim.kinematics' reach)")


def _check_encoder(agent, objects) -> None:
    enc = agent.encoder
    for what, lo_key, hi_key, value in (
            ("size", "encoder.size_min_cm", "encoder.size_max_cm", lambda o: float(o.extent_cm.prod()) ** (1 / 3)),
            ("mass", "encoder.mass_min_g", "encoder.mass_max_g", lambda o: o.mass_g)):
        lo, hi = getattr(enc, lo_key.split(".")[1]), getattr(enc, hi_key.split(".")[1])
        if lo >= hi:
            raise Joint([lo_key, hi_key], f"{lo_key} {lo:g} is not below {hi_key} {hi:g}")
        for o in _objects(objects):
            u = (math.log(value(o)) - math.log(lo)) / (math.log(hi) - math.log(lo))
            if not -ENCODER_MARGIN <= u <= 1 + ENCODER_MARGIN:
                unit = "cm" if what == "size" else "g"
                raise Joint([lo_key, hi_key] if u < 0 else [hi_key, lo_key],
                             f"the encoder's {what}s {lo_key} {lo:g} .. {hi_key} {hi:g} {unit} exclude object "
                             f"'{o.name}' ({what} {value(o):.3g} {unit}): its map could not tell it from nothing")

