"""Every public module works inside someone else's torch model: train()/eval(), .to(), state_dict, and calls.

Written because `SelfOrganizingMap.train(data, ...)` once replaced nn.Module.train(mode), so `model.eval()` on any
model holding a map (or an Agent) raised a TypeError.
"""

import math

import pytest
import torch
from torch import nn

from aesop_torch import (Agent, AgentConfig, CausalRules, EpisodicMemory, ObjectHub, SelfOrganizingMap,
                         SensoryEncoder, SOMConfig)
from aesop_torch.agent import OBJECT_ROWS

CYL = [11.5, 6.36, 6.36]


def lifted(rgb, mass_g, B=1):
    return {"rgb": torch.tensor([rgb] * B), "extent_cm": torch.tensor([CYL] * B),
            "fill": torch.tensor([math.pi / 4] * B), "mass_g": torch.tensor([float(mass_g)] * B)}


class Container(nn.Module):
    """A user's model holding one of every public module."""

    def __init__(self, develop: bool = True):
        super().__init__()
        # a small developmental set keeps the test fast; the API is what is under test
        self.agent = Agent(AgentConfig(seed=0, som_samples=600, som_epochs=5), batch=2, develop=develop)
        self.som = SelfOrganizingMap(SOMConfig(rows=3, cols=3, dim=2))
        self.encoder = SensoryEncoder()
        self.hub = ObjectHub({"color": 9, "size": 4}, batch=2)
        self.memory = EpisodicMemory(batch=2)
        self.rules = CausalRules(batch=2)
        self.head = nn.Linear(4, 1)   # an ordinary trainable layer beside ours


@pytest.fixture(scope="module")
def model():
    m = Container()
    m.som.init_weights(torch.rand(50, 2, generator=torch.Generator().manual_seed(1)))
    m.som.train_online(torch.rand(50, 2, generator=torch.Generator().manual_seed(2)), 20,
                       torch.Generator().manual_seed(3))
    m.agent.step(lifted((0.85, 0.1, 0.1), 420, B=2), torch.tensor([365.0, 365.0]), torch.zeros(2, dtype=torch.bool),
                 torch.ones(2, dtype=torch.bool))
    return m


def test_train_and_eval_reach_every_submodule(model):
    for call, expected in ((lambda: model.train(), True), (lambda: model.eval(), False),
                           (lambda: model.train(False), False), (lambda: model.train(True), True)):
        assert call() is model   # nn.Module.train returns the module itself
        assert all(m.training is expected for m in model.modules()), expected


def test_to_cpu_and_state_dict_round_trip(model):
    assert model.to("cpu") is model
    state = model.state_dict()
    for key in ("agent.maps.color.weights", "agent.hub.branches", "agent.memory.patterns", "agent.rules.state",
                "som.weights", "hub.branches", "memory.patterns", "rules.state", "head.weight"):
        assert key in state, key
    fresh = Container(develop=False)     # maps left at zero: everything must come from the state dict
    assert not torch.equal(fresh.agent.maps["color"].weights, model.agent.maps["color"].weights)
    fresh.load_state_dict(state)
    for k, v in fresh.state_dict().items():
        assert torch.equal(v, state[k]), k
    # everything the agent computes follows from the loaded state: predictions agree exactly
    m = lifted((0.1, 0.25, 0.85), 420, B=2)
    assert torch.equal(fresh.agent.predict(m).nan_to_num(-1.0), model.agent.predict(m).nan_to_num(-1.0))


def test_every_module_can_be_called_in_eval_mode(model):
    model.eval()
    m = lifted((0.1, 0.25, 0.85), 420, B=2)
    inputs = model.encoder(m)
    assert set(inputs) == {"color", "shape", "size", "weight"} and inputs["color"].shape == (2, 3)
    x = torch.tensor([[0.2, 0.7], [0.9, 0.1]])
    assert model.som.activity(x).shape == (2, 9) and model.som.winner(x).shape == (2,)
    acts = torch.zeros(2, 2, 9)
    acts[:, 0, :] = model.agent.maps["color"].activity(inputs["color"])[:, :9]
    acts[:, 1, :4] = torch.tensor([0.1, 1.0, 0.2, 0.0])
    present = torch.ones(2, 2, dtype=torch.bool)
    model.hub.allocate(acts.argmax(-1), present, torch.ones(2, dtype=torch.bool))
    cue = model.hub.bottom_up(acts, present)
    assert cue.shape == (2, 50) and cue.max() > 0
    assert model.hub.top_down(cue).shape == (2, 2, 9)
    recall = model.memory.recall(cue)            # empty memory: nothing recalled
    assert not recall.any.any()
    fired = model.rules.apply(torch.tensor([[True, False, False, False]] * 2), torch.tensor([False, True]),
                              torch.ones(2, dtype=torch.bool))
    assert fired.shape == (2, 4)
    assert model.rules.knowledge(0)["color"]["state"] == "irrelevant"    # changed, outcome did not: Elimination
    assert model.rules.knowledge(1)["color"]["state"] == "dominant"      # changed, outcome did too: Growth
    expected = model.agent.predict(lifted((0.1, 0.25, 0.85), 420, B=2))   # the same cylinder in blue
    assert expected == pytest.approx([365.0, 365.0], abs=3.0)
    assert model.agent.memory.count.tolist() == [1, 1]
    assert model.agent.memory.patterns[0, 0, list(OBJECT_ROWS)].sum() == 24     # 2 neurons on each of 12 rows
    assert model.head(torch.ones(1, 4)).shape == (1, 1)
