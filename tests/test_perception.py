"""Perception from the camera against the engine's truth (sim/oracle.py): each shape, a box turned about z and a
box lying on its side: extents within 5 %, fill within 0.08, colour within 0.02; the hand is sent where the eye saw
the top; and the run path reads no engine truth (the engine's answers are made to fail while it perceives)."""

import math

import numpy as np
import pybullet as p
import pytest

import sim.episode as episode
from sim.objects import DEFAULT_OBJECTS_FILE, ObjectSpec, load_objects
from sim.oracle import aabb_top, truth
from sim.perception import min_area_rect, support
from sim.water import make_body
from sim.world import World

CASES = {  # name: (shape, dims, rgb, orientation as euler xyz)
    "cylinder": ("cylinder", (6.0, 10.0), (0.85, 0.10, 0.10), (0, 0, 0)),
    "thin_cylinder": ("cylinder", (1.6, 8.5), (0.10, 0.70, 0.20), (0, 0, 0.7)),
    "tall_cylinder": ("cylinder", (3.0, 18.0), (0.95, 0.95, 0.95), (0, 0, 0)),   # the side view looks again, wider
    "cube": ("cube", (4.0,), (0.50, 0.50, 0.50), (0, 0, 0)),
    "small_cube": ("cube", (1.5,), (0.95, 0.50, 0.05), (0, 0, 0.3)),
    "sphere": ("sphere", (5.0,), (0.10, 0.25, 0.85), (0, 0, 0)),
    "small_sphere": ("sphere", (1.8,), (0.90, 0.85, 0.10), (0, 0, 0)),
    "box": ("box", (7.0, 3.0, 2.0), (0.55, 0.15, 0.70), (0, 0, 0)),
    "box_turned": ("box", (8.0, 2.0, 4.5), (0.10, 0.80, 0.85), (0, 0, 0.6)),
    "box_on_its_side": ("box", (6.0, 1.7, 3.5), (0.95, 0.55, 0.70), (math.pi / 2, 0, 0.35)),
}


@pytest.fixture(scope="module")
def world():
    w = World(load_objects(DEFAULT_OBJECTS_FILE), seed=0)
    yield w
    w.close()


def put(world, name):
    shape, dims, rgb, euler = CASES[name]
    world.reset(name)
    body = world.place_object(ObjectSpec(name, shape, dims, 100.0, rgb), p.getQuaternionFromEuler(euler))
    world.step(48)  # at rest on the stand
    return body


@pytest.mark.parametrize("name", list(CASES))
def test_perceived_against_the_engine(world, name):
    body = put(world, name)
    seen = world.look(body)
    true = truth(world.client, body)
    m = seen.measurement
    assert set(m) == {"rgb", "extent_cm", "fill", "mass_g"}
    np.testing.assert_allclose(m["extent_cm"], true["extent_cm"], rtol=0.05)
    assert m["fill"] == pytest.approx(true["fill"], abs=0.08)
    np.testing.assert_allclose(m["rgb"], true["rgb"], atol=0.02)
    # the hand goes where the eye saw the top: within 3 mm of the engine's box around the object
    np.testing.assert_allclose(seen.top_centre, aabb_top(world.client, body), atol=0.003)


def test_the_shapes_are_told_apart_by_fill(world):
    # the shape cue separates what the file calls the shapes: box/cube 1, cylinder pi/4, sphere pi/6
    fills = {}
    for name in ("cube", "box_turned", "cylinder", "sphere"):
        fills[name] = world.look(put(world, name)).measurement["fill"]
    assert min(fills["cube"], fills["box_turned"]) > fills["cylinder"] + 0.1 > fills["sphere"] + 0.2


def test_same_scene_same_percept(world):
    a = world.look(put(world, "box_turned")).measurement
    b = world.look(put(world, "box_turned")).measurement
    for k in ("rgb", "extent_cm", "fill"):
        assert np.array_equal(a[k], b[k])


def test_an_object_out_of_view_is_refused(world):
    world.reset("nothing")
    far = make_body(world.client, "cube", [0.03] * 3, 0.1, (0.5, 0.5, 0.5), [1.5, 1.5, 0.015], 0.8)
    with pytest.raises(RuntimeError, match="not in the side view"):
        world.look(far)
    p.removeBody(far, physicsClientId=world.client)


def test_the_run_path_reads_no_engine_truth(world, monkeypatch):
    """While the robot looks, nothing may ask the engine about the object (not even its pose); while it takes and
    weighs it, nothing may read its bounding box, collision shape, dynamics or colour (the hold itself is physics:
    the constraint attaches at the object's pose)."""
    def banned(fn):
        def refuse(*a, **k):
            raise AssertionError(f"p.{fn} read while perceiving")
        return refuse

    truth_fns = ("getAABB", "getCollisionShapeData", "getDynamicsInfo", "getVisualShapeData")
    real_look, real_take = World.look, episode._take

    def look(self, body):
        with monkeypatch.context() as m:
            for fn in truth_fns + ("getBasePositionAndOrientation",):
                m.setattr(p, fn, banned(fn))
            return real_look(self, body)

    def take(world_, body, seen):
        with monkeypatch.context() as m:
            for fn in truth_fns:
                m.setattr(p, fn, banned(fn))
            return real_take(world_, body, seen)

    monkeypatch.setattr(World, "look", look)
    monkeypatch.setattr(episode, "_take", take)
    m = world.inspect("grey_heavy_cube")   # a 5 cm cube of 300 g
    np.testing.assert_allclose(m["extent_cm"], 5.0, rtol=0.05)
    assert m["fill"] == pytest.approx(1.0, abs=0.08)
    assert m["mass_g"] == pytest.approx(300.0, abs=5.0)


def test_min_area_rect_finds_a_turned_rectangle():
    rng = np.random.default_rng(0)
    a = 0.4
    u, v = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    s, t = rng.uniform(-3, 3, 2000), rng.uniform(-1, 1, 2000)
    corners = [(-3, -1), (3, -1), (3, 1), (-3, 1)]
    pts = np.concatenate([np.outer(s, u) + np.outer(t, v), [x * u + y * v for x, y in corners]]) + [1.0, 2.0]
    centre, sides, angle = min_area_rect(pts)
    np.testing.assert_allclose(centre, [1.0, 2.0], atol=1e-9)
    np.testing.assert_allclose(sides, [6.0, 2.0], atol=1e-9)
    assert math.isclose(angle % math.pi, a, abs_tol=1e-9)


def test_support_places_a_digital_edge_to_a_fraction_of_a_pixel():
    # the centres of the boundary pixels of a half-plane x . n <= 7.3 (pixels of side 1), at several angles
    for ang in (0.0, 0.2, math.pi / 4, 1.0):
        n = np.array([math.cos(ang), math.sin(ang)])
        g = np.stack(np.meshgrid(np.arange(-40, 40) + 0.5, np.arange(-40, 40) + 0.5), -1).reshape(-1, 2)
        inside = g @ n <= 7.3
        thick = abs(n[0]) + abs(n[1])
        edge = g[inside & (g @ n > 7.3 - thick) & (np.abs(g @ np.array([-n[1], n[0]])) < 20)]
        assert support(edge, n, 1.0) == pytest.approx(7.3, abs=0.5)
