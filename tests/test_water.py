"""Buoyancy by simulation (sim/water.py), without the robot: objects dropped or stood in the jar settle where
Archimedes says, to within 2 %; the level solve is exact for prisms; the green ball floats at the surface."""

import math

import numpy as np
import pybullet as p
import pytest

from sim.objects import (DEFAULT_OBJECTS_FILE, JarSpec, ObjectsConfig, ObjectSpec, archimedes_cm3, load_objects,
                         min_mass_g_for)
from sim.water import CM, Tank, TankConfig, Water, WaterConfig, make_body, sample_points

JAR = JarSpec(12.0, 20.0, 14.0)


@pytest.fixture
def client():
    c = p.connect(p.DIRECT)
    yield c
    p.disconnect(c)


def new_tank(client, jar=JAR) -> Tank:
    tank = Tank(client, jar, [0.0, 0.0], 0.0)
    R = jar.inner_diameter_cm / 2
    pos = tank.ball_rest_pos()
    pos[0] += (R - tank.config.ball_diameter_cm / 2 - 0.1) * CM  # against the +x wall, as in the world
    p.resetBasePositionAndOrientation(tank.ball, pos, [0, 0, 0, 1], physicsClientId=client)
    assert tank.run_until_settled()[0]
    return tank


def displaced_cm3(tank: Tank, spec: ObjectSpec, z_bottom_cm: float | None = None) -> float:
    """Drop spec (its bottom 1 cm above the rim, or stand it at z_bottom_cm) beside the ball; cm^3 displaced."""
    level0 = tank.level_cm
    x = -(tank.config.ball_diameter_cm + 0.1) / 2 * CM  # the middle of the room beside the ball
    bottom = tank.rim_z + 0.01 if z_bottom_cm is None else tank.bottom_z + z_bottom_cm * CM
    tank.add_object(spec, [x, 0.0, bottom + spec.height_cm * CM / 2])
    settled, _ = tank.run_until_settled()
    assert settled
    return (tank.level_cm - level0) * tank.jar.area_cm2


CASES = [(shape, dims, m) for shape, dims, masses in [
    ("cylinder", (5.0, 8.0), (5, 60, 300, 600)),      # 157 cm^3
    ("cube", (5.0,), (5, 100, 600)),                  # 125 cm^3
    ("sphere", (6.0,), (5, 50, 600)),                 # 113 cm^3
    ("box", (4.0, 5.0, 6.0), (5, 80, 600)),           # 120 cm^3
] for m in masses]


@pytest.mark.parametrize("shape, dims, mass", CASES)
def test_dropped_object_displaces_what_archimedes_says(client, shape, dims, mass):
    spec = ObjectSpec("o", shape, dims, float(mass), (0.5, 0.5, 0.5))
    expected = archimedes_cm3(spec, JAR)
    assert expected == pytest.approx(mass if not spec.sinks else spec.volume_cm3, rel=1e-9)
    assert displaced_cm3(new_tank(client), spec) == pytest.approx(expected, rel=0.02)


DEFAULTS = load_objects(DEFAULT_OBJECTS_FILE)


@pytest.mark.parametrize("name", [o.name for o in DEFAULTS.train + DEFAULTS.probe])
def test_every_default_object(client, name):
    spec = DEFAULTS.get(name)
    assert displaced_cm3(new_tank(client, DEFAULTS.jar), spec) == pytest.approx(
        archimedes_cm3(spec, DEFAULTS.jar), rel=0.02)


def test_the_papers_cylinders(client):
    tank = new_tank(client)
    heavy = ObjectSpec("h", "cylinder", (6.36, 11.5), 420.0, (1, 0, 0))
    assert displaced_cm3(tank, heavy) == pytest.approx(365.3, rel=0.02)
    tank = new_tank(client)
    light = ObjectSpec("l", "cylinder", (6.36, 11.5), 14.0, (1, 0, 0))
    assert displaced_cm3(tank, light) == pytest.approx(14.0, rel=0.02)


