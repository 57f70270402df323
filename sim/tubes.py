"""The Aesop battery's apparatus in pybullet (issue 32): tubes side by side, water simulated as the jar's is.

Each water tube is a glass tube (sim/water.py's jar body, any diameter) with its own `Water`; tubes joined by a
hidden channel share one `ChannelWater`: one volume of water over the sum of their areas, so their levels
equalise (no pipe is built: the channel is hidden, and the water model needs only the shared level). Sand and
sawdust are static beds (a cylinder filling the tube to its level): an object lands on them and their surface
cannot rise. A hollow cup is a floor and a ring of staves; the water sees only its walls (its sample points fill
the walls, not the cavity), so it fills as it enters and displaces its walls' volume. A reward is a small floating
ball (`TubesConfig.reward_*`), kept to one side of its tube so a dropped object sinks past it.

Levels are measured from the simulation: a water tube's is the level `Water` solves from the bodies' submerged
volumes each step, a bed's is its top as pybullet holds it. `outcome` (sim/apparatus.py) is the yardstick.

The robot is not in this world: the simulation releases each object just above the chosen tube's surface (the
arm's reach over a tube row was not checked; sim/world.py's arm is fitted to one jar).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pybullet as p

from sim.apparatus import Task, TaskObject, Tube
from sim.objects import ObjectSpec
from sim.water import CM, G, Tank, TankConfig, Water, make_body, round_visual, sample_points

SUBSTRATE_RGB = {"sand": (0.85, 0.75, 0.45), "sawdust": (0.70, 0.50, 0.25)}


@dataclass
class TubesConfig:
    tank: TankConfig = field(default_factory=lambda: TankConfig(wall_thickness_cm=0.3))  # test-tube glass
    # a reward that floats beside a 3 cm object in a 5 cm tube (1 cm of the wall's side for it): a 1.5 cm, 0.8 g
    # ball (a bit of cork), half under water
    reward_diameter_cm: float = 1.5
    reward_mass_g: float = 0.8
    gap_cm: float = 2.0                 # between neighbouring tubes' outer walls
    release_above_cm: float = 1.0       # an object's bottom this far above the surface when let go
    cup_staves: int = 12                # the cup's wall as flat boxes; with the floor 13 parts (pybullet: at most 16)
    settle_level_cm: float = 1e-4       # the level moved by less than this over a window: settled (0.01 cm^3)


class ChannelWater(Water):
    """One body of water in several tubes joined below (a hidden channel): one level over the sum of their areas.
    Every tube's inner bottom is at `bottom_z` (they stand on one table)."""

    def __init__(self, client, columns, bottom_z, water_volume, timestep, config=None):
        (cx, cy), r = columns[0]
        super().__init__(client, (cx, cy), bottom_z, r, water_volume, timestep, config)
        self.columns = [(float(x), float(y), float(r)) for (x, y), r in columns]
        self.area = sum(math.pi * r * r for _, _, r in self.columns)
        self.level = self.bottom_z + self.water_volume / self.area

    def column(self, pos):
        return min(self.columns, key=lambda c: math.hypot(pos[0] - c[0], pos[1] - c[1]))


def cup_cloud(dims_cm, wall_cm, n: int):
    """Sample points of a cup's walls (floor and side), frame at its bounding box's centre: (points, weights,
    spacing) for Water.add_body, the weights summing to the walls' volume."""
    d, h = (x * CM for x in dims_cm)
    t = wall_cm * CM
    pts, _, spacing = sample_points("cylinder", [d, d, h], n)
    keep = (np.hypot(pts[:, 0], pts[:, 1]) >= d / 2 - t) | (pts[:, 2] <= -h / 2 + t)
    pts = pts[keep]
    walls = math.pi / 4 * (d * d * h - (d - 2 * t) ** 2 * (h - t))
    return pts, np.full(len(pts), walls / len(pts)), spacing


def make_cup(client, obj: TaskObject, pos, config: TubesConfig) -> int:
    """A hollow open-topped cylinder: a floor disc and a ring of staves; it looks like the solid one beside it."""
    d, h = (x * CM for x in obj.dims_cm)
    t, n, R = obj.wall_cm * CM, config.cup_staves, d / 2
    width = 2 * R * math.tan(math.pi / n) * 1.02
    col = p.createCollisionShapeArray(
        [p.GEOM_CYLINDER] + [p.GEOM_BOX] * n,
        radii=[R] + [0] * n, lengths=[t] + [0] * n,
        halfExtents=[[0, 0, 0]] + [[t / 2, width / 2, h / 2]] * n,
        collisionFramePositions=[[0, 0, -h / 2 + t / 2]] + [[(R - t / 2) * math.cos(2 * math.pi * i / n),
                                                            (R - t / 2) * math.sin(2 * math.pi * i / n), 0]
                                                           for i in range(n)],
        collisionFrameOrientations=[[0, 0, 0, 1]] + [p.getQuaternionFromEuler([0, 0, 2 * math.pi * i / n])
                                                     for i in range(n)],
        physicsClientId=client)
    vis = round_visual(client, "cylinder", R, h, obj.rgb)
    m = obj.mass_g * G
    body = p.createMultiBody(m, col, vis, list(pos), physicsClientId=client)
    # a thin shell: I = m (R^2/2 + ...) about its axis; a solid's formula would be half that. Close enough to settle.
    p.changeDynamics(body, -1, localInertiaDiagonal=[m * (6 * R * R + h * h) / 12] * 2 + [m * R * R],
                     lateralFriction=config.tank.object_friction, restitution=0.0, physicsClientId=client)
    return body


