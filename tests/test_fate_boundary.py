"""The contextual model's expected fate from a boundary fitted over the recalled episodes
(aesop_torch/fate_boundary.py), and the recall-weighted vote it replaces kept as the `boundary` ablation."""

import pytest
import torch

from aesop_torch import Agent, AgentConfig
from aesop_torch.fate_boundary import expected_fate
from aesop_torch.local_readout import property_columns

RED = (0.85, 0.1, 0.1)


def _one_property(values, fates, present, live=(True, True)):
    """Recalled episodes on two features (the first the one the fates follow), the present object at `present`."""
    xk = torch.tensor([values], dtype=torch.float32)
    x = torch.tensor([present], dtype=torch.float32)
    f = torch.tensor([fates])
    return float(expected_fate(x, xk, f, torch.ones(1, len(fates)), torch.tensor([live]), ridge=1e-2)[0])


def test_a_boundary_fitted_on_one_property_puts_new_values_on_their_side():
    # floaters at 0.1-0.3 on the first feature, sinkers at 0.6-0.8: the boundary lies between, so a new value
    # beyond either group (which no vote over the group could tell from it) and one on either side of the gap
    # are on their side; the second feature is noise the fates do not follow
    values = [[0.1, 0.5], [0.2, 0.1], [0.3, 0.9], [0.6, 0.2], [0.7, 0.8], [0.8, 0.4]]
    fates = [0, 0, 0, 1, 1, 1]
    assert _one_property(values, fates, [0.95, 0.5]) > 0.9
    assert _one_property(values, fates, [0.55, 0.5]) > 0.5
    assert _one_property(values, fates, [0.35, 0.5]) < 0.5
    assert _one_property(values, fates, [0.0, 0.5]) < 0.1


def test_only_the_live_columns_enter_the_fit_and_nothing_seen_is_even_odds():
    # the fates follow the first feature; with only the second live (it separates nothing) the fit knows nothing
    # of the first, and the present object's side is the share of sinkers among the recalled (half)
    values = [[0.1, 0.5], [0.2, 0.5], [0.7, 0.5], [0.8, 0.5]]
    fates = [0, 0, 1, 1]
    assert _one_property(values, fates, [0.9, 0.5], live=(True, False)) > 0.9
    assert _one_property(values, fates, [0.9, 0.5], live=(False, True)) == pytest.approx(0.5, abs=1e-3)
    # episodes whose fate was not seen (-1) say nothing: even odds
    assert _one_property(values, [-1, -1, -1, -1], [0.9, 0.5]) == 0.5


@pytest.fixture(scope="module")
def developed():
    return {ab: Agent(AgentConfig.contextual(seed=0, ablate=ab)) for ab in ((), ("boundary",))}


def cube(side_cm, mass_g):
    return {"rgb": torch.tensor([RED]), "extent_cm": torch.tensor([[side_cm] * 3]), "fill": torch.tensor([1.0]),
            "mass_g": torch.tensor([float(mass_g)])}


def _heavier_than_the_floater_it_recalls(developed, ablate):
    """Red cubes remembered (no rules: every pathway at full strength): small and large ones on either side of the
    boundary (3 cm: 20 g floats, 60 g sinks; 8 cm: 300 g floats, 600 g sinks) and a 5 cm cube of 100 g that floats.
    A 5 cm cube of 170 g (136 cm^3 of mass in 125 cm^3: it sinks) recalls the 100 g one most strongly, whose fate
    the vote takes; the boundary through the other four puts it on the sinking side."""
    agent = developed[ablate].select([0])
    for side, mass, sank in ((3.0, 20, False), (3.0, 60, True), (8.0, 300, False), (8.0, 600, True),
                             (5.0, 100, False)):
        volume = min(mass, side ** 3)
        agent.remember(cube(side, mass), torch.tensor([float(volume)]), torch.tensor([False]), torch.tensor([False]),
                       sank=torch.tensor([sank]))
    a = agent.anticipate(cube(5.0, 170))
    assert a.p_sink[0] > 0.5, a.p_sink


def test_the_boundary_sinks_an_object_the_vote_floats_with_its_nearest_episode(developed):
    _heavier_than_the_floater_it_recalls(developed, ())
    with pytest.raises(AssertionError):
        _heavier_than_the_floater_it_recalls(developed, ("boundary",))


def test_the_boundary_ablation_is_named_in_the_runner_help():
    from train.run import parse_args
    with pytest.raises(SystemExit):
        import contextlib
        import io
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            parse_args(["--help"])
    assert "boundary" in out.getvalue()


