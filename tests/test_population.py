"""train.learning.population: every order at once (prefix sharing, shared recall) gives what Experiment gives order by order.

Closed-form outcomes (Archimedes, no physics), as a cached-physics run would record them.
"""

import itertools
import statistics
from collections import Counter

import pytest
import torch

from aesop_torch.agent import OBJECT_ROWS, Agent, AgentConfig
from aesop_torch.memory import EpisodicMemory, MemoryConfig
from sim.objects import DEFAULT_OBJECTS_FILE, load_objects
from train.learning.experiment import Experiment, closed_form_outcomes, draw_orders, median_rel_error
from train.learning.population import (RecallCache, SharedRecallMemory, _owned, _row_keys, agreement, canonicalise,
                              median_rel_errors, run_population)
from train.runner.summary import knowledge_key

# five of the default objects whose 120 orders agree on their knowledge but end with different sets of probe
# predictions (which episodes were encoded, and so recalled, differs from order to order), so agreement between the
# two runs is not agreement on one answer
MIXED = ("red_heavy_cylinder", "blue_heavy_cylinder", "red_light_cylinder", "red_small_heavy_cylinder",
         "green_heavy_box")


@pytest.fixture(scope="module")
def world():
    objs = load_objects(DEFAULT_OBJECTS_FILE)
    outcomes, probes = closed_form_outcomes(objs)
    return [s.name for s in objs.train], [p.name for p in objs.probe], outcomes, probes


def experiment(names, probe_names, orders, outcomes, probes, model="extended"):
    """The hand-counted cases below are the extended model's (its knowledge is a function of the evidence set)."""
    exp = Experiment(list(names), probe_names, orders, config=AgentConfig.named(model))
    exp.probes = probes
    while not exp.done:
        exp.step(lambda name, b, t: outcomes[name])
    return exp


def assert_same_as_experiment(pop, exp):
    keys = [knowledge_key(k) for k in exp.final_knowledge()]
    assert pop["final_knowledge"] == keys
    want = exp.probe_predictions()
    got = pop["final_probe_cm3"]
    assert torch.equal(torch.isnan(got), torch.isnan(want))
    # float rounding only: an agent's float results depend in their last bits on the batch it is computed in
    assert torch.allclose(torch.nan_to_num(got), torch.nan_to_num(want), rtol=1e-5, atol=0)
    errs = [r[-1]["probe_rel_error"] for r in exp.records]
    for a, b in zip(pop["final_probe_rel_error"], errs):
        assert (a is None) == (b is None) and (a is None or abs(a - b) <= 1e-4)
    common, n = Counter(keys).most_common(1)[0]
    assert pop["most_common_knowledge"] == common and pop["agree_fraction"] == n / len(keys)


@pytest.fixture(scope="module")
def mixed(world):
    _, probe_names, outcomes, probes = world
    names = list(MIXED)
    orders = [list(p) for p in itertools.permutations(range(len(names)))]
    exp = experiment(names, probe_names, orders, outcomes, probes)
    # chunk 7: every level above the first is split into pieces, and the last level's only children reuse parents
    pop = run_population(names, probe_names, orders, outcomes, probes, exp.config, chunk=7, threads=1)
    return exp, pop, names, orders


def test_all_orders_of_five_match_experiment(mixed):
    exp, pop, _, _ = mixed
    assert_same_as_experiment(pop, exp)
    distinct = {tuple(row) for row in pop["final_probe_cm3"].nan_to_num(-1.0).tolist()}
    assert len(distinct) > 1                              # the comparison covers orders that end differently
    assert pop["nodes_per_level"] == [5, 20, 60, 120, 120]
    # at most one step per trie node (not 5 x 120), fewer where prefixes leave their agents in the same state
    assert pop["agent_steps"] == sum(pop["steps_per_level"]) < 5 + 20 + 60 + 120 + 120


@pytest.mark.parametrize("model", ["extended", "paper"])
def test_subset_with_a_repeated_order_matches_experiment(world, model):
    """A trie over any given orders: random ones, one given twice (same leaf, reported for both); either model."""
    train, probe_names, outcomes, probes = world
    names = train[:6]
    orders = draw_orders(len(names), "20", seed=3)
    orders.append(list(orders[4]))
    exp = experiment(names, probe_names, orders, outcomes, probes, model)
    pop = run_population(names, probe_names, orders, outcomes, probes, exp.config, chunk=4, threads=1)
    assert_same_as_experiment(pop, exp)
    assert pop["final_knowledge"][-1] == pop["final_knowledge"][4]


