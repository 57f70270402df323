"""The learning rules as a truth table, the paper's episodes 2-3 as rule inputs, knowledge as a function of the
evidence (order independence, contexts, minimal explanations), and the batch answer on a set worked by hand."""

import pytest
import torch

from aesop_torch.rules import (DOMINANT, FLOATING, IRRELEVANT, LIKELY_IRRELEVANT, MIXED, RULE_NAMES, SINKING, UNKNOWN,
                               CausalRules, RulesConfig, batch_knowledge, context_of, contradiction, outcome_unclear)

C, SH, SI, W = range(4)  # color, shape, size, weight


def dp(*props, B=1):
    x = torch.zeros(B, 4, dtype=torch.bool)
    for p in props:
        x[:, p] = True
    return x


def fire(rules, changed, contradicted, strength=None, compared=True, context=MIXED):
    B = rules.state.shape[0]
    out = rules.apply(changed, torch.full((B,), contradicted), torch.full((B,), compared), strength,
                      torch.full((B,), context))
    return ["".join(RULE_NAMES[int(c)] for c in row) for row in out]


def test_contradiction_tolerance():
    cfg = RulesConfig()
    obs = torch.tensor([365.0, 24.0, 365.0, 50.0, 10.0])
    exp = torch.tensor([364.0, 365.0, float("nan"), 38.0, 8.0])
    # 1 off: as expected; 341 off: contradiction; nothing expected: nothing to contradict; 12 off, 24 % of the
    # larger (50): contradiction (> 20 %); 2 off of 10 is within the 3 cm^3 absolute reading tolerance
    assert contradiction(obs, exp, cfg).tolist() == [False, True, False, True, False]
    # between as expected (max(1 cm^3, 5 %)) and contradicted (max(3 cm^3, 20 %)): the dead zone
    assert outcome_unclear(obs, exp, cfg).tolist() == [False, False, False, False, True]
    # relative to the larger of the two: a against b reads as b against a
    seen = ~torch.isnan(exp)
    assert contradiction(exp[seen], obs[seen], cfg).tolist() == contradiction(obs, exp, cfg)[seen].tolist()
    assert outcome_unclear(exp[seen], obs[seen], cfg).tolist() == outcome_unclear(obs, exp, cfg)[seen].tolist()
    assert not contradiction(torch.tensor([50.0]), torch.tensor([40.0]), cfg).item()      # 10 of 50: 20 %, not more
    assert outcome_unclear(torch.tensor([100.0]), torch.tensor([90.0]), cfg).item()        # 10 % off
    assert not outcome_unclear(torch.tensor([100.0]), torch.tensor([96.0]), cfg).item()    # 4 %: as expected


def test_context_of_fates():
    a, b = torch.tensor([0, 1, 0, 1, -1]), torch.tensor([0, 1, 1, 0, 1])
    assert context_of(a, b).tolist() == [FLOATING, SINKING, MIXED, MIXED, MIXED]


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


def test_uncertainty_reduces_a_pathway_marginally_and_never_silences_it():
    """0.85^n per firing down to the floor (0.5 by default): 0.85, 0.7225, 0.614, 0.522, then 0.5 for ever, far
    above the strength below which a pathway retro-activates nothing (AgentConfig.retro_floor 0.1), where an
    eliminated one sits (0.05)."""
    rules, strength = CausalRules(), torch.ones(1, 4)
    seen = []
    for _ in range(120):
        fire(rules, dp(W), True, strength)
        seen.append(float(strength[0, SH]))
    assert seen[:5] == pytest.approx([0.85, 0.7225, 0.614125, 0.52200625, 0.5])
    assert seen[-1] == 0.5 and rules.state[0, SH] == LIKELY_IRRELEVANT
    fire(rules, dp(SH), False, strength)
    assert float(strength[0, SH]) == pytest.approx(0.05)


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


def test_relevance_differs_by_context_and_the_order_does_not_matter():
    # weight alone changes the outcome of a floater (12 g vs 30 g) and does not change a sinker's (two of equal size)
    a, b = CausalRules(), CausalRules()
    fire(a, dp(W), True, context=FLOATING)
    fire(a, dp(W), False, context=SINKING)
    fire(b, dp(W), False, context=SINKING)
    assert b.state[0, W] == IRRELEVANT
    fire(b, dp(W), True, context=FLOATING)
    assert a.state[0, W] == b.state[0, W] == DOMINANT          # it matters somewhere
    assert a.by_context(0)["floating"]["dominant"] == ["weight"]
    assert a.by_context(0)["sinking"]["irrelevant"] == ["weight"]


