"""The runner's faster paths give what the plain ones gave: predictions without the decoding, the first orders of a
draw without drawing all, a population drawn and run on another process, the first simulations handed over early,
Figure 2 encoded once for every log."""

import pytest
import torch

from aesop_torch.agent import AgentConfig
from sim.objects import DEFAULT_OBJECTS_FILE, load_objects
from train.learning.experiment import (
    Experiment,
    closed_form_outcomes,
    draw_orders,
    stack_measurements,
)
from train.learning.sim_pool import Physics
from train.learning.population import run_orders, run_population

THREE = ("red_heavy_cylinder", "red_light_cylinder", "green_heavy_box")


@pytest.fixture(scope="module")
def world():
    objs = load_objects(DEFAULT_OBJECTS_FILE)
    outcomes, probes = closed_form_outcomes(objs)
    return objs, outcomes, probes


@pytest.mark.parametrize("model", ["paper", "extended", "contextual"])
def test_a_prediction_without_the_decoded_values_is_the_same_bit_for_bit(world, model):
    objs, outcomes, probes = world
    exp = Experiment(list(THREE), [p.name for p in objs.probe], [[0, 1, 2], [2, 1, 0]],
                     config=AgentConfig.named(model))
    exp.probes = probes
    while not exp.done:
        exp.step(lambda name, b, t: outcomes[name])
    m = stack_measurements([probes[objs.probe[0].name]["measurement"]] * 2)
    full, bare = exp.agent.anticipate(m), exp.agent.anticipate(m, decoded=False)
    for part in ("expected", "p_sink", "by_fate"):   # the same bits (NaN included)
        assert torch.equal(getattr(full, part).view(torch.int32), getattr(bare, part).view(torch.int32)), part
    assert not torch.isnan(full.expected).all()
    assert full.values is not None and full.recalled_values is not None
    # the paper's average reads no values: none decoded; the fitted readouts read them: decoded all the same
    assert (bare.values is None) == (model == "paper") and (bare.recalled_values is None) == (model == "paper")


@pytest.mark.parametrize("orders", ["all", "listed", "7", "200"])
def test_the_first_orders_of_a_draw_are_the_full_draws_first(orders):
    full = draw_orders(5, orders, seed=3)
    for limit in (1, 4, 64, 500):
        assert draw_orders(5, orders, seed=3, limit=limit) == full[:limit]


def test_run_orders_is_run_population_of_the_drawn_orders_without_the_predictions(world):
    objs, outcomes, probes = world
    names, probe_names = list(THREE), [p.name for p in objs.probe]
    config = AgentConfig()
    got = run_orders(names, probe_names, "all", 0, outcomes, probes, config)
    want = run_population(names, probe_names, draw_orders(3, "all", 0), outcomes, probes, config, curves=True)
    assert "final_probe_cm3" not in got and got.keys() == want.keys() - {"final_probe_cm3"}
    for k in got.keys() - {"timing_s"}:
        assert got[k] == want[k], k


def test_jobs_submitted_early_are_taken_up_by_the_same_jobs_submit():
    physics = Physics(load_objects(DEFAULT_OBJECTS_FILE), workers=1)   # in this process: lazy, nothing simulated
    jobs = [("drop", "red_heavy_cylinder", False), ("inspect", "blue_heavy_cylinder", None)]
    physics.submit_early(jobs)
    early = physics._early[1]
    assert physics.submit([("drop", "red_light_cylinder", False)]) is not early   # other jobs: their own
    assert physics.submit(list(jobs)) is early                                     # the same: taken up, once
    assert physics.submit(jobs) is not early and physics._early is None


def test_figure_2_encoded_once_writes_what_add_image_writes(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from train.runner.tensorboard_log import OrderLog
    image = (torch.arange(6 * 5 * 3) % 251).to(torch.uint8).view(6, 5, 3).numpy()
    plain, once = OrderLog(tmp_path / "plain"), OrderLog(tmp_path / "once")
    plain.image("figure2", image, 8)
    once.shown(OrderLog.encoded("figure2", image), 8)
    plain.close()
    once.close()
    got = []
    for d in ("plain", "once"):
        acc = EventAccumulator(str(tmp_path / d), size_guidance={"images": 0})
        acc.Reload()
        got.append([(e.step, e.width, e.height, e.encoded_image_string) for e in acc.Images("figure2")])
    assert got[0] == got[1] and len(got[0]) == 1 and got[0][0][:3] == (8, 5, 6)