def test_same_inputs_same_outputs_bit_for_bit(world, mixed):
    exp, pop, names, orders = mixed
    _, probe_names, outcomes, probes = world
    again = run_population(names, probe_names, orders, outcomes, probes, exp.config, chunk=7, threads=1)
    assert again["final_knowledge"] == pop["final_knowledge"]
    assert again["final_probe_rel_error"] == pop["final_probe_rel_error"]
    assert torch.equal(again["final_probe_cm3"].nan_to_num(-1.0), pop["final_probe_cm3"].nan_to_num(-1.0))


# the red and blue heavy cylinders, the light and the small red cylinders: R0 and B1 differ in colour alone, so the
# later of them is not encoded (nothing new: the outcome held), and what it compares itself with (so the evidence it
# adds) depends on which objects were stored before it. Every other object is encoded, and a comparison of two of
# them adds the same evidence whichever came first.
FOUR = ("red_heavy_cylinder", "blue_heavy_cylinder", "red_light_cylinder", "red_small_heavy_cylinder")


def four_states(prefix) -> tuple:
    """The state after a prefix of FOUR, by the rule above: the objects seen, which of R0 / B1 came first, and the
    objects seen before the later of them came."""
    heavy = [i for i, o in enumerate(prefix) if o in (0, 1)]
    return (frozenset(prefix), prefix[heavy[0]] if heavy else None,
            frozenset(prefix[:heavy[1]]) if len(heavy) == 2 else None)


def test_merged_states_of_four_objects_counted_by_hand(world):
    """All 24 orders of FOUR: a level's distinct states (four_states over its prefixes) are stepped once each; the
    next level steps each of them with each object it has not seen. By hand: 4 states after one object, 7 after two
    ({R0, B1} twice: R0 or B1 first), 10 after three ({R0, B1, x} four times: first heavy R0 or B1, x before the
    later one or not), 8 after four. Results: Experiment's, and the plain trie's (merge=False, every node stepped)."""
    _, probe_names, outcomes, probes = world
    names, n = list(FOUR), len(FOUR)
    orders = [list(p) for p in itertools.permutations(range(n))]
    states = [{four_states(o[:t + 1]) for o in orders} for t in range(n)]
    assert [len(s) for s in states] == [4, 7, 10, 8]
    exp = experiment(names, probe_names, orders, outcomes, probes)
    pop = run_population(names, probe_names, orders, outcomes, probes, exp.config, chunk=5, threads=1)
    assert pop["steps_per_level"] == [4] + [len(states[t - 1]) * (n - t) for t in range(1, n)] == [4, 12, 14, 10]
    assert pop["distinct_final_states"] == 8
    assert_same_as_experiment(pop, exp)
    plain = run_population(names, probe_names, orders, outcomes, probes, exp.config, chunk=5, threads=1, merge=False)
    assert plain["steps_per_level"] == plain["nodes_per_level"] == [4, 12, 24, 24]
    assert plain["final_knowledge"] == pop["final_knowledge"]
    assert plain["final_probe_rel_error"] == pop["final_probe_rel_error"]
    assert torch.allclose(plain["final_probe_cm3"].nan_to_num(-1.0), pop["final_probe_cm3"].nan_to_num(-1.0),
                          rtol=1e-5, atol=0)


def test_a_merge_needs_the_same_orders_below(world):
    """R0 R2 and R2 R0 end in the same state; their orders' results are shared only where the same objects follow in
    the same order below them."""
    _, probe_names, outcomes, probes = world
    names = list(FOUR)
    for orders, steps in (([[0, 2, 3, 1], [2, 0, 1, 3]], [2, 2, 2, 2]),     # different suffixes: both stepped
                          ([[0, 2, 3, 1], [2, 0, 3, 1]], [2, 2, 1, 1])):    # the same suffix: stepped once
        exp = experiment(names, probe_names, orders, outcomes, probes)
        pop = run_population(names, probe_names, orders, outcomes, probes, exp.config, threads=1)
        assert pop["steps_per_level"] == steps
        assert_same_as_experiment(pop, exp)