def test_tall_sinker_sticking_out_displaces_only_its_wet_part(client):
    # 4 cm wide, 19 cm tall, 600 g, standing in 10 cm of water: L = 10 * 36 / (36 - 4) = 11.25 cm, V = 45 pi
    jar = JarSpec(12.0, 20.0, 10.0)
    tall = ObjectSpec("t", "cylinder", (4.0, 19.0), 600.0, (1, 0, 0))
    tank = new_tank(client, jar)
    got = displaced_cm3(tank, tall, z_bottom_cm=0.2)
    assert got == pytest.approx(45 * math.pi, rel=0.02)
    assert got < 0.7 * tall.volume_cm3  # clearly not the whole volume
    body = list(tank.water.bodies)[-1]  # the post, added after the ball
    assert p.getAABB(body, -1, physicsClientId=client)[1][2] > tank.water.level  # it does stick out


def test_ball_floats_at_the_surface(client):
    tank = new_tank(client)
    c = tank.config
    r = c.ball_diameter_cm / 2
    v_sub = tank.water.submerged_volume(tank.ball) / CM ** 3
    assert v_sub == pytest.approx(c.ball_mass_g, rel=0.01)  # floats: displaces its mass
    centre_cm = p.getBasePositionAndOrientation(tank.ball, physicsClientId=client)[0][2] / CM
    draft = tank.water.level / CM - (centre_cm - r)
    # the cap below the surface holds the ball's mass of water: pi h^2 (3r - h) / 3 = m, solved by bisection
    lo, hi = 0.0, 2 * r
    for _ in range(60):
        h = (lo + hi) / 2
        lo, hi = (h, hi) if math.pi * h * h * (3 * r - h) / 3 < c.ball_mass_g else (lo, h)
    assert draft == pytest.approx(h, abs=0.05)  # within half a millimetre
    assert tank.level_cm == pytest.approx(JAR.water_depth_cm, abs=0.002)  # the jar's depth is with the ball in


def test_level_solve_is_exact_for_prisms(client):
    # static posts, no dynamics: the level obeys L = L0 + a L / A exactly (the layer smoothing is exact here)
    A = 36 * math.pi                    # cm^2, 12 cm jar
    water = Water(client, [0.0, 0.0], 0.0, 0.06, A * 3.0 * CM ** 3, 1 / 240)   # 3 cm of water alone
    standing = make_body(client, "box", [0.04, 0.04, 0.19], 0.0, (1, 0, 0), [0.0, 0.0, 0.095], 0.5)
    water.add_body(standing, "box", [0.04, 0.04, 0.19])
    water.update_level()
    L = 3.0 * A / (A - 16)
    assert water.depth / CM == pytest.approx(L, rel=1e-6)
    assert water.submerged_volume(standing) / CM ** 3 == pytest.approx(16 * L, rel=1e-6)
    # the same 4 x 5 x 6 box laid on its side (90 degrees about x): footprint 4 x 6, 5 tall
    water.remove_body(standing)
    p.removeBody(standing, physicsClientId=client)
    lying = make_body(client, "box", [0.04, 0.05, 0.06], 0.0, (1, 0, 0), [0.0, 0.0, 0.025], 0.5)
    p.resetBasePositionAndOrientation(lying, [0.0, 0.0, 0.025], p.getQuaternionFromEuler([math.pi / 2, 0, 0]),
                                      physicsClientId=client)
    water.add_body(lying, "box", [0.04, 0.05, 0.06])
    water.update_level()
    L = 3.0 * A / (A - 24)
    assert L < 5.0
    assert water.submerged_volume(lying) / CM ** 3 == pytest.approx(24 * L, rel=1e-6)
    # outside the jar nothing is wet
    p.resetBasePositionAndOrientation(lying, [0.2, 0.0, 0.025], [0, 0, 0, 1], physicsClientId=client)
    water.update_level()
    assert water.submerged_volume(lying) == 0.0 and water.depth / CM == pytest.approx(3.0, rel=1e-9)



