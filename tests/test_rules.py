"""The learning rules as a truth table, the paper's episodes 2-3 as rule inputs, and order independence."""

import pytest
import torch

from aesop_torch.rules import (DOMINANT, IRRELEVANT, LIKELY_IRRELEVANT, RULE_NAMES, UNKNOWN, CausalRules,
                               RulesConfig, contradiction)

C, SH, SI, W = range(4)  # color, shape, size, weight


def dp(*props, B=1):
    x = torch.zeros(B, 4, dtype=torch.bool)
    for p in props:
        x[:, p] = True
    return x


def fire(rules, changed, contradicted, strength=None, compared=True):
    B = rules.state.shape[0]
    out = rules.apply(changed, torch.full((B,), contradicted), torch.full((B,), compared), strength)
    return ["".join(RULE_NAMES[int(c)] for c in row) for row in out]


def test_contradiction_tolerance():
    cfg = RulesConfig()
    obs = torch.tensor([365.0, 24.0, 365.0, 50.0])
    exp = torch.tensor([364.0, 365.0, float("nan"), 40.0])
    # 1 cm^3 off: same; 341 off: contradiction; nothing expected: nothing to contradict; 10 off of 40 is within
    # the 12 cm^3 absolute reading tolerance
    assert contradiction(obs, exp, cfg).tolist() == [False, True, False, False]
    assert contradiction(torch.tensor([100.0]), torch.tensor([80.0]), cfg).item()  # 20 > max(12, 0.15 * 80)


def test_paper_episode_2_eliminates_colour():
    rules, strength = CausalRules(), torch.ones(1, 4)
    assert fire(rules, dp(C), False, strength) == ["ESSS"]
    assert rules.state[0].tolist() == [IRRELEVANT, UNKNOWN, UNKNOWN, UNKNOWN]
    assert rules.certainty[0].tolist() == [1.0, 0.0, 0.0, 0.0]
    assert strength[0].tolist() == pytest.approx([0.05, 1.0, 1.0, 1.0])  # drastically reduced, others untouched


def test_paper_episode_3_grows_weight_and_makes_shape_and_size_uncertain():
    rules, strength = CausalRules(), torch.ones(1, 4)
    fire(rules, dp(C), False, strength)
    # colour is decided, so a contradiction without a colour change says nothing new about it: status quo
    assert fire(rules, dp(W), True, strength) == ["SUUG"]
    k = rules.knowledge(0)
    assert k["weight"] == {"state": "dominant", "certainty": 1.0}
    assert k["shape"] == {"state": "likely_irrelevant", "certainty": 0.3}
    assert k["size"]["state"] == "likely_irrelevant"
    assert k["color"] == {"state": "irrelevant", "certainty": 1.0}
    assert torch.allclose(strength[0], torch.tensor([0.05, 0.85, 0.85, 3.0]))


def test_no_recall_fires_nothing():
    rules = CausalRules()
    assert fire(rules, dp(C, W), True, compared=False) == ["SSSS"]
    assert (rules.state == UNKNOWN).all()


def test_certainty_grows_with_uncertainty_but_never_reaches_one():
    rules = CausalRules()
    values = []
    for _ in range(40):
        fire(rules, dp(W), True)
        values.append(float(rules.certainty[0, SH]))
    assert values[:3] == pytest.approx([0.3, 0.51, 0.657])  # 1 - 0.7^n by hand
    assert all(a < b for a, b in zip(values[:20], values[1:20]))  # grows with every firing
    assert rules.state[0, SH] == LIKELY_IRRELEVANT and max(values) < 1.0  # never decided by Uncertainty alone


def test_ambiguous_growth_is_overturned_by_clean_elimination_in_either_order():
    # colour and weight change together and the outcome changes; elsewhere colour alone changes without effect
    a, b = CausalRules(), CausalRules()
    fire(a, dp(C, W), True)
    assert a.state[0, C] == DOMINANT and a.state[0, W] == DOMINANT  # ambiguous: both provisionally dominant
    fire(a, dp(C), False)
    fire(b, dp(C), False)
    fire(b, dp(C, W), True)
    assert a.state.tolist() == b.state.tolist()
    assert a.state[0, C] == IRRELEVANT and a.state[0, W] == DOMINANT


def test_clean_growth_outranks_a_later_or_earlier_null_result():
    # weight alone changes the outcome (14 g vs 420 g); elsewhere weight alone changes without effect (two sinkers)
    a, b = CausalRules(), CausalRules()
    fire(a, dp(W), True)
    fire(a, dp(W), False)
    fire(b, dp(W), False)
    assert b.state[0, W] == IRRELEVANT
    fire(b, dp(W), True)
    assert a.state[0, W] == b.state[0, W] == DOMINANT


def test_agents_in_a_batch_are_independent():
    rules, strength = CausalRules(batch=2), torch.ones(2, 4)
    changed = torch.tensor([[True, False, False, False], [False, False, False, True]])
    out = rules.apply(changed, torch.tensor([False, True]), torch.tensor([True, True]), strength)
    assert ["".join(RULE_NAMES[int(c)] for c in r) for r in out] == ["ESSS", "UUUG"]
    assert strength[0].tolist() == pytest.approx([0.05, 1.0, 1.0, 1.0])
    state = rules.state_dict()
    fresh = CausalRules(batch=2)
    fresh.load_state_dict(state)
    assert torch.equal(fresh.state, rules.state) and torch.equal(fresh.proven, rules.proven)


def test_a_known_irrelevant_change_does_not_make_growth_ambiguous():
    rules = CausalRules()
    fire(rules, dp(C), False)                 # colour eliminated
    assert fire(rules, dp(C, W), True) == ["GUUG"]
    assert bool(rules.proven[0, W]) and not bool(rules.proven[0, C])
    assert rules.state[0, C] == IRRELEVANT    # Growth cannot revive an eliminated property
    fire(rules, dp(W), False)                 # a later null result on weight cannot overturn clean dominance
    assert rules.state[0, W] == DOMINANT
