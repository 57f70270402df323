"""The runner's faster paths give what the plain ones gave: predictions without the decoding, the first orders of a
draw without drawing all, a population drawn and run on another process, the first simulations handed over early,
Figure 2 encoded once for every log."""

import numpy as np
import pytest
import torch

from aesop_torch.agent import AgentConfig
from sim.objects import DEFAULT_OBJECTS_FILE, load_objects
from train.learning.experiment import (
    Experiment,
    closed_form_outcomes,
    draw_orders,
    order_tensor,
    stack_measurements,
)
from train.learning.population import run_orders, run_population
from train.learning.sim_pool import Physics

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


@pytest.mark.parametrize("n", range(1, 9))
def test_all_orders_as_a_tensor_are_itertools_permutations(n):
    """Oracle: itertools.permutations(range(n)), lexicographic, as draw_orders lists them."""
    import itertools
    got = order_tensor(n, "all", 0)
    assert got.dtype == torch.long and got.tolist() == [list(p) for p in itertools.permutations(range(n))]


@pytest.mark.parametrize("orders", ["listed", "1", "7", "200"])
def test_other_orders_as_a_tensor_are_the_draw(orders):
    assert order_tensor(5, orders, 3).tolist() == draw_orders(5, orders, seed=3)


def test_rows_are_sorted_only_in_lexicographic_order():
    import random

    from train.learning.population import _sorted_rows
    rng = random.Random(0)
    for _ in range(300):
        n = rng.randint(1, 4)
        rows = [[rng.randrange(3) for _ in range(n)] for _ in range(rng.randint(1, 7))]
        assert _sorted_rows(torch.tensor(rows)) == (sorted(rows) == rows), rows


def test_orders_given_as_a_tensor_run_as_the_lists(world):
    objs, outcomes, probes = world
    names, probe_names = list(THREE), [p.name for p in objs.probe]
    lists = [[2, 0, 1], [0, 1, 2], [1, 2, 0], [0, 1, 2]]   # unsorted, one repeated
    want = run_population(names, probe_names, lists, outcomes, probes, AgentConfig(), curves=True)
    got = run_population(names, probe_names, torch.tensor(lists), outcomes, probes, AgentConfig(), curves=True)
    assert torch.equal(got.pop("final_probe_cm3").view(torch.int32), want.pop("final_probe_cm3").view(torch.int32))
    for k in got.keys() - {"timing_s"}:
        assert got[k] == want[k], k
    for bad in (torch.tensor([[0, 1]]), torch.tensor([0, 1, 2]), torch.tensor([[0.0, 1.0, 2.0]])):
        with pytest.raises(ValueError, match="every order must list 3 train objects"):
            run_population(names, probe_names, bad, outcomes, probes, AgentConfig())


def test_json_safe_of_plain_lists_is_the_item_by_item_answer():
    import math

    from train.runner.summary import json_safe

    class Sub(float):
        pass
    for items in (["IIDD", "UUDD"], [0.25, None, math.nan, -math.inf, 0.5], [1, True, None, "x"],
                  [Sub("nan"), 1.0], [(math.inf, 1.0), "a"], []):
        got = json_safe(items)
        want = [None if isinstance(v, float) and not math.isfinite(v) else
                [None if not math.isfinite(w) else w for w in v] if isinstance(v, tuple) else v for v in items]
        assert got == want and got is not items and [type(v) for v in got] == [type(v) for v in want], items


def test_run_orders_is_run_population_of_the_drawn_orders_without_the_predictions(world):
    objs, outcomes, probes = world
    names, probe_names = list(THREE), [p.name for p in objs.probe]
    config = AgentConfig()
    got = run_orders(names, probe_names, "all", 0, outcomes, probes, config)
    want = run_population(names, probe_names, draw_orders(3, "all", 0), outcomes, probes, config, curves=True)
    assert "final_probe_cm3" not in got and got.keys() == want.keys() - {"final_probe_cm3"}
    for k in got.keys() - {"timing_s"}:
        assert got[k] == want[k], k


def test_orders_prepared_ahead_give_the_same_population_and_are_taken_once(world, monkeypatch):
    from train.learning import population
    objs, outcomes, probes = world
    names, probe_names = list(THREE), [p.name for p in objs.probe]
    want = run_orders(names, probe_names, "all", 0, outcomes, probes, AgentConfig())
    population.prepare_orders(3, "all", 0)
    order_t, trie = population._PREPARED[(3, "all", 0)]
    built = []
    monkeypatch.setattr(population, "_Trie", lambda orders: built.append(orders) or trie)
    got = run_orders(names, probe_names, "all", 0, outcomes, probes, AgentConfig())
    assert built == [] and population._PREPARED == {}   # the prepared trie used, not built again; taken once
    for k in got.keys() - {"timing_s"}:
        assert got[k] == want[k], k
    other = order_t.clone()   # the same rows, another tensor: its own trie is built
    population._Walk(names, probe_names, outcomes, probes, other, 8, None, trie=trie)
    assert len(built) == 1 and built[0] is other