def test_a_sphere_half_under_holds_half_its_volume(client):
    # a 6 cm sphere held with its centre 5 cm up, and just enough water for the level to settle there: the solve
    # must find L = 5 cm, the wet half 2/3 pi r^3 (36 pi cm^3), its centre of buoyancy 3r/8 below the centre, and
    # the waterplane the sphere's equator (closed form: the cap pi h^2 (3r - h) / 3)
    A, r = 36 * math.pi, 3.0
    half = 2 / 3 * math.pi * r ** 3
    water = Water(client, [0.0, 0.0], 0.0, 0.06, (A * 5.0 - half) * CM ** 3, 1 / 240)
    ball = make_body(client, "sphere", [0.06] * 3, 0.1, (0, 1, 0), [0.0, 0.0, 0.05], 0.5)
    water.add_body(ball, "sphere", [0.06] * 3)
    water.update_level()
    assert water.depth / CM == pytest.approx(5.0, abs=1e-8)
    assert water.submerged_volume(ball) / CM ** 3 == pytest.approx(half, rel=1e-8)
    body = water.bodies[ball]
    assert body.cob[2] / CM == pytest.approx(5.0 - 3 * r / 8, abs=1e-6)
    assert body.waterplane / CM ** 2 == pytest.approx(math.pi * r * r, rel=1e-6)
    # sunk 2 cm into the floor the sphere is no longer whole in the jar: its points are used, and the floor cuts off
    # a 2 cm cap (pi 2^2 (9 - 2) / 3 cm^3); the rest, its top 4 cm up, is under water. The points resolve the cut
    # to half a cell (0.19 cm) of the 8 pi cm^2 section; the closed form, blind to the floor, would say 36 pi
    p.resetBasePositionAndOrientation(ball, [0.0, 0.0, 0.01], [0, 0, 0, 1], physicsClientId=client)
    water.update_level()
    assert water.submerged_volume(ball) / CM ** 3 == pytest.approx(4 / 3 * math.pi * r ** 3 - 28 * math.pi / 3,
                                                                   abs=8 * math.pi * 0.19)

def test_a_sphere_wholly_under_is_wet_all_through_and_one_at_the_surface_a_cap(client):
    # the floating sphere's step takes the cap without posing its bounds, but only where the wholly-wet test cannot
    # pass: a sphere deep under water still counts its points' volume (the shortcut), which differs from the
    # closed-form whole sphere in the last bits; one at the surface gets the cap
    from sim.water import _cap
    A = 36 * math.pi
    water = Water(client, [0.0, 0.0], 0.0, 0.06, A * 10.0 * CM ** 3, 1 / 240)   # 10 cm of water alone
    ball = make_body(client, "sphere", [0.06] * 3, 0.1, (0, 1, 0), [0.0, 0.0, 0.04], 0.5)
    water.add_body(ball, "sphere", [0.06] * 3)
    b = water.bodies[ball]
    assert b.volume != _cap(0.06, 0.03)[0]
    water.update_level()                             # its top 3 cm under the surface
    assert water.submerged_volume(ball) == b.volume and b.cob.tolist() == [0.0, 0.0, 0.04]
    p.resetBasePositionAndOrientation(ball, [0.0, 0.0, 0.105], [0, 0, 0, 1], physicsClientId=client)
    water.update_level()                             # cut by the surface
    h = water.level - (0.105 - 0.03)
    assert 0 < h < 0.06 and water.submerged_volume(ball) == _cap(h, 0.03)[0]


def test_the_spheres_level_in_python_floats_is_numpys_bit_for_bit():
    # the level with spheres alone is solved in Python floats (the ball floats there at every step): it must be the
    # numpy solve's level exactly. Spheres dry, cut and under, 1 to 3 of them (3: a short sum's order shows), from
    # levels above and below the answer; and np.clip's -0.0 kept
    rng = np.random.default_rng(0)
    water = Water(0, [0.0, 0.0], 0.0, 0.06, 0.6e-3, 1 / 240)    # no body added: no pybullet call
    for n in (1, 2, 3):
        for _ in range(200):
            radii = rng.uniform(0.005, 0.03, n)
            bottoms = rng.uniform(-0.01, 0.12, n)
            water.level = float(rng.uniform(0.0, 0.15))
            base = float(rng.uniform(0.02, 0.1))
            fast = water._solve(base, [], bottoms.tolist(), radii.tolist())
            assert fast == water._solve_points_numpy(base, [], bottoms, radii)
    assert math.copysign(1, float(np.clip(np.array([-0.0]), 0.0, 1.0)[0])) == -1   # what _clip mirrors
    from sim.water import _clip
    assert math.copysign(1, _clip(-0.0, 0.0, 1.0)) == -1 and _clip(2.0, 0.0, 1.0) == 1.0 and _clip(-1, 0.0, 1) == 0


