"""Context properties (EncoderConfig.context: an apparatus' tube perceived with the object) are judged by the same four
rules through the same comparisons as the object's properties (issue 32), in both models; with no context the agent
is the paper's four properties, unchanged.

Oracles by hand: the same object dropped twice, the second time into a tube that differs in one context property.
Same outcome -> that property changed and the outcome held: Elimination (its pathway drastically reduced, 0.05).
Outcome moved (20 -> 60 cm^3, past the 20 % contradiction tolerance) -> Growth (paper: 1 + growth_step = 2;
extended: dominant, 3). Two context properties changed at once -> neither rule can attribute it: no verdict."""

from dataclasses import replace

import pytest
import torch

from aesop_torch.agent import Agent
from aesop_torch.agent_config import AgentConfig
from aesop_torch.encoders import PROPERTIES, EncoderConfig
from aesop_torch.rules import DOMINANT, ELIMINATION, GROWTH, IRRELEVANT, STATUS_QUO, UNKNOWN

CONTEXT = ("surface", "place")
OBJ = {"rgb": [[0.8, 0.1, 0.1]], "extent_cm": [[4.0, 4.0, 4.0]], "fill": [1.0], "mass_g": [150.0]}


@pytest.fixture(scope="module")
def maps():
    """The context agents' maps, developed once (small: the oracles need the maps to tell 0.15 from 0.6 only)."""
    return Agent(_config("paper"), batch=1).maps


def _config(model):
    return AgentConfig.named(model, encoder=EncoderConfig(context=CONTEXT), som_samples=800, som_epochs=5, seed=1)


def _agent(model, maps):
    agent = Agent(_config(model), batch=1, develop=False)
    agent.maps = maps
    return agent


def _drop(agent, surface, place, observed):
    m = dict(OBJ, context={"surface": [surface], "place": [place]})
    no = torch.zeros(1, dtype=torch.bool)
    return agent.step(m, torch.tensor([observed]), no, no, sank=torch.ones(1, dtype=torch.bool))


def test_default_config_judges_the_four_properties_and_serialises_as_before():
    c = AgentConfig()
    assert c.properties == PROPERTIES and len(c.delta_p_band) == 4
    assert "CONTEXT_DELTA_BAND" not in c.to_dict()
    agent = Agent(replace(c, som_samples=200, som_epochs=1), batch=1)
    assert agent.properties == PROPERTIES and agent._judged() == [0, 1, 2, 3]
    assert agent.rules.properties == PROPERTIES and agent.rules.state.shape == (1, 4)


def test_context_config_judges_the_context_with_its_band():
    c = _config("extended")
    assert c.properties == PROPERTIES + CONTEXT
    assert c.delta_p_band[4:] == (AgentConfig.CONTEXT_DELTA_BAND,) * 2
    again = AgentConfig.from_dict(c.to_dict())
    assert again.delta_p_band == c.delta_p_band and again.properties == c.properties
    with pytest.raises(ValueError, match="delta_p_band"):
        replace(c, delta_p_band=c.delta_p_band[:5])


@pytest.mark.parametrize("model", ["paper", "extended"])
def test_context_change_with_the_same_outcome_is_eliminated(model, maps):
    agent = _agent(model, maps)
    assert agent.rules.properties == PROPERTIES + CONTEXT
    _drop(agent, 0.15, 0.5, 20.0)
    step = _drop(agent, 0.6, 0.5, 20.0)                       # only the surface's look changed; the outcome held
    s = PROPERTIES.index("weight") + 1 + CONTEXT.index("surface")
    assert step.delta_p[0, 0].tolist() == [False] * 4 + [True, False]
    assert step.fired[0, 0, s] == ELIMINATION
    assert agent.rules.state[0, s] == IRRELEVANT
    surface_map = list(agent.maps).index("surface")
    assert agent.hub.strength[0, surface_map] == pytest.approx(agent.config.rules.eliminated_strength)
    assert (agent.rules.state[0, :4] == UNKNOWN).all()        # the object's properties did not change: no verdict


@pytest.mark.parametrize("model", ["paper", "extended"])
def test_context_change_with_another_outcome_grows(model, maps):
    agent = _agent(model, maps)
    _drop(agent, 0.15, 0.5, 20.0)
    step = _drop(agent, 0.6, 0.5, 60.0)                       # only the surface's look changed; the outcome tripled
    s = 4 + CONTEXT.index("surface")
    assert step.delta_c[0, 0] and step.fired[0, 0, s] == GROWTH
    assert agent.rules.state[0, s] == DOMINANT
    want = 1.0 + agent.config.rules.growth_step if model == "paper" else agent.config.rules.dominant_strength
    assert agent.hub.strength[0, list(agent.maps).index("surface")] == pytest.approx(want)
    # the strengths act in recall as the object's do: each tube's option is predicted nearer its own episode's
    # outcome than the other's (their geometric midpoint, 34.6). The paper model's readout (recall strength to the
    # 16th) takes its own episode's within 10 %; the extended one's fit has no context column
    # (fitted_readout.FEATURE_COLUMNS), so both episodes enter it, weighted by recall strength
    pred = [float(agent.predict(dict(OBJ, context={"surface": [v], "place": [0.5]}))[0]) for v in (0.15, 0.6)]
    assert pred[0] < (20.0 * 60.0) ** 0.5 < pred[1]
    if model == "paper":
        assert pred[0] == pytest.approx(20.0, rel=0.1) and pred[1] == pytest.approx(60.0, rel=0.1)


@pytest.mark.parametrize("model", ["paper", "extended"])
def test_two_context_changes_at_once_are_not_attributed(model, maps):
    agent = _agent(model, maps)
    _drop(agent, 0.15, 0.0, 20.0)
    step = _drop(agent, 0.6, 1.0, 20.0)                       # surface and place changed together, outcome held
    assert step.delta_p[0, 0].tolist() == [False] * 4 + [True, True]
    if model == "paper":                                      # the paper model fires E only on a clean comparison
        assert (step.fired[0, 0, 4:] == STATUS_QUO).all()
    # the extended model reports E on each changed property, and keeps the change set {surface, place} as evidence:
    # two changes may cancel, so neither is eliminated. Both models: no verdict, both pathways kept
    assert (agent.rules.state[0, 4:] == UNKNOWN).all()
    assert (agent.hub.strength[0, [list(agent.maps).index(p) for p in CONTEXT]] == 1.0).all()