def test_agents_in_a_batch_are_independent():
    rules, strength = CausalRules(batch=2), torch.ones(2, 4)
    changed = torch.tensor([[True, False, False, False], [False, False, False, True]])
    out = rules.apply(changed, torch.tensor([False, True]), torch.tensor([True, True]), strength)
    assert ["".join(RULE_NAMES[int(c)] for c in r) for r in out] == ["ESSS", "UUUG"]
    assert strength[0].tolist() == pytest.approx([0.05, 1.0, 1.0, 1.0])
    state = rules.state_dict()
    fresh = CausalRules(batch=2)
    fresh.load_state_dict(state)
    assert torch.equal(fresh.state, rules.state) and torch.equal(fresh.contradicted, rules.contradicted)


def test_an_eliminated_pathway_shows_no_change_in_its_context():
    rules = CausalRules()
    fire(rules, dp(C), False)                 # colour eliminated (in the mixed context)
    # colour no longer retro-activates there: the change it would show is not seen, weight alone changed
    assert fire(rules, dp(C, W), True) == ["SUUG"]
    assert rules.state[0].tolist() == [IRRELEVANT, LIKELY_IRRELEVANT, LIKELY_IRRELEVANT, DOMINANT]


def test_minimal_explanation_resolves_a_confound():
    # colour and weight changed together (contradicted); elsewhere weight and size changed together (contradicted):
    # weight alone explains both, so weight is dominant and colour and size are not
    rules = CausalRules()
    fire(rules, dp(C, W), True)
    assert rules.state[0].tolist() == [DOMINANT, LIKELY_IRRELEVANT, LIKELY_IRRELEVANT, DOMINANT]   # both candidates
    fire(rules, dp(SI, W), True)
    assert rules.dominant[0, MIXED].tolist() == [False, False, False, True]
    assert rules.state[0, C] != DOMINANT and rules.state[0, SI] != DOMINANT


def test_an_elimination_elsewhere_is_presumed_unless_the_evidence_needs_the_property():
    rules = CausalRules()
    fire(rules, dp(C), False, context=FLOATING)       # colour irrelevant for floaters
    fire(rules, dp(C, SI), True, context=SINKING)     # a sinker pair: colour and size changed, outcome too
    assert rules.dominant[0, SINKING].tolist() == [False, False, True, False]   # size, not colour
    other = CausalRules()
    fire(other, dp(C), False, context=FLOATING)
    fire(other, dp(C), True, context=SINKING)         # only colour changed, and the outcome did: it is needed
    assert other.dominant[0, SINKING].tolist() == [True, False, False, False]


def test_a_floater_against_a_sinker_is_explained_by_what_matters_for_either():
    """Colour, shape and size eliminated for floaters, weight grown for floaters and size for sinkers. A floater
    against a sinker changed colour, shape and size (outcome moved), another only weight (moved): the first needs a
    property presumed irrelevant, so the mixed context explains on its own evidence, and {colour, weight},
    {shape, weight} and {size, weight} explain both equally well. Of these {size, weight} alone uses only what
    matters for a floater or a sinker: colour and shape stay irrelevant (both were dominant before, 2026-12-02)."""
    rules = CausalRules()
    for p in (C, SH, SI):
        fire(rules, dp(p), False, context=FLOATING)
    fire(rules, dp(W), True, context=FLOATING)
    fire(rules, dp(SI), True, context=SINKING)
    fire(rules, dp(C, SH, SI), True, context=MIXED)
    fire(rules, dp(W), True, context=MIXED)
    assert rules.dominant[0, MIXED].tolist() == [False, False, True, True]
    assert rules.state[0].tolist() == [IRRELEVANT, IRRELEVANT, DOMINANT, DOMINANT]
    # with nothing dominant for floaters or sinkers, the mixed context keeps every minimal explanation
    bare = CausalRules()
    for p in (C, SH, SI):
        fire(bare, dp(p), False, context=FLOATING)
    fire(bare, dp(C, SH, SI), True, context=MIXED)
    fire(bare, dp(W), True, context=MIXED)
    assert bare.dominant[0, MIXED].tolist() == [True, True, True, True]


def test_several_changes_that_hold_eliminate_nothing():
    # a larger but hollower object can displace the same: no verdict on either
    rules = CausalRules()
    fire(rules, dp(SH, SI), False, context=SINKING)
    assert (rules.state == UNKNOWN).all()
    fire(rules, dp(SH), False, context=SINKING)       # now shape alone held: shape out, and with it size alone
    assert rules.eliminated[0, SINKING].tolist() == [False, True, True, False]