def test_canonicalise_relabels_by_object(world):
    """R0 then R2 and R2 then R0 (both encoded, each in the other slot and on the other hub neurons) hold the same
    bytes after canonicalise: R0's episode and assembly first, on hub neurons 0-1 of each row."""
    _, _, outcomes, _ = world
    cfg = AgentConfig()
    cfg.memory.max_episodes = cfg.hub.max_assemblies = 4
    agent = Agent(cfg, batch=2)
    first, second = torch.tensor([0, 2]), torch.tensor([2, 0])
    rec = [outcomes[name] for name in FOUR]
    owners = (torch.full((2, 4), 4), torch.full((2, 4), 4))
    for obj in (first, second):
        meas = {k: torch.tensor([rec[i]["measurement"][k] for i in obj.tolist()]) for k in
                ("rgb", "extent_cm", "fill", "mass_g")}
        nh, nm = agent.hub.n_assemblies.clone(), agent.memory.count.clone()
        res = agent.step(meas, torch.tensor([rec[i]["observed_cm3"] for i in obj.tolist()]),
                         torch.tensor([rec[i]["goal_before"] for i in obj.tolist()]),
                         torch.tensor([rec[i]["goal_after"] for i in obj.tolist()]),
                         sank=torch.tensor([rec[i]["sank"] for i in obj.tolist()]))
        assert res.encoded.all()
        owners = (_owned(owners[0], nh, agent.hub.n_assemblies, obj), _owned(owners[1], nm, agent.memory.count, obj))
    assert owners[0].tolist() == owners[1].tolist() == [[0, 2, 4, 4], [2, 0, 4, 4]]
    assert not torch.equal(agent.memory.patterns[0], agent.memory.patterns[1])
    learned = lambda: {f"{p}.{k}": v.clone() for p in ("hub", "memory", "rules")   # noqa: E731
                       for k, v in getattr(agent, p).state_dict().items()}
    before = learned()
    hub_owner, mem_owner = canonicalise(agent, *owners)
    assert hub_owner.tolist() == mem_owner.tolist() == [[0, 2, 4, 4]] * 2
    for key, value in learned().items():
        assert torch.equal(value[0], value[1]), key
        assert torch.equal(value[0], before[key][0]), key      # agent 0 already stored them in object order
    # R0's episode is the first and its object rows hold hub neurons 0-1 of each row (its assembly)
    obj_rows = agent.memory.patterns[1, 0, list(OBJECT_ROWS)]
    assert obj_rows[:, :2].all() and obj_rows.sum() == 2 * len(OBJECT_ROWS)
    assert torch.equal(agent.hub.branches[1, 0], before["hub.branches"][1, 1])


def test_agreement_on_a_hand_made_case():
    common, fraction, counts = agreement(["IIDD", "ILDD", "IIDD", "UUUU", "IIDD", "ILDD"])
    assert (common, fraction) == ("IIDD", 0.5)
    assert counts == {"IIDD": 3, "ILDD": 2, "UUUU": 1}
    assert agreement(["ILDD", "IIDD"])[:2] == ("ILDD", 0.5)   # a tie goes to the key seen first
    with pytest.raises(ValueError):
        agreement([])


def test_agree_fraction_of_the_mixed_set(mixed):
    """The 120 orders of MIXED all end ILDD (counted from Experiment's own knowledge): colour eliminated by the red and
    blue cylinders, weight grown by the heavy and light ones, size by the large and small heavy cylinders; shape
    changed only together with other properties, never alone against a changed outcome: likely irrelevant."""
    exp, pop, _, _ = mixed
    assert Counter(knowledge_key(k) for k in exp.final_knowledge()) == {"ILDD": 120}
    assert pop["most_common_knowledge"] == "ILDD"
    assert pop["agree_fraction"] == 1.0
    assert pop["knowledge_counts"] == {"ILDD": 120}


def test_median_rel_errors_is_median_rel_error_row_by_row():
    truth = torch.tensor([100.0, 20.0, 50.0, 10.0])
    nan = float("nan")
    pred = torch.tensor([[110.0, 20.0, 40.0, 10.0],     # errors .1 0 .2 0 -> median (0 + .1) / 2
                         [nan, 30.0, 50.0, 12.5],       # 1 (nothing expected) .5 0 .25
                         [nan, nan, nan, nan]])         # no prediction at all: None
    got = median_rel_errors(pred, truth)
    assert got == [median_rel_error(p, truth) for p in pred]
    assert got[0] == pytest.approx(0.05) and got[1] == pytest.approx(0.375) and got[2] is None
    odd = median_rel_errors(pred[:, :3], truth[:3])
    assert odd == [median_rel_error(p, truth[:3]) for p in pred[:, :3]]
    assert odd[0] == pytest.approx(statistics.median([0.1, 0.0, 0.2]))