def test_figure_2_of_the_population_run_last_here_is_the_figure_of_its_answer(world, tmp_path, monkeypatch):
    from train.learning import population
    from train.runner.figure_process import (
        POPULATION_FIGURE_KEYS,
        figure_of_the_population,
    )
    from train.runner.figures import save_figure2
    objs, outcomes, probes = world
    names, probe_names = list(THREE), [p.name for p in objs.probe]
    exp = Experiment(names, probe_names, [[0, 1, 2], [2, 1, 0]])
    exp.probes = probes
    while not exp.done:
        exp.step(lambda name, b, t: outcomes[name])
    monkeypatch.setattr(population, "LAST", {})
    with pytest.raises(RuntimeError, match="no population"):
        figure_of_the_population(exp.records, tmp_path / "none.png", 40, 0.05)
    answer = run_orders(names, probe_names, "all", 0, outcomes, probes, AgentConfig())
    assert population.LAST == answer
    figure_of_the_population(exp.records, tmp_path / "last.png", 40, 0.05)
    save_figure2(exp.records, tmp_path / "sent.png", 40, 0.05, {k: answer[k] for k in POPULATION_FIGURE_KEYS})
    assert (tmp_path / "last.png").read_bytes() == (tmp_path / "sent.png").read_bytes()


def test_jobs_submitted_early_are_taken_up_by_the_same_jobs_submit():
    physics = Physics(load_objects(DEFAULT_OBJECTS_FILE), workers=1)   # in this process: lazy, nothing simulated
    jobs = [("drop", "red_heavy_cylinder", False), ("inspect", "blue_heavy_cylinder", None)]
    physics.submit_early(jobs)
    early = physics._early[1]
    assert physics.submit([("drop", "red_light_cylinder", False)]) is not early   # other jobs: their own
    assert physics.submit(list(jobs)) is early                                     # the same: taken up, once
    assert physics.submit(jobs) is not early and physics._early is None


@pytest.mark.timeout(120)
def test_workers_forked_with_the_world_built_once_simulate_what_a_world_built_here_does(monkeypatch):
    import multiprocessing

    import sim.world
    from train.learning import sim_pool

    builds = multiprocessing.get_context("fork").Value("i", 0)   # counted in whichever process builds a world

    class Counted(sim.world.World):
        def __init__(self, *args, **kwargs):
            with builds.get_lock():
                builds.value += 1
            super().__init__(*args, **kwargs)
    monkeypatch.setattr(sim.world, "World", Counted)
    objs = load_objects(DEFAULT_OBJECTS_FILE)
    jobs = [("inspect", objs.probe[0].name, None), ("drop", "red_light_cylinder", None)]
    pool = Physics(objs, workers=2)
    try:
        pool.start()
        assert sim_pool._WORLD is None   # this process's copy closed once the workers hold theirs
        forked = pool.run(jobs)
    finally:
        pool.close()
    assert builds.value == 1   # one world for both workers, not one each
    here = Physics(objs, workers=1)
    try:
        own = here.run(jobs)
    finally:
        here.close()
    same = lambda a, b: a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)   # every bit
    assert same(forked[0], own[0]) and same(forked[1].measurement, own[1].measurement)
    for field in ("observed_cm3", "level_before_cm", "level_after_cm", "goal_reachable_before", "goal_reached_after",
                  "sank", "settled", "delivered"):
        assert getattr(forked[1], field) == getattr(own[1], field), field


def test_a_world_that_cannot_be_built_before_the_fork_fails_each_job_in_one_line(monkeypatch):
    import sim.world
    from sim.errors import WorldBuildError

    def refuse(*args, **kwargs):
        raise ValueError("no room for the jar\nsecond line")
    monkeypatch.setattr(sim.world, "World", refuse)
    physics = Physics(load_objects(DEFAULT_OBJECTS_FILE), workers=2)
    try:
        with pytest.raises(WorldBuildError, match=r"^the world could not be built: ValueError: no room for the jar$"):
            physics.run([("inspect", "blue_heavy_cylinder", None)])
    finally:
        physics.close()


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