def test_an_outcome_that_moves_with_nothing_seen_changed_withdraws_the_context_eliminations():
    """The cascade above: shape held alone, so a larger-but-hollower sinker pair counted as size alone, and both went
    for sinkers. Two sinkers whose outcome then moved while nothing the context still sees changed (shape and size
    no longer retro-activate there) show that an eliminated property mattered: the sinking context's held evidence
    is forgotten, its pathways retro-activate again, and the same pair now shows both changes: no verdict. The
    floaters' elimination stays, and colour is judged afresh for sinkers."""
    rules = CausalRules()
    fire(rules, dp(C), False, context=FLOATING)
    fire(rules, dp(SH, SI), False, context=SINKING)
    fire(rules, dp(SH), False, context=SINKING)
    assert rules.eliminated[0, SINKING].tolist() == [False, True, True, False]
    fire(rules, dp(), True, context=SINKING)          # nothing seen changed, the outcome moved
    assert rules.eliminated[0, SINKING].tolist() == [False, False, False, False]
    assert rules.eliminated[0, FLOATING].tolist() == [True, False, False, False]
    fire(rules, dp(SH, SI), False, context=SINKING)
    assert not rules.eliminated[0, SINKING].any()
    fire(rules, dp(C), False, context=SINKING)
    assert rules.eliminated[0, SINKING].tolist() == [True, False, False, False]
    # where nothing was eliminated such an outcome is noise and forgets nothing
    other = CausalRules()
    fire(other, dp(SH), False, context=FLOATING)
    fire(other, dp(), True, context=SINKING)
    assert other.eliminated[0, FLOATING].tolist() == [False, True, False, False]
    assert other.held[0, FLOATING].any()


def test_knowledge_does_not_depend_on_the_order_of_the_evidence():
    g = torch.Generator().manual_seed(7)
    for _ in range(30):
        n = 12
        changed = torch.rand(n, 4, generator=g) < 0.4
        # every contradicted comparison shows a change: one that shows none withdraws eliminations (test above)
        contra = (torch.rand(n, generator=g) < 0.5) & changed.any(-1)
        ctx = torch.randint(3, (n,), generator=g)
        states = set()
        for _ in range(4):
            order = torch.randperm(n, generator=g)
            rules = CausalRules()
            for i in order.tolist():
                rules.apply(changed[i:i + 1], contra[i:i + 1], torch.ones(1, dtype=torch.bool), context=ctx[i:i + 1])
            states.add(tuple(rules.state[0].tolist()))
        assert len(states) == 1


def test_batch_answer_of_a_three_object_set_by_hand():
    """Three objects: a heavy red cylinder (sinks, 365), the same in blue (sinks, 365), the red one at 14 g (floats,
    14). Pairs, episode j against i at [i, j]:
      (0, 1) colour changed, outcome held, sinking: colour eliminated (clean) for sinkers;
      (0, 2) weight changed, contradicted, mixed: weight needed;
      (1, 2) colour and weight changed, contradicted, mixed: colour presumed irrelevant (eliminated for sinkers),
             so weight explains it.
    Knowledge: colour irrelevant, shape and size likely irrelevant (the outcome changed while they did not), weight
    dominant."""
    C_, SH_, SI_, W_ = range(4)
    delta_p = torch.zeros(3, 3, 4, dtype=torch.bool)
    delta_p[0, 1, C_] = True
    delta_p[0, 2, W_] = True
    delta_p[1, 2, C_] = delta_p[1, 2, W_] = True
    delta_c = torch.tensor([[False, False, True], [False, False, True], [False, False, False]])
    sank = torch.tensor([1, 1, 0])
    context = context_of(sank[:, None].expand(3, 3), sank[None, :].expand(3, 3))
    state = batch_knowledge(delta_p, delta_c, context)
    assert state.tolist() == [IRRELEVANT, LIKELY_IRRELEVANT, LIKELY_IRRELEVANT, DOMINANT]
    # the lower triangle is not read: a pair is compared once
    delta_p[2, 0, C_] = True
    assert batch_knowledge(delta_p, delta_c, context).tolist() == state.tolist()


def test_a_property_dominant_only_through_a_confound_is_flagged():
    """Colour and weight changed together among sinkers and the outcome moved: both dominant, neither shown alone
    (confounded). Weight alone then moves a sinker's outcome: weight explains both, colour drops out. Among floaters
    colour and size change together: both dominant for floaters, confounded; weight stays shown (among sinkers)."""
    rules = CausalRules()
    fire(rules, dp(C, W), True, context=SINKING)
    assert rules.state[0].tolist() == [DOMINANT, LIKELY_IRRELEVANT, LIKELY_IRRELEVANT, DOMINANT]
    assert rules.confounded[0].tolist() == [True, False, False, True]
    fire(rules, dp(W), True, context=SINKING)
    assert rules.state[0].tolist() == [LIKELY_IRRELEVANT, LIKELY_IRRELEVANT, LIKELY_IRRELEVANT, DOMINANT]
    assert not rules.confounded.any()
    fire(rules, dp(C, SI), True, context=FLOATING)
    assert rules.state[0].tolist() == [DOMINANT, LIKELY_IRRELEVANT, DOMINANT, DOMINANT]
    assert rules.confounded[0].tolist() == [True, False, True, False]