def test_row_keys_are_exact_bytes():
    a = torch.tensor([[1, 2], [3, 4], [1, 2]])
    flags = torch.tensor([[True] * 9, [True] * 9, [True] * 8 + [False]])   # packed 8 to a byte, the 9th counts
    keys = _row_keys(a)
    assert keys[0] == keys[2] != keys[1]
    keys = _row_keys(a, flags)
    assert len(set(keys)) == 3
    assert _row_keys(torch.tensor([[0.0], [-0.0]]))[0] != _row_keys(torch.tensor([[0.0], [-0.0]]))[1]


def sheet(code: int, cfg: MemoryConfig) -> torch.Tensor:
    """A valid episode: object row neurons code..code+4, every other row neurons 2 code, 2 code + 1."""
    x = torch.zeros(cfg.rows, cfg.cols, dtype=torch.bool)
    for r in range(cfg.rows):
        k = cfg.row_k[r]
        x[r, (code * k) % cfg.cols:(code * k) % cfg.cols + k] = True
    return x


def test_shared_recall_recalls_each_distinct_memory_and_cue_once():
    """Four agents, two memories (A: episodes 1 and 3, B: episode 2), cues on episode 1 or 2: three distinct pairs."""
    cfg = MemoryConfig(max_episodes=2)
    plain, shared = EpisodicMemory(cfg, batch=4), SharedRecallMemory(cfg, batch=4)
    shared.cache = RecallCache()
    for mem in (plain, shared):
        mem.store(torch.stack([sheet(1, cfg), sheet(2, cfg), sheet(1, cfg), sheet(1, cfg)]))
        mem.store(torch.stack([sheet(3, cfg)] * 4), torch.tensor([True, False, True, True]))
    cue = torch.stack([sheet(c, cfg)[cfg.cue_rows[0]].float() for c in (1, 2, 1, 2)])
    want, got = plain.recall(cue), shared.recall(cue)
    assert shared.cache.size == 3                  # (A, cue 1) twice, (B, cue 2), (A, cue 2)
    assert torch.equal(got.episodes, want.episodes) and torch.equal(got.valid, want.valid)
    assert torch.allclose(got.strength, want.strength)
    assert torch.equal(got.episodes[0, 0], sheet(1, cfg)) and torch.equal(got.episodes[1, 0], sheet(2, cfg))
    again = shared.recall(cue)                     # everything is in the cache now
    assert shared.cache.size == 3 and torch.equal(again.episodes, got.episodes)
    assert torch.equal(again.strength, got.strength)


def test_select_copies_the_chosen_agents(world):
    train, _, outcomes, _ = world
    agent = Agent(AgentConfig(), batch=3)
    m = {k: torch.tensor([outcomes[train[i]]["measurement"][k] for i in (0, 2, 4)]) for k in
         ("rgb", "extent_cm", "fill", "mass_g")}
    agent.step(m, torch.tensor([365.0, 14.0, 60.0]), torch.zeros(3, dtype=torch.bool), torch.zeros(3, dtype=torch.bool))
    picked = agent.select([2, 0, 2])
    assert picked.batch == 3 and picked.memory.batch == 3 and picked.maps is agent.maps
    for part in ("hub", "memory", "rules"):
        for name, buf in getattr(agent, part).state_dict().items():
            assert torch.equal(getattr(getattr(picked, part), name), buf[[2, 0, 2]]), (part, name)
    before = agent.hub.W.clone()
    picked.hub.W.zero_()                                   # copies, not views
    assert torch.equal(agent.hub.W, before)
    with pytest.raises(ValueError):
        agent.select([3])
    with pytest.raises(ValueError):
        agent.select([])


def test_bad_input_is_refused(world):
    train, probe_names, outcomes, probes = world
    names = train[:3]
    cfg = AgentConfig()
    with pytest.raises(ValueError, match="every order"):
        run_population(names, probe_names, [[0, 1]], outcomes, probes, cfg)
    with pytest.raises(ValueError, match="index"):
        run_population(names, probe_names, [[0, 1, 3]], outcomes, probes, cfg)
    with pytest.raises(ValueError, match="no outcome"):
        run_population(names + ["ghost"], probe_names, [[0, 1, 2, 3]], outcomes, probes, cfg)
    with pytest.raises(ValueError, match="chunk"):
        run_population(names, probe_names, [[0, 1, 2]], outcomes, probes, cfg, chunk=0)