def test_the_points_level_with_caps_in_python_floats_is_numpys_bit_for_bit():
    # a cut body's points beside 0 to 3 spheres in closed form (a floater beside the ball): the solve with the caps
    # in Python floats and np.clip as maximum then minimum gives numpy's level exactly
    rng = np.random.default_rng(1)
    water = Water(0, [0.0, 0.0], 0.0, 0.06, 0.6e-3, 1 / 240)    # no body added: no pybullet call
    for n in (0, 1, 2, 3):
        for _ in range(100):
            k, layer = int(rng.integers(1, 400)), float(rng.uniform(0.001, 0.004))
            z = rng.uniform(0.03, 0.07, k)
            w = np.full(k, float(rng.uniform(1e-8, 1e-7)))
            parts = [(w, z, layer, float(rng.uniform(0.0, 1e-4)))]
            radii, bottoms = rng.uniform(0.005, 0.03, n), rng.uniform(-0.01, 0.08, n)
            water.level = float(rng.uniform(0.03, 0.07))
            base = float(rng.uniform(0.02, 0.05))
            fast = water._solve_points(base, parts, bottoms.tolist(), radii.tolist())
            assert fast == water._solve_points_numpy(base, parts, bottoms, radii)


def test_a_body_whose_points_cannot_reach_the_wall_is_solved_as_with_the_walls_mask(client, monkeypatch):
    # a 5 cm cube beside the ball, cut by the surface, turned any way about the vertical and tilted a little: its
    # bounding sphere reaches the 6 cm wall, but at most such poses its points cannot (Water._across bounds them, to
    # rounding: the water keeps 1e-9 m clear of it), and the mask is then left out; level, V_sub, waterplane and
    # centre of buoyancy are the same bits as with the mask
    water = Water(client, [0.0, 0.0], 0.0, 0.06, math.pi * 0.06 ** 2 * 0.05, 1 / 240)
    cube = make_body(client, "cube", [0.05] * 3, 0.1, (1, 0, 0), [-0.02, 0.0, 0.05], 0.5)
    water.add_body(cube, "cube", [0.05] * 3)
    b = water.bodies[cube]
    rng = np.random.default_rng(2)
    skipped = 0
    for _ in range(60):
        q = p.getQuaternionFromEuler([*rng.normal(0.0, 0.2, 2), rng.uniform(-math.pi, math.pi)])  # as it floats
        x = float(rng.uniform(-0.025, -0.02))   # about where an object lands beside the ball (2.05 cm off the axis)
        p.resetBasePositionAndOrientation(cube, [x, 0.0, float(rng.uniform(0.04, 0.06))], q, physicsClientId=client)
        R = np.array(p.getMatrixFromQuaternion(q)).reshape(3, 3)
        posed = R @ b.points_t
        assert np.hypot(posed[0], posed[1]).max() <= Water._across(R, b) + 1e-15
        skipped += abs(x) + b.reach >= 0.06 > abs(x) + Water._across(R, b) + 1e-9
        results = []
        for across in (Water._across, lambda R, b: math.inf):    # as it runs, then always with the mask
            monkeypatch.setattr(Water, "_across", staticmethod(across))
            water.level = 0.05
            water.update_level()
            results.append((water.level, b.v_sub, b.waterplane, b.cob.tolist()))
            monkeypatch.undo()
        assert results[0] == results[1]
    assert skipped >= 30


@pytest.mark.parametrize("shape, size", [("cylinder", (0.05, 0.05, 0.08)), ("sphere", (0.06,) * 3),
                                         ("box", (0.04, 0.05, 0.06))])
def test_sample_points_fill_the_shape(shape, size):
    pts, w, spacing = sample_points(shape, size, 4096)
    exact = {"cylinder": math.pi * 0.025 ** 2 * 0.08, "sphere": math.pi * 0.06 ** 3 / 6, "box": 0.04 * 0.05 * 0.06}
    assert w.sum() == pytest.approx(exact[shape], rel=1e-12) and np.allclose(w, w[0])
    assert 2000 < len(pts) < 8000 and np.all((0 < spacing) & (spacing < np.asarray(size) / 8))
    half = np.asarray(size) / 2
    assert np.all(np.abs(pts) <= half)
    if shape == "sphere":
        assert np.all(np.sum((pts / half) ** 2, axis=1) <= 1)
    assert np.allclose(pts.mean(axis=0), 0, atol=1e-12)       # centre of buoyancy of the whole body: its centre
    again, _, _ = sample_points(shape, size, 4096)
    assert np.array_equal(pts, again)


