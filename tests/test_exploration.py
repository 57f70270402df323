"""The robot chooses its next object (AgentConfig.explore "active", aesop_torch/exploration.py): the one whose
comparison with a remembered episode changes the fewest live properties; in the sweep's cells, the experiment (and
its resume) and the population alike."""

import copy

import pytest
import torch

from aesop_torch import Agent, AgentConfig
from aesop_torch.exploration import choose_in_order, next_object

RED, BLUE = (0.85, 0.1, 0.1), (0.1, 0.2, 0.85)


def objects(*specs):
    """(rgb, extents, fill, mass) per object -> one batched measurement."""
    return {"rgb": torch.tensor([s[0] for s in specs]), "extent_cm": torch.tensor([s[1] for s in specs]),
            "fill": torch.tensor([s[2] for s in specs]), "mass_g": torch.tensor([float(s[3]) for s in specs])}


@pytest.fixture(scope="module")
def developed():
    return Agent(AgentConfig.contextual(seed=0))


def test_the_next_object_is_the_one_that_changes_fewest_properties_from_a_remembered_one(developed):
    agent = developed.select([0])
    # remembered: a red 5 cm cube of 50 g (floats)
    agent.remember(objects((RED, [5.0] * 3, 1.0, 50)), torch.tensor([50.0]), torch.tensor([False]),
                   torch.tensor([False]), sank=torch.tensor([False]))
    # on the stand, in the teacher's order: a blue 8 cm cube of 300 g (colour, size, weight changed), a blue 5 cm
    # sphere of 50 g (colour, fill), a red 5 cm cube of 300 g (weight alone): the last is the clean comparison
    stand = objects((BLUE, [8.0] * 3, 1.0, 300), (BLUE, [5.0] * 3, 0.5236, 50), (RED, [5.0] * 3, 1.0, 300))
    acts, present = agent.activities(stand)
    rank = torch.tensor([[0, 1, 2]])
    assert next_object(agent, acts, present, torch.ones(1, 3, dtype=torch.bool), rank).tolist() == [2]
    # without it, the sphere (two changed) before the large cube (three)
    assert next_object(agent, acts, present, torch.tensor([[True, True, False]]), rank).tolist() == [1]
    # nothing remembered: the teacher's order decides
    empty = developed.select([0])
    assert next_object(empty, acts, present, torch.ones(1, 3, dtype=torch.bool), rank).tolist() == [0]
    # the chosen object moves to position t, the others keep the teacher's order
    orders = torch.tensor([[3, 0, 1, 2]])
    four_acts, four_present = agent.activities(objects((BLUE, [8.0] * 3, 1.0, 300), (BLUE, [5.0] * 3, 0.5236, 50),
                                                       (RED, [5.0] * 3, 1.0, 300), (RED, [5.0] * 3, 1.0, 50)))
    assert choose_in_order(agent, four_acts, four_present, orders, 1).tolist() == [2]
    assert orders.tolist() == [[3, 2, 0, 1]]


def test_the_config_refuses_an_unknown_explore_in_one_line():
    with pytest.raises(ValueError, match="explore must be one of teacher, active"):
        AgentConfig.contextual(explore="random")


@pytest.fixture(scope="module")
def small_set():
    from sim.make_objects import generate
    from sim.objects import parse_objects
    from sim.sensor_model import SensorModel
    from train.experiment import closed_form_outcomes
    objs = parse_objects(generate(1000, 8, 3, pairs=True))
    outcomes, probes = closed_form_outcomes(objs, sensor=SensorModel(), seed=1000)
    return [o.name for o in objs.train], [o.name for o in objs.probe], outcomes, probes


def _experiment(small_set, explore, orders):
    from train.experiment import Experiment
    names, pnames, outcomes, probes = small_set
    exp = Experiment(names, pnames, copy.deepcopy(orders), seed=0,
                     config=AgentConfig.contextual(explore=explore, fate_recalls=4))
    exp.outcomes, exp.probes = dict(outcomes), dict(probes)
    return exp


def test_an_active_experiment_rewrites_its_orders_and_resumes_as_if_never_stopped(small_set):
    from train.experiment import Experiment
    teacher = [[0, 1, 2, 3, 4, 5, 6, 7], [7, 6, 5, 4, 3, 2, 1, 0]]
    whole = _experiment(small_set, "active", teacher)
    while not whole.done:
        whole.step(lambda name, b, t: whole.outcomes[name])
    assert all(sorted(o) == list(range(8)) for o in whole.orders)
    assert [o[0] for o in whole.orders] == [0, 7]          # the teacher's first object
    assert whole.orders != teacher                          # the robot chose otherwise somewhere
    assert [r["object"] for r in whole.records[0]] == [whole.train_names[i] for i in whole.orders[0]]
    # stopped after 3 episodes, checkpointed and resumed: the same choices, records and knowledge
    part = _experiment(small_set, "active", teacher)
    for _ in range(3):
        part.step(lambda name, b, t: part.outcomes[name])
    resumed = Experiment.from_state_dict(copy.deepcopy(part.state_dict()))
    while not resumed.done:
        resumed.step(lambda name, b, t: resumed.outcomes[name])
    assert resumed.orders == whole.orders
    assert resumed.records == whole.records
    # the teacher's order (the default) is kept as given
    kept = _experiment(small_set, "teacher", teacher)
    kept.step(lambda name, b, t: kept.outcomes[name])
    kept.step(lambda name, b, t: kept.outcomes[name])
    assert kept.orders == teacher


def test_the_population_of_active_agents_ends_as_the_experiment(small_set):
    from train.population import run_population
    names, pnames, outcomes, probes = small_set
    teacher = [[0, 1, 2, 3, 4, 5, 6, 7], [7, 6, 5, 4, 3, 2, 1, 0], [3, 1, 4, 0, 5, 2, 7, 6]]
    exp = _experiment(small_set, "active", teacher)
    while not exp.done:
        exp.step(lambda name, b, t: exp.outcomes[name])
    pop = run_population(names, pnames, teacher, outcomes, probes, exp.config, chunk=2)
    assert pop["chosen_orders"] == exp.orders
    from train.population import knowledge_keys
    assert pop["final_knowledge"] == knowledge_keys(exp.agent.rules.state)


def test_the_runner_takes_explore_as_a_flag_and_keeps_it_in_run_json(tmp_path):
    from train import run
    from train.run_config import run_settings
    args = run.parse_args(["--explore", "active", "--model", "contextual", "--out", str(tmp_path / "out")])
    assert args.overrides["explore"] == "active"
    objects = run.load_run_objects(args)
    assert run_settings(args, objects)["overrides"]["explore"] == "active"
    assert run.resolve_config(args, objects).agent.explore == "active"
    default = run.parse_args(["--out", str(tmp_path / "other")])
    assert "explore" not in default.overrides


def test_active_exploration_with_per_episode_physics_is_refused_in_one_line(tmp_path, capsys):
    from train import run
    out = tmp_path / "out"
    code = run.main(["--explore", "active", "--physics", "per-episode", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--explore active" in err[0] and "per-episode" in err[0], err
    assert not out.exists()