def test_config_threads_and_progress(world):
    train, probe_names, outcomes, probes = world
    cfg, seen = AgentConfig(), []
    threads = torch.get_num_threads()
    pop = run_population(train[:3], probe_names, [[0, 1, 2], [2, 1, 0]], outcomes, probes, cfg, chunk=1,
                         progress=lambda done, total: seen.append((done, total)), threads=2)
    assert cfg.memory.max_episodes == 230 and cfg.hub.max_assemblies == 230   # the caller's config is not touched
    assert torch.get_num_threads() == threads
    assert seen == [(1, 2), (2, 2)] and pop["orders"] == 2


def test_closed_form_outcomes_sink_by_volume_float_by_mass(world):
    _, _, outcomes, probes = world
    heavy, light = outcomes["red_heavy_cylinder"], outcomes["red_light_cylinder"]
    assert heavy["observed_cm3"] == pytest.approx(3.141592653589793 * 3.18 ** 2 * 11.5, rel=1e-6)  # sinks: volume
    assert light["observed_cm3"] == pytest.approx(14.0, rel=1e-6)                                   # floats: mass
    assert heavy["goal_after"] and not light["goal_after"] and not heavy["goal_before"]
    assert heavy["measurement"]["mass_g"] == 420.0 and set(probes) == {
        "purple_heavy_cylinder", "white_light_cylinder", "grey_heavy_cube", "orange_light_box", "pink_light_cylinder"}


def test_probe_predictions_in_one_call_equal_one_call_per_probe(world):
    """Experiment.probe_predictions predicts every (order, probe) in one call on copies of the agents; a cue's recall
    and readout do not depend on its batch, so it equals predicting each probe for the orders on their own."""
    names, probe_names, outcomes, probes = world
    orders = [[0, 1, 2, 3, 4, 5, 6, 7], [7, 6, 5, 4, 3, 2, 1, 0], [3, 1, 4, 0, 5, 2, 7, 6]]
    exp = Experiment(list(names), probe_names, orders)
    exp.probes = probes
    for _ in range(4):
        exp.step(lambda name, b, t: outcomes[name])
        one_by_one = torch.stack([exp.predict(probes[p]["measurement"]) for p in probe_names], 1)
        assert torch.equal(exp.probe_predictions(), one_by_one)


def test_curves_give_every_orders_error_after_every_episode(world):
    """All 24 orders of FOUR with curves: each episode's counted errors are Experiment's per-order errors (as the
    records round them, float rounding aside), and Figure 2's band at an episode is the quantiles of those errors
    computed directly. The plain trie (every node stepped, no copied subtrees) counts the same."""
    import numpy as np

    from train.runner.figures import ERROR_BANDS, error_bands
    from train.common.quantiles import weighted_quantiles

    _, probe_names, outcomes, probes = world
    names, n = list(FOUR), len(FOUR)
    orders = [list(p) for p in itertools.permutations(range(n))]
    exp = experiment(names, probe_names, orders, outcomes, probes)
    pop = run_population(names, probe_names, orders, outcomes, probes, exp.config, chunk=5, threads=1, curves=True)
    assert "curves" not in run_population(names, probe_names, orders[:2], outcomes, probes, exp.config, threads=1)
    eps = pop["curves"]["probe_rel_error"]
    assert len(eps) == n
    qs = [0.5] + [q for band in ERROR_BANDS for q in band]
    _, band = error_bands([], {"orders": 24, "curves": pop["curves"]})
    spread = False
    for t, e in enumerate(eps):
        direct = [r[t]["probe_rel_error"] for r in exp.records]
        have = sorted(x for x in direct if x is not None)
        assert e["none"] == direct.count(None) and sum(e["counts"]) + e["none"] == 24
        assert e["values"] == sorted(set(e["values"]))                      # distinct, each counted once
        assert np.allclose(np.repeat(e["values"], e["counts"]), have, rtol=0, atol=1e-4)
        if have:
            want = np.quantile(have, qs)
            assert np.allclose(weighted_quantiles(e["values"], e["counts"], qs), want, rtol=0, atol=1e-4)
            assert np.allclose(band[:, t], np.maximum(want, 1e-4), rtol=0, atol=1e-4)
            spread |= max(e["counts"]) > 1 and len(e["values"]) > 1
    assert spread     # some episode has several errors, some shared by several orders: the counts matter
    assert np.allclose(np.repeat(eps[-1]["values"], eps[-1]["counts"]),
                       sorted(x for x in pop["final_probe_rel_error"] if x is not None), rtol=0, atol=0)
    plain = run_population(names, probe_names, orders, outcomes, probes, exp.config, chunk=5, threads=1, merge=False,
                           curves=True)
    assert plain["curves"] == pop["curves"]
