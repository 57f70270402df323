"""The contextual model's expected fate from a boundary fitted over the recalled episodes
(aesop_torch/fate_boundary.py), and the recall-weighted vote it replaces kept as the `boundary` ablation."""

import pytest
import torch

from aesop_torch import Agent, AgentConfig
from aesop_torch.fate_boundary import expected_fate

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
