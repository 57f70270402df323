"""The no-physics paths' noise model (sim/sensor_model.py) tied to the simulator: what the simulated camera, hand
and jar measure on a few objects lies within 3 sd of the model (about its per-shape bias), and the model draws
what it says, reproducibly per (seed, object)."""

import math

import numpy as np
import pybullet as p
import pytest

from sim.objects import DEFAULT_OBJECTS_FILE, ObjectSpec, load_objects
from sim.oracle import truth
from sim.sensor_model import SensorModel
from sim.world import World
from train.learning.experiment import closed_form_outcomes

MODEL = SensorModel()
OBJECTS = [  # (spec, orientation as euler xyz): each shape, a turned box and one on its side, small and large
    (ObjectSpec("cyl", "cylinder", (4.3, 7.9), 200.0, (0.2, 0.6, 0.3)), (0, 0, 0)),
    (ObjectSpec("cube", "cube", (2.2,), 50.0, (0.9, 0.4, 0.1)), (0, 0, 0.5)),
    (ObjectSpec("ball", "sphere", (6.8,), 90.0, (0.3, 0.3, 0.8)), (0, 0, 0)),
    (ObjectSpec("small_ball", "sphere", (2.0,), 9.0, (0.7, 0.2, 0.6)), (0, 0, 0)),
    (ObjectSpec("box", "box", (8.4, 2.6, 5.1), 300.0, (0.6, 0.6, 0.1)), (0, 0, 1.1)),
    (ObjectSpec("lying", "box", (3.3, 7.0, 1.9), 120.0, (0.1, 0.1, 0.1)), (math.pi / 2, 0, 0.2)),
]


@pytest.fixture(scope="module")
def world():
    w = World(load_objects(DEFAULT_OBJECTS_FILE), seed=0)
    yield w
    w.close()


@pytest.mark.parametrize("k", range(len(OBJECTS)), ids=[o[0].name for o in OBJECTS])
def test_the_cameras_errors_are_within_3_sd_of_the_model(world, k):
    spec, euler = OBJECTS[k]
    world.reset(spec.name)
    body = world.place_object(spec, p.getQuaternionFromEuler(euler))
    world.step(48)
    m, true = world.look(body).measurement, truth(world.client, body)
    rel = m["extent_cm"] / true["extent_cm"] - 1.0
    bias = dict(MODEL.extent_rel_bias)[spec.shape]
    assert np.all(np.abs(rel - bias) <= 3 * MODEL.extent_rel_sd), rel
    assert abs(m["fill"] - true["fill"] - dict(MODEL.fill_bias)[spec.shape]) <= 3 * MODEL.fill_sd
    assert np.all(np.abs(m["rgb"] - true["rgb"]) <= 3 * MODEL.rgb_sd)


def test_the_hands_and_the_jars_errors_are_within_3_sd_of_the_model(world):
    out = world.run_episode("yellow_light_sphere")    # 60 g, a floater: it displaces its mass
    spec = world.spec("yellow_light_sphere")
    assert abs(out.measurement["mass_g"] - spec.mass_g) <= 3 * MODEL.mass_sd_g
    sd = math.hypot(MODEL.outcome_rel_sd * out.archimedes_cm3, MODEL.outcome_abs_sd_cm3)
    assert abs(out.observed_cm3 - out.archimedes_cm3) <= 3 * sd
    m = world.inspect("grey_heavy_cube")
    assert abs(m["mass_g"] - world.spec("grey_heavy_cube").mass_g) <= 3 * MODEL.mass_sd_g


def test_the_model_draws_what_it_says():
    model = SensorModel(rgb_sd=0.01, extent_rel_sd=0.02, fill_sd=0.03, mass_sd_g=2.0, outcome_rel_sd=0.01,
                        outcome_abs_sd_cm3=0.5)
    spec = ObjectSpec("s", "sphere", (5.0,), 30.0, (0.5, 0.4, 0.3))   # a floater: 30 cm^3 whatever its size
    jar = load_objects(DEFAULT_OBJECTS_FILE).jar
    rng = np.random.default_rng(1)
    ms = [model.measure(spec, rng) for _ in range(4000)]
    ext = np.array([m["extent_cm"] for m in ms]) / 5.0 - 1.0
    fill = np.array([m["fill"] for m in ms]) - spec.fill
    assert ext.mean() == pytest.approx(dict(model.extent_rel_bias)["sphere"], abs=0.002)
    assert ext.std() == pytest.approx(0.02, rel=0.15)   # sorting three draws narrows each a little
    assert fill.mean() == pytest.approx(dict(model.fill_bias)["sphere"], abs=0.002)
    assert fill.std() == pytest.approx(0.03, rel=0.05)
    np.testing.assert_allclose(np.std([m["rgb"] for m in ms], axis=0), 0.01, rtol=0.05)
    assert np.std([m["mass_g"] for m in ms]) == pytest.approx(2.0, rel=0.05)
    vs = np.array([model.observe(spec, jar, rng) for _ in range(4000)])
    assert vs.mean() == pytest.approx(30.0, abs=0.05)
    assert vs.std() == pytest.approx(math.hypot(0.3, 0.5), rel=0.05)


