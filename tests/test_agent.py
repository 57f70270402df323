"""The paper's episodes 1-3 through the whole agent, as pure data (no simulator)."""

import math

import pytest
import torch

from aesop_torch import Agent, AgentConfig
from aesop_torch.rules import RULE_NAMES

RED, BLUE = (0.85, 0.1, 0.1), (0.1, 0.2, 0.85)
CYL = ([11.5, 6.36, 6.36], math.pi / 4)  # the paper's large cylinder: 6.36 cm across, 11.5 cm tall


def lifted(rgb, mass_g, extent=CYL[0], fill=CYL[1], B=1):
    return {"rgb": torch.tensor([rgb] * B), "extent_cm": torch.tensor([extent] * B), "fill": torch.tensor([fill] * B),
            "mass_g": torch.tensor([float(mass_g)] * B)}


def drop(agent, m, observed, reached):
    B = agent.batch
    return agent.step(m, torch.full((B,), float(observed)), torch.zeros(B, dtype=torch.bool),
                      torch.full((B,), reached))


def letters(step, b=0):
    return "".join(RULE_NAMES[int(r)] for r in step.rules_fired()[b])


@pytest.fixture(scope="module")
def paper():
    agent = Agent(AgentConfig(seed=0))
    e1 = drop(agent, lifted(RED, 420), 365.0, True)
    e2 = drop(agent, lifted(BLUE, 420), 365.0, True)
    e3 = drop(agent, lifted(RED, 14), 24.0, False)
    return agent, e1, e2, e3


def test_episode_1_explores_and_encodes(paper):
    _, e1, _, _ = paper
    assert not e1.recalled.item() and math.isnan(e1.expected.item())
    assert letters(e1) == "SSSS" and e1.encoded.item()


def test_episode_2_expects_365_eliminates_colour_and_does_not_encode(paper):
    agent, _, e2, _ = paper
    assert e2.recalled.item() and e2.expected.item() == pytest.approx(365.0, abs=2.0)  # reward code step: 2 cm^3
    assert letters(e2) == "ESSS" and not e2.encoded.item()


def test_episode_3_grows_weight_makes_shape_and_size_uncertain_and_encodes(paper):
    agent, _, _, e3 = paper
    assert e3.expected.item() == pytest.approx(365.0, abs=2.0) and e3.delta_c[0, 0].item()
    assert letters(e3) == "SUUG" and e3.encoded.item()
    k = agent.knowledge(0)
    assert k["color"] == {"state": "irrelevant", "certainty": 1.0}
    assert k["weight"] == {"state": "dominant", "certainty": 1.0}
    assert k["shape"]["state"] == k["size"]["state"] == "likely_irrelevant"
    assert 0 < k["shape"]["certainty"] < 1
    assert agent.memory.count.item() == 2  # episodes 1 and 3; episode 2 was not encoded


def test_prediction_is_the_strength_weighted_average_of_recalled_rewards(paper):
    agent = paper[0]
    m = lifted(RED, 100)  # a weight between the two stored cylinders' (14 g, 420 g)
    a = agent.anticipate(m)
    w = a.recall.strength[0] ** agent.config.prediction_sharpness * a.recall.valid[0]
    by_hand = float((w * torch.nan_to_num(a.rewards[0])).sum() / w.sum())
    assert a.recall.valid[0].sum() >= 1
    assert agent.predict(m).item() == pytest.approx(by_hand)
    # the stored objects themselves are predicted from their own episodes
    assert agent.predict(lifted(RED, 420)).item() == pytest.approx(365, abs=8)
    assert agent.predict(lifted(RED, 14)).item() == pytest.approx(24, abs=8)


def test_nothing_recalled_predicts_nan():
    agent = Agent(AgentConfig(seed=0))
    assert math.isnan(agent.predict(lifted(RED, 420)).item())


def test_batched_agents_match_single_agents_and_state_dict_round_trips():
    # agent 0 sees red, blue; agent 1 sees blue, red (two orders side by side)
    both = Agent(AgentConfig(seed=3), batch=2)
    singles = [Agent(AgentConfig(seed=3)), Agent(AgentConfig(seed=3))]
    seq = [(RED, BLUE), (BLUE, RED)]
    for t in range(2):
        m = {k: torch.cat([lifted(seq[0][t], 420)[k], lifted(seq[1][t], 420)[k]]) for k in lifted(RED, 1)}
        sb = drop(both, m, 365.0, True)
        for b in range(2):
            s1 = drop(singles[b], lifted(seq[b][t], 420), 365.0, True)
            assert letters(sb, b) == letters(s1)
    for b in range(2):
        assert both.knowledge(b) == singles[b].knowledge(0)
        assert torch.equal(both.memory.patterns[b], singles[b].memory.patterns[0])
    copy = Agent(AgentConfig(seed=3), batch=2)
    copy.load_state_dict(both.state_dict())
    probe = {k: torch.cat([v, v]) for k, v in lifted(RED, 400).items()}
    assert torch.equal(copy.predict(probe), both.predict(probe))