class Apparatus:
    """The task's tubes in a row along y on the floor (z = floor_z), their water, beds and rewards."""

    def __init__(self, client: int, task: Task, config: TubesConfig | None = None, origin_xy=(0.27, 0.06),
                 floor_z: float = 0.0):
        self.client, self.task = client, task
        self.config = c = config or TubesConfig()
        tc = c.tank
        p.setGravity(0, 0, -tc.gravity, physicsClientId=client)
        p.setPhysicsEngineParameter(fixedTimeStep=tc.timestep_s, numSolverIterations=tc.solver_iterations,
                                    physicsClientId=client)
        self.bottom_z = floor_z + tc.bottom_thickness_cm * CM
        outer = [t.inner_diameter_cm + 2 * tc.wall_thickness_cm for t in task.tubes]
        span = sum(outer) + c.gap_cm * (len(outer) - 1)
        y, self.centers = origin_xy[1] - span / 2 * CM, {}
        for t, o in zip(task.tubes, outer):
            self.centers[t.name] = np.array([origin_xy[0], y + o / 2 * CM])
            y += (o + c.gap_cm) * CM
        self.tube_bodies = {t.name: self._make_tube(t) for t in task.tubes}
        self.beds, self.waters, self.water_of, self.rewards, self.visuals = {}, [], {}, {}, {}
        ball_v = c.reward_mass_g * G / tc.water.density
        done = set()
        for t in task.tubes:
            if t.substrate != "water":
                self.beds[t.name] = self._make_bed(t)
                continue
            if t.name in done:
                continue
            group = [task.tube(n) for n in task.group(t.name)]
            done.update(g.name for g in group)
            volume = sum(g.area_cm2 * g.level_cm for g in group) * CM ** 3 - ball_v * sum(g.reward for g in group)
            if len(group) == 1:
                w = Water(client, self.centers[t.name], self.bottom_z, t.inner_diameter_cm / 2 * CM, volume,
                          tc.timestep_s, tc.water)
            else:
                w = ChannelWater(client, [(self.centers[g.name], g.inner_diameter_cm / 2 * CM) for g in group],
                                 self.bottom_z, volume, tc.timestep_s, tc.water)
            self.waters.append(w)
            for g in group:
                self.water_of[g.name] = w
        for t in task.tubes:
            if t.reward:
                self.rewards[t.name] = self._make_reward(t)
            if t.substrate == "water":
                # an exact mesh (pybullet's cylinder visual stands ~1 mm proud: the camera would read the level high)
                vis = round_visual(client, "cylinder", t.inner_diameter_cm / 2 * CM * 0.995, t.height_cm * CM,
                                   tc.water_rgba[:3])
                self.visuals[t.name] = p.createMultiBody(0, -1, vis, [0, 0, -10], physicsClientId=client)
                p.changeVisualShape(self.visuals[t.name], -1, rgbaColor=list(tc.water_rgba), physicsClientId=client)
        for w in self.waters:
            w.update_level()
        self.sync_visuals()

    # -- building ----------------------------------------------------------------------------------------------
    def _make_tube(self, t: Tube) -> int:
        """sim/water.py's jar body (bottom plate, ring of staves, glass look) at this tube's size."""
        tc = self.config.tank
        maker = SimpleNamespace(config=tc, client=self.client,
                                center=np.array([*self.centers[t.name], self.bottom_z - tc.bottom_thickness_cm * CM]))
        return Tank._make_jar(maker, t.inner_diameter_cm / 2 * CM, tc.wall_thickness_cm * CM, t.height_cm * CM)

    def _make_bed(self, t: Tube) -> int:
        """A static granular bed filling the tube to its level: objects land on it, its surface stays."""
        R, h = t.inner_diameter_cm / 2 * CM * 0.995, t.level_cm * CM
        col = p.createCollisionShape(p.GEOM_CYLINDER, radius=R, height=h, physicsClientId=self.client)
        vis = round_visual(self.client, "cylinder", R, h, SUBSTRATE_RGB[t.substrate])
        body = p.createMultiBody(0, col, vis, [*self.centers[t.name], self.bottom_z + h / 2],
                                 physicsClientId=self.client)
        p.changeDynamics(body, -1, lateralFriction=0.9, restitution=0.0, physicsClientId=self.client)
        return body

    def _make_reward(self, t: Tube) -> int:
        """The floating reward (on a bed, resting on it), against the wall at -x: objects fall at +x."""
        c, tc = self.config, self.config.tank
        d = c.reward_diameter_cm * CM
        x = self.centers[t.name][0] - (t.inner_diameter_cm / 2 * CM - d / 2 - 0.1 * CM)
        if t.substrate == "water":
            from sim.water import _draft_sphere_m
            z = self.bottom_z + t.level_cm * CM + d / 2 - _draft_sphere_m(d / 2, c.reward_mass_g * G / 1000.0)
        else:
            z = self.bottom_z + t.level_cm * CM + d / 2
        ball = make_body(self.client, "sphere", [d] * 3, c.reward_mass_g * G, tc.ball_rgb,
                         [x, self.centers[t.name][1], z], tc.object_friction)
        if t.substrate == "water":
            self.water_of[t.name].add_body(ball, "sphere", [d] * 3)
        return ball

    # -- running -----------------------------------------------------------------------------------------------
    def levels_cm(self) -> dict:
        """Every tube's surface above its inner bottom as the simulation has it: the water's solved level, a bed's
        top."""
        out = {}
        for t in self.task.tubes:
            if t.name in self.beds:
                out[t.name] = (p.getAABB(self.beds[t.name], physicsClientId=self.client)[1][2] - self.bottom_z) / CM
            else:
                out[t.name] = self.water_of[t.name].depth / CM
        return out

    def sync_visuals(self):
        for name, body in self.visuals.items():
            h = self.task.tube(name).height_cm * CM
            p.resetBasePositionAndOrientation(body, [*self.centers[name], self.water_of[name].level - h / 2],
                                              [0, 0, 0, 1], physicsClientId=self.client)

    def step(self):
        for w in self.waters:
            w.step()
        p.stepSimulation(physicsClientId=self.client)

    def drop(self, tube: str, obj: ObjectSpec) -> dict:
        """Release `obj` upright just above `tube`'s surface, at +x of its axis (clear of the reward), and step
        until settled. Returns {"levels": measured levels (cm), "settled", "steps", "body"}."""
        c, tc, t = self.config, self.config.tank, self.task.tube(tube)
        size = obj.size_xyz_cm * CM
        x = self.centers[tube][0] + max(0.0, (t.inner_diameter_cm - obj.size_xyz_cm[0]) / 2 - 0.15) * CM
        z = self.bottom_z + (self.levels_cm()[tube] + c.release_above_cm) * CM + size[2] / 2
        pos = [x, self.centers[tube][1], z]
        if getattr(obj, "wall_cm", None) is not None:
            body = make_cup(self.client, obj, pos, c)
            cloud = cup_cloud(obj.dims_cm, obj.wall_cm, tc.water.points_per_body)
        else:
            body = make_body(self.client, obj.shape, size, obj.mass_g * G, obj.rgb, pos, tc.object_friction)
            cloud = None
        if t.substrate == "water":
            self.water_of[tube].add_body(body, obj.shape, size, cloud)
        settled, steps = self._settle(body)
        self.sync_visuals()
        return {"levels": self.levels_cm(), "settled": settled, "steps": steps, "body": body}

    def _settle(self, body: int) -> tuple[bool, int]:
        """Step until the dropped body and every reward are still and every level steady over `settle_windows`
        windows in a row (TankConfig's thresholds), or the timeout."""
        c, tc, cl = self.config, self.config.tank, self.client
        bodies = [body, *self.rewards.values()]
        win = tc.settle_window_steps
        seconds = win * tc.timestep_s
        quiet, before = 0, None
        for i in range(int(round(tc.settle_timeout_s / tc.timestep_s))):
            self.step()
            if (i + 1) % win:
                continue
            now = ([np.array(p.getBasePositionAndOrientation(b, physicsClientId=cl)[0]) for b in bodies],
                   self.levels_cm())
            if before is not None:
                still = all(np.linalg.norm(a - b) < tc.settle_speed_m_s * seconds for a, b in zip(now[0], before[0]))
                steady = all(abs(now[1][k] - before[1][k]) < c.settle_level_cm for k in now[1])
                quiet = quiet + 1 if still and steady else 0
                if quiet >= tc.settle_windows:
                    return True, i + 1
            before = now
        return False, i + 1


def simulate_drop(task: Task, tube: str, obj: ObjectSpec, config: TubesConfig | None = None) -> dict:
    """One drop in a fresh headless world: the measured levels before and after (cm), and whether it settled."""
    cl = p.connect(p.DIRECT)
    try:
        ap = Apparatus(cl, task, config)
        start = ap.levels_cm()
        out = ap.drop(tube, obj)
        return {"start": start, "levels": out["levels"], "settled": out["settled"], "steps": out["steps"]}
    finally:
        p.disconnect(cl)