def test_same_seed_same_draws():
    objects = load_objects(DEFAULT_OBJECTS_FILE)
    a = closed_form_outcomes(objects, sensor=SensorModel(), seed=3)
    b = closed_form_outcomes(objects, sensor=SensorModel(), seed=3)
    c = closed_form_outcomes(objects, sensor=SensorModel(), seed=4)
    assert a == b and a != c
    name = objects.train[0].name
    assert a[0][name]["measurement"] != c[0][name]["measurement"]
    # an object's draws depend on (seed, name) only, not on what else is drawn
    one = MODEL.measure(objects.train[0], MODEL.rng(3, name))
    assert one == a[0][name]["measurement"]


def test_a_light_object_is_never_felt_below_the_floor_and_the_agent_stores_it():
    """The no-physics path's felt mass, like the world's (tests/test_world.py): an object lighter than the hand's
    noise is felt at least `min_felt_mass_g`, never zero or negative ("measurement 'mass_g' must be > 0") nor a
    hair above zero, whose weight no map unit answers ("a present map has no activity to store")."""
    import torch
    from aesop_torch.agent import Agent, AgentConfig
    from sim.objects import ObjectsConfig
    from sim.world import WorldConfig
    from train.learning.experiment import stack_measurements
    model = SensorModel(mass_sd_g=5.0)
    floor = model.min_felt_mass_g
    assert floor == WorldConfig().min_felt_mass_g == ObjectsConfig().min_mass_g > 0
    for mass in (ObjectsConfig().min_mass_g, 1e-300):      # the lightest the file admits, and far below it
        spec = ObjectSpec("feather", "cube", (1.0,), mass, (0.9, 0.9, 0.2))
        felt = [model.measure(spec, model.rng(s, spec.name))["mass_g"] for s in range(200)]
        assert min(felt) == floor and sum(f == floor for f in felt) > 50      # about half the draws are floored
    spec = ObjectSpec("feather", "cube", (1.0,), ObjectsConfig().min_mass_g, (0.9, 0.9, 0.2))
    m = next(m for s in range(200) if (m := model.measure(spec, model.rng(s, spec.name)))["mass_g"] == floor)
    agent = Agent(AgentConfig())
    acts, present = agent.activities(stack_measurements([m]))
    assert float(acts[0, list(agent.maps).index("weight")].max()) > 0     # the weight map still answers
    agent.remember(stack_measurements([m]), torch.tensor([0.1]), torch.tensor([False]), torch.tensor([False]),
                   torch.tensor([0]))
    assert int(agent.memory.count[0]) == 1


def test_the_closed_form_tells_the_fate_the_robot_sees_not_the_engines():
    """Cubes of 5 cm (125 cm^3) in the default jar: 125.25 g (density 1.002) sinks by the engine's test, but on the
    physics path such a sinker is seen floating (SensorModel.fate_seen_sinking_above_g_cm3, benches/fate_perception.py);
    126.25 g (1.010) is seen on the bottom, 123.75 g (0.990) floating. Without a sensor model the fate is exact."""
    from sim.objects import parse_objects
    jar = {"inner_diameter_cm": 12.0, "height_cm": 19.5, "water_depth_cm": 14.0}
    cubes = [{"name": f"c{i}", "shape": "cube", "color": "red", "dims_cm": [5.0], "mass_g": m}
             for i, m in enumerate((125.25, 126.25, 123.75))]
    objs = parse_objects({"jar": jar, "train": cubes, "probe": []})
    assert [o.sinks for o in objs.train] == [True, True, False]
    seen, _ = closed_form_outcomes(objs, sensor=MODEL, seed=0)
    assert [seen[n]["sank"] for n in ("c0", "c1", "c2")] == [False, True, False]
    exact, _ = closed_form_outcomes(objs)
    assert [exact[n]["sank"] for n in ("c0", "c1", "c2")] == [True, True, False]
