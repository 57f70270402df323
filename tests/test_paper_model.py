"""The paper model: rules that edit the pathway strengths one firing at a time, knowledge that reaches recall through
them, and a readout that is a weighted average of the recalled rewards."""

import math

import pytest
import torch

from aesop_torch import Agent, AgentConfig
from aesop_torch.incremental_rules import IncrementalRules
from aesop_torch.readouts import recall_average
from aesop_torch.rules import (DOMINANT, IRRELEVANT, LIKELY_IRRELEVANT, RULE_NAMES, UNKNOWN, RulesConfig)

C, SH, SI, W = range(4)
RED, BLUE, GREEN = (0.85, 0.1, 0.1), (0.1, 0.2, 0.85), (0.1, 0.8, 0.2)
CYL = [11.5, 6.36, 6.36]


def changed(*props):
    x = torch.zeros(1, 4, dtype=torch.bool)
    x[0, list(props)] = True
    return x


def fire(rules, props, contradicted):
    out = rules.apply(changed(*props), torch.tensor([contradicted]), torch.tensor([True]))
    return "".join(RULE_NAMES[int(c)] for c in out[0])


def test_each_firing_edits_the_strengths_as_the_paper_says():
    cfg = RulesConfig()
    rules = IncrementalRules(cfg)
    assert fire(rules, [C], False) == "ESSS"                       # colour alone changed, outcome held
    assert rules.strength[0, C].item() == pytest.approx(cfg.eliminated_strength)
    assert fire(rules, [W], True) == "SUUG"                        # weight alone changed, outcome moved
    assert rules.strength[0].tolist() == pytest.approx([cfg.eliminated_strength, cfg.uncertain_decay,
                                                         cfg.uncertain_decay, 1.0 + cfg.growth_step])
    assert rules.state[0].tolist() == [IRRELEVANT, LIKELY_IRRELEVANT, LIKELY_IRRELEVANT, DOMINANT]
    assert rules.certainty[0].tolist() == pytest.approx([1.0, cfg.certainty_step, cfg.certainty_step, 1.0])
    for _ in range(5):
        fire(rules, [W], True)
    assert rules.strength[0, W].item() == cfg.dominant_strength    # capped
    assert rules.strength[0, SH].item() == cfg.uncertain_floor     # Uncertainty never silences a pathway
    assert rules.fired[0, W].tolist() == [1, 0, 6, 0]              # S (episode 2), E, G, U counts


def test_an_eliminated_pathway_fires_nothing_again_and_a_confound_attributes_nothing():
    rules = IncrementalRules()
    fire(rules, [C], False)
    assert fire(rules, [C], True) == "SUUU"          # colour shows no change any more: the others are uncertain
    assert fire(rules, [C, W], True) == "SUUG"       # ... so colour and weight changed is a clean weight change
    before = rules.strength.clone()
    assert fire(rules, [SH, SI], True) == "SSSS"     # two changed: neither can be told; weight is dominant (no U)
    assert fire(rules, [SH, SI], False) == "SSSS"
    assert torch.equal(rules.strength, before)


def test_a_pathway_grown_on_growth_still_ends_irrelevant_after_a_clean_elimination():
    rules = IncrementalRules()
    fire(rules, [C], True)
    assert rules.state[0, C] == DOMINANT
    fire(rules, [C], False)
    assert rules.state[0, C] == IRRELEVANT and rules.state[0, W] == LIKELY_IRRELEVANT
    assert (IncrementalRules().state == UNKNOWN).all()


def test_recall_average_by_hand():
    rewards = torch.tensor([[100.0, 10.0, float("nan")], [5.0, 7.0, 9.0]])
    strength = torch.tensor([[1.0, 0.5, 1.0], [0.0, 0.0, 0.0]])
    assert recall_average(rewards, strength, 1.0)[0].item() == pytest.approx(105.0 / 1.5)
    assert recall_average(rewards, strength, 2.0)[0].item() == pytest.approx(102.5 / 1.25)
    assert math.isnan(recall_average(rewards, strength, 2.0)[1].item())   # nothing recalled


def lifted(rgb, mass_g, B=1):
    return {"rgb": torch.tensor([rgb] * B), "extent_cm": torch.tensor([CYL] * B),
            "fill": torch.tensor([math.pi / 4] * B), "mass_g": torch.tensor([float(mass_g)] * B)}