def test_bad_input_is_refused(client):
    with pytest.raises(ValueError, match="shape"):
        sample_points("cone", (0.1, 0.1, 0.1), 100)
    with pytest.raises(ValueError, match="size_xyz"):
        sample_points("box", (0.1, -0.1, 0.1), 100)
    with pytest.raises(ValueError, match="ball"):
        Tank(client, JarSpec(4.0, 20.0, 10.0), [0, 0], 0.0, TankConfig())


# -- the objects file's limits that come from the water ---------------------------------------------------------------

def test_the_shallowest_water_the_file_admits_floats_the_ball(client):
    """ObjectsConfig.min_water_depth_cm: the ball floats clear of the bottom there (1.3 cm of water under it);
    water shallower than its draft is refused by the tank in one clear line (it was a negative water volume, and
    a runner's worker failing on it again and again)."""
    cfg = ObjectsConfig()
    draft = Tank.ball_draft_cm(TankConfig())
    assert draft == pytest.approx(0.70, abs=0.01) and cfg.min_water_depth_cm >= draft + 1.0
    tank = new_tank(client, JarSpec(12.0, 19.5, cfg.min_water_depth_cm))
    z = p.getBasePositionAndOrientation(tank.ball, physicsClientId=client)[0][2]
    assert z - tank.config.ball_diameter_cm / 2 * CM - tank.bottom_z > 1.0 * CM      # floating, well off the bottom
    assert tank.level_cm == pytest.approx(cfg.min_water_depth_cm, abs=0.002)
    spec = ObjectSpec("o", "cube", (3.0,), 60.0, (0.5, 0.5, 0.5))   # sinks, sticks out of 2 cm of water
    assert displaced_cm3(tank, spec) == pytest.approx(archimedes_cm3(spec, tank.jar), rel=0.02)
    for depth in (0.01, 0.5):
        with pytest.raises(ValueError, match="too shallow for the ball to float"):
            Tank(client, JarSpec(12.0, 19.5, depth), [0, 0], 0.0, TankConfig())


def test_the_lightest_floater_the_file_admits_is_one_the_water_can_follow():
    """ObjectsConfig.min_mass_per_area_g_cm2: at the limit a floater bobs at w dt <= 0.83 of the timestep (the
    level's rise included); instability starts near 1.5 (measured: ObjectsConfig)."""
    cfg, tank, water = ObjectsConfig(), TankConfig(), WaterConfig()
    mass_per_area = cfg.min_mass_per_area_g_cm2 * 10.0          # g/cm^2 -> kg/m^2
    w_dt = math.sqrt(water.density * water.gravity / mass_per_area) * tank.timestep_s
    assert w_dt <= 0.85


@pytest.mark.parametrize("jar, shape, dims", [
    (JarSpec(12.0, 19.5, 14.0), "cylinder", (7.0, 1.0)),       # 0.3 g of it jumped out of the jar
    (JarSpec(29.0, 20.0, 14.0), "cylinder", (24.5, 1.0)),      # the widest jar, its widest disc
    (JarSpec(29.0, 20.0, 14.0), "box", (17.3, 17.3, 1.0)),
    (JarSpec(12.0, 19.5, 14.0), "box", (1.0, 1.0, 7.0)),       # a stick: it floats lying down
    (JarSpec(16.0, 19.5, 14.0), "sphere", (11.5,)),
])
def test_the_lightest_admitted_floaters_settle_where_archimedes_says(client, jar, shape, dims):
    least = min_mass_g_for(ObjectSpec("o", shape, dims, 1.0, (0.5, 0.5, 0.5)), jar)
    spec = ObjectSpec("o", shape, dims, least, (0.5, 0.5, 0.5))
    assert displaced_cm3(new_tank(client, jar), spec) == pytest.approx(least, rel=0.02)