def test_the_same_image_event_in_every_log_is_checksummed_once_to_the_same_value(tmp_path, monkeypatch):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    from tensorboard.compat.tensorflow_stub.pywrap_tensorflow import masked_crc32c
    from tensorboard.summary.writer import record_writer

    from train.runner.tensorboard_log import OrderLog, _LastCrc
    crc = record_writer.masked_crc32c
    assert isinstance(crc, _LastCrc)
    big = bytes(range(256)) * 40
    for data in (b"", b"abc", big, big[:-1] + b"x", big):   # small, large, another large, the first again
        assert crc(data) == masked_crc32c(data)
    calls = []
    monkeypatch.setattr(crc, "crc", lambda data: calls.append(len(data)) or masked_crc32c(data))
    noise = torch.randint(0, 256, (60, 50, 3), generator=torch.Generator().manual_seed(0))
    encoded = OrderLog.encoded("figure2", noise.to(torch.uint8).numpy())   # ~9 kB of PNG: a large record
    logs = [OrderLog(tmp_path / f"o{b}") for b in range(3)]
    for log in logs:
        log.shown(encoded, 8, 1234.5)
    for log in logs:
        log.close()
    assert len([n for n in calls if n >= _LastCrc.LARGE]) == 1   # one image event's bytes, checksummed once
    for b in range(3):   # each log reads back whole (a wrong checksum would be a corrupt record)
        acc = EventAccumulator(str(tmp_path / f"o{b}"), size_guidance={"images": 0})
        acc.Reload()
        assert [(e.wall_time, e.step, e.width, e.height) for e in acc.Images("figure2")] == [(1234.5, 8, 50, 60)]


def test_probe_readings_on_a_process_of_their_own_are_the_walks_own(world):
    """The population's curves read on a forked process (run_orders' way with 2 cores) give what the walk reads
    itself: every result the same, the predictions bit for bit; the child is gone after."""
    import os

    objs, outcomes, probes = world
    names, probe_names = [o.name for o in objs.train][:5], [p.name for p in objs.probe]
    orders = order_tensor(5, "all", 0)
    here = run_population(names, probe_names, orders, outcomes, probes, AgentConfig(), curves=True)
    there = run_population(names, probe_names, orders, outcomes, probes, AgentConfig(), curves=True,
                           probe_process=True)
    assert torch.equal(here.pop("final_probe_cm3").view(torch.int32), there.pop("final_probe_cm3").view(torch.int32))
    for k in here.keys() - {"timing_s"}:
        assert here[k] == there[k], k
    assert any(c["values"] for c in here["curves"]["probe_rel_error"])
    with pytest.raises(ChildProcessError):   # reaped: no child left behind
        os.waitpid(-1, os.WNOHANG)


def test_a_probe_process_that_dies_is_an_error_not_a_gap(world, monkeypatch):
    from train.learning import population

    objs, outcomes, probes = world
    names, probe_names = list(THREE), [p.name for p in objs.probe]

    def dies(*args):
        raise MemoryError("killed")
    monkeypatch.setattr(population, "_serve", dies)   # the forked child calls it
    with pytest.raises(RuntimeError, match="probe process .* died"):
        run_population(names, probe_names, order_tensor(3, "all", 0), outcomes, probes, AgentConfig(), curves=True,
                       probe_process=True)


def test_a_population_given_the_developed_maps_is_the_one_that_develops_them(world):
    """The runner hands its experiment's maps to the population (run_orders' maps) rather than have them developed
    again: the same results, the predictions bit for bit; maps of another seed give other activities (the maps
    are used, not ignored)."""
    from aesop_torch.agent import Agent

    objs, outcomes, probes = world
    names, probe_names = list(THREE), [p.name for p in objs.probe]
    orders = order_tensor(3, "all", 0)
    own = run_population(names, probe_names, orders, outcomes, probes, AgentConfig(), curves=True)
    maps = {k: v.numpy() for k, v in Agent(AgentConfig()).maps.state_dict().items()}
    given = run_population(names, probe_names, orders, outcomes, probes, AgentConfig(), curves=True, maps=maps)
    pred = own.pop("final_probe_cm3")
    assert torch.equal(pred.view(torch.int32), given.pop("final_probe_cm3").view(torch.int32))
    for k in own.keys() - {"timing_s"}:
        assert own[k] == given[k], k
    other = AgentConfig()
    other.seed = 1
    maps1 = {k: v.numpy() for k, v in Agent(other).maps.state_dict().items()}
    assert any((maps1[k] != maps[k]).any() for k in maps)
    moved = run_population(names, probe_names, orders, outcomes, probes, AgentConfig(), curves=True, maps=maps1)
    assert not torch.equal(moved["final_probe_cm3"].nan_to_num(-1.0), pred.nan_to_num(-1.0))