def remember(agent, m, cm3, sank):
    agent.remember(m, torch.tensor([cm3]), torch.tensor([False]), torch.tensor([cm3 > 200]), sank=torch.tensor([sank]))


@pytest.mark.parametrize("ablate", [(), ("rules",)])
def test_once_colour_is_eliminated_the_cue_recalls_the_weight_matched_episode(ablate):
    """Two remembered episodes: red heavy (365 cm^3) and blue light (24 cm^3). A blue heavy cylinder matches each in
    three properties of four, and is expected between the two. Then a green heavy cylinder displaces what the red
    one did: colour alone changed, Elimination. Now the blue heavy cylinder's cue brings back the weight-matched
    episode, and the prediction moves to its reward. With the rules off it stays where it was."""
    agent = Agent(AgentConfig.paper(seed=0, ablate=ablate))
    remember(agent, lifted(RED, 420), 365.0, True)
    remember(agent, lifted(BLUE, 14), 24.0, False)
    probe = lifted(BLUE, 420)
    before = agent.predict(probe).item()
    assert 60.0 < before < 330.0, before                            # between the two: a tie of look and weight
    agent.step(lifted(GREEN, 420), torch.tensor([365.0]), torch.tensor([False]), torch.tensor([True]),
               sank=torch.tensor([True]))
    after = agent.predict(probe).item()
    if ablate:
        assert agent.knowledge(0)["color"]["state"] == "unknown" and after == pytest.approx(before, rel=1e-4)
    else:
        assert agent.knowledge(0)["color"]["state"] == "irrelevant"
        assert after == pytest.approx(365.0, rel=0.03), after


@pytest.mark.parametrize("ablate", [(), ("rules",), ("gating",)])
def test_a_paper_prediction_lies_within_the_recalled_rewards(ablate):
    """A weighted average cannot extrapolate: for novel objects far outside what was stored (a 1 g and a 3 kg
    cylinder) as well as inside, every prediction lies in [min, max] of the rewards its recall brought back."""
    agent = Agent(AgentConfig.paper(seed=1, ablate=ablate))
    g = torch.Generator().manual_seed(5)
    for _ in range(10):
        mass = float(torch.exp(torch.empty(1).uniform_(math.log(10), math.log(900), generator=g)))
        rgb = tuple(torch.rand(3, generator=g).tolist())
        agent.step(lifted(rgb, mass), torch.tensor([min(mass, 365.0)]), torch.tensor([False]),
                   torch.tensor([mass > 200]), sank=torch.tensor([mass > 365]))
    predicted = 0
    for mass in (1.0, 30.0, 200.0, 600.0, 3000.0):
        a = agent.anticipate(lifted(RED, mass))
        got = a.rewards[a.recall.valid & (a.recall.strength > 0)]
        if got.numel() == 0:                       # a cue that settles on no episode: no prediction at all
            assert math.isnan(a.expected.item())
            continue
        predicted += 1
        assert got.min().item() * (1 - 1e-6) <= a.expected.item() <= got.max().item() * (1 + 1e-6)
    assert predicted >= 3


def test_gating_ablation_makes_the_cue_ignore_the_strengths():
    on, off = (Agent(AgentConfig.paper(seed=0, ablate=a)) for a in ((), ("gating",)))
    for agent in (on, off):
        agent.hub.strength[0, C] = 0.05                             # colour eliminated
        remember(agent, lifted(RED, 420), 365.0, True)
    blue = lifted(BLUE, 420)
    cue_on = on.hub.bottom_up(*on.activities(blue))
    assert on.anticipate(blue).recall.strength[0, 0] > off.anticipate(blue).recall.strength[0, 0]
    assert cue_on.max().item() > 0.95                               # colour barely counts: a near-full match


def test_named_configs_and_bad_ablations():
    assert AgentConfig() == AgentConfig.paper() and AgentConfig.named("extended") == AgentConfig.extended()
    assert AgentConfig.extended().compare_with is None and AgentConfig.paper().compare_with == 1
    with pytest.raises(ValueError, match="prior"):
        AgentConfig.paper(ablate=("prior",))
    with pytest.raises(ValueError, match="model"):
        AgentConfig(model="bayes")
    assert AgentConfig.from_dict(AgentConfig.extended(ablate=("prior",)).to_dict()).ablate == ("prior",)