def test_a_contextual_config_from_before_the_boundary_keeps_the_vote_it_learned_with():
    old = AgentConfig.contextual().to_dict()
    del old["fate_boundary_ridge"]
    assert AgentConfig.from_dict(old).ablate == ("boundary",)
    assert AgentConfig.from_dict(AgentConfig.contextual().to_dict()).ablate == ()
    # the paper model has no boundary to keep
    paper = AgentConfig.paper().to_dict()
    del paper["fate_boundary_ridge"]
    assert AgentConfig.from_dict(paper).ablate == ()


def drop(agent, m, cm3, sank):
    return agent.step(m, torch.tensor([cm3]), torch.tensor([False]), torch.tensor([False]), sank=torch.tensor([sank]))


@pytest.fixture(scope="module")
def lived_agents():
    """The contextual model with the boundary over every property live for the fate (`causes` ablated, so that the
    columns do not depend on what the rules found here), its fate's recall bringing back one episode: fitted over
    every episode lived, or (`lived` ablated) over the recalled one."""
    return {ab: Agent(AgentConfig.contextual(seed=0, ablate=ab, fate_recalls=1))
            for ab in (("causes",), ("causes", "lived"))}


def _lived_boundary_sinks_the_heavier_cube(agents, ablate):
    """The cubes of `_heavier_than_the_floater_it_recalls`, lived (dropped, not remembered): 3 cm 20 g floats, 60 g
    sinks, 8 cm 300 g floats, 600 g sinks, 5 cm 100 g floats. A 5 cm cube of 170 g sinks (136 cm^3 of mass in 125
    cm^3). Its one recalled episode is the 100 g floater, on the wrong side; the boundary over all five episodes
    lived puts it on the sinking side."""
    agent = agents[ablate].select([0])
    for side, mass, sank in ((3.0, 20, False), (3.0, 60, True), (8.0, 300, False), (8.0, 600, True),
                             (5.0, 100, False)):
        drop(agent, cube(side, mass), float(min(mass, side ** 3)), sank)
    assert int(agent.rules.lived_count[0]) == 5
    a = agent.anticipate(cube(5.0, 170))
    assert a.p_sink[0] > 0.5, a.p_sink


def test_the_fate_is_fitted_over_every_episode_lived(lived_agents):
    _lived_boundary_sinks_the_heavier_cube(lived_agents, ("causes",))
    with pytest.raises(AssertionError):          # over the one episode its recall brings back: it floats
        _lived_boundary_sinks_the_heavier_cube(lived_agents, ("causes", "lived"))


@pytest.mark.parametrize("ablate", [(), ("causes",)])
def test_the_boundary_is_fitted_over_the_properties_dominant_somewhere(ablate):
    """Strengths set by hand (color fill elongation size weight; contexts floating, sinking, fate): weight dominant
    among floaters, fill and size among sinkers, colour eliminated in both (irrelevant to the fate too), elongation
    undecided. The boundary's columns: fill, size and weight (elongation, live but dominant nowhere, is left out);
    with nothing dominant anywhere, every live property (all but colour); with `causes` ablated, always every live
    one."""
    agent = Agent(AgentConfig.contextual(seed=0, ablate=ablate), develop=False)
    layout = {"color": 3, "fill": 1, "elongation": 2, "size": 1, "weight": 1}
    values = {p: torch.zeros(1, d) for p, d in layout.items()}
    x, cols = property_columns(values, agent.properties)

    def columns_of():
        got = agent._fate_columns(x, cols)[0]
        return [p for p, c in zip(agent.properties, cols) if got[c].all()]
    s = torch.ones(1, 3, 5)
    s[0, :2, 0] = 0.05                                                # colour eliminated among floaters and sinkers
    agent.rules.strength.copy_(s)
    assert columns_of() == ["fill", "elongation", "size", "weight"]
    s[0, 0, 4] = s[0, 1, 1] = s[0, 1, 3] = 3.0                      # weight; fill and size
    agent.rules.strength.copy_(s)
    assert columns_of() == (["fill", "size", "weight"] if not ablate else ["fill", "elongation", "size", "weight"])


def test_with_the_rules_off_every_episode_lived_is_still_kept_and_nothing_derived():
    """`rules` ablated: the knowledge stays unknown (strengths 1), and the lived store the fate is fitted over still
    fills (the rules' ablation takes away what the rules learn, not the fate's examples)."""
    agent = Agent(AgentConfig.contextual(seed=0, ablate=("rules",)))
    drop(agent, cube(3.0, 20), 20.0, False)
    drop(agent, cube(3.0, 60), 27.0, True)
    assert int(agent.rules.lived_count[0]) == 2
    assert torch.equal(agent.rules.strength, torch.ones_like(agent.rules.strength))
