"""Object hub with hand-made map activities (one-hot winners): storage, bottom-up, top-down, cross-modal, strength
gating, batch independence; the 2-hot action, body and reward codes."""

import math

import pytest
import torch

from aesop_torch.hub import ActionHub, BodyHub, Fate, HubConfig, ObjectHub, RewardCode

MAPS = {"color": 4, "shape": 3, "size": 3, "weight": 5, "word": 6}
C, SH, SI, W, WD = range(5)
U = 6
PROPS = torch.tensor([True, True, True, True, False])   # the four properties, no word
ALL = torch.ones(5, dtype=torch.bool)


def one_hot(winners, present):
    """(B, P) winners -> (B, P, U) one-hot map activities, zero for absent maps."""
    a = torch.zeros(winners.shape[0], len(MAPS), U)
    a.scatter_(2, winners[:, :, None], 1.0)
    return a * present[:, :, None]


def store(hub, winners, present, seed=0, mask=None):
    B = hub.W.shape[0]
    winners = torch.as_tensor(winners).reshape(B, -1)
    present = torch.as_tensor(present).expand(B, len(MAPS))
    mask = torch.ones(B, dtype=torch.bool) if mask is None else mask
    return hub.allocate(winners, present, mask, torch.Generator().manual_seed(seed))


def cue(winners, present=PROPS):
    winners = torch.as_tensor(winners).reshape(1, -1)
    present = present.reshape(1, -1)
    return one_hot(winners, present), present


RED_CYL = [1, 0, 2, 3, 0]


def test_stored_object_gives_one_on_its_assembly_and_nothing_else():
    hub = ObjectHub(MAPS)
    assembly = store(hub, RED_CYL, PROPS)
    assert assembly.shape == (1, 50) and assembly.sum() == 5
    u = hub.bottom_up(*cue(RED_CYL))
    assert torch.equal(u, assembly.float())           # exactly 1.0 on the assembly, 0 elsewhere
    assert hub.usage.sum() == 5 and hub.n_assemblies.item() == 1
    best, found = hub.match(*cue(RED_CYL))
    assert best.item() == 1.0 and torch.equal(found, assembly)


def test_top_down_reconstructs_exactly_the_stored_units():
    hub = ObjectHub(MAPS)
    assembly = store(hub, RED_CYL, PROPS)
    r = hub.top_down(assembly)
    acts, _ = cue(RED_CYL)
    assert torch.equal(r, acts)                        # 1.0 on each stored unit, nothing elsewhere, no word
    assert torch.equal(hub.W_back, hub.W.transpose(-1, -2))


def test_one_property_changed_gives_three_quarters():
    hub = ObjectHub(MAPS)
    assembly = store(hub, RED_CYL, PROPS)
    blue = list(RED_CYL)
    blue[C] = 2
    u = hub.bottom_up(*cue(blue))
    assert u[assembly].tolist() == pytest.approx([0.75] * 5)
    light = list(RED_CYL)
    light[W] = 0
    assert hub.match(*cue(light))[0].item() == pytest.approx(0.75)


def test_zero_colour_strength_hides_colour_both_ways():
    hub = ObjectHub(MAPS)
    assembly = store(hub, RED_CYL, PROPS)
    hub.strength[:, C] = 0.0
    blue = list(RED_CYL)
    blue[C] = 2
    assert hub.bottom_up(*cue(blue))[assembly].tolist() == [1.0] * 5   # a colour change is invisible
    r = hub.top_down(assembly)
    assert r[0, C].abs().sum() == 0                                    # and colour is not retro-activated
    acts, _ = cue(RED_CYL)
    assert torch.equal(r[0, SH:W + 1], acts[0, SH:W + 1])              # the rest still is


def test_strength_weights_the_properties():
    hub = ObjectHub(MAPS)
    assembly = store(hub, RED_CYL, PROPS)
    hub.strength[0, :4] = torch.tensor([0.05, 1.0, 1.0, 3.0])
    light = list(RED_CYL)
    light[W] = 0
    assert hub.bottom_up(*cue(light))[assembly][0].item() == pytest.approx(2.05 / 5.05)
    assert hub.top_down(assembly)[0, W, RED_CYL[W]].item() == pytest.approx(3.0)


def test_graded_activity_is_read_relative_to_its_peak():
    hub = ObjectHub(MAPS)
    assembly = store(hub, RED_CYL, PROPS)
    acts, present = cue(RED_CYL)
    remeasured = acts * 0.7                         # every winner matched a little less well
    remeasured[0, C, 2] = 0.35                      # and a neighbouring colour unit half as much as the winner
    assert hub.bottom_up(remeasured, present)[assembly].tolist() == pytest.approx([1.0] * 5)
    raw = ObjectHub(MAPS, HubConfig(relative_activity=False))
    assembly = store(raw, RED_CYL, PROPS)
    assert raw.bottom_up(remeasured, present)[assembly].tolist() == pytest.approx([0.7] * 5)


def test_word_retro_activates_colour_and_shape():
    hub = ObjectHub(MAPS)
    store(hub, RED_CYL, ALL)                                  # stored with its name: word unit 0
    blue_cyl = [2, 0, 2, 3, 4]
    store(hub, blue_cyl, ALL, seed=1)                         # "blue cylinder": word unit 4
    word = torch.zeros(1, MAPS["word"])
    word[0, 4] = 1.0
    r = hub.cross_modal(word)
    assert r[0, C].tolist() == [0, 0, 1, 0, 0, 0]             # the blue unit of the colour map
    assert r[0, SH].tolist() == [1, 0, 0, 0, 0, 0]            # the cylinder unit of the shape map
    assert r[0, WD, 4] == 1 and r[0, WD, 0] == 0              # and its own name, not the other


def test_least_used_neurons_give_disjoint_assemblies_then_reuse():
    hub = ObjectHub(MAPS)
    seen = torch.zeros(1, 50, dtype=torch.bool)
    for i in range(10):                                       # 10 x 5 = 50: every neuron exactly once
        a = store(hub, [i % 4, i % 3, 0, i % 5, 0], PROPS, seed=i)
        assert not (a & seen).any()
        seen |= a
    assert seen.all() and (hub.usage == 1).all()
    store(hub, [0, 0, 0, 0, 0], PROPS, seed=10)
    assert hub.usage.sum() == 55 and hub.usage.max() == 2


def test_codes_stay_apart_as_objects_multiply():
    # 60 objects of 5 of 50 neurons: 600 neuron pairs in all, of the 1,225 there are, so every two assemblies can
    # share at most one neuron, and allocation finds such codes (least-used alone gave the 11th object the 1st's)
    hub = ObjectHub(MAPS, HubConfig(max_assemblies=60))
    for i in range(60):
        store(hub, [i % 4, i % 3, i % 2, i % 5, 0], PROPS, seed=i)
    a = hub.assemblies[0].float()
    shared = a @ a.T
    assert torch.equal(shared.diagonal(), torch.full((60,), 5.0))
    assert shared.fill_diagonal_(0).max() == 1
    assert hub.usage.sum() == 300 and hub.usage.max() - hub.usage.min() <= 2


def test_tie_breaks_come_from_the_generator():
    a = store(ObjectHub(MAPS), RED_CYL, PROPS, seed=3)
    b = store(ObjectHub(MAPS), RED_CYL, PROPS, seed=3)
    c = store(ObjectHub(MAPS), RED_CYL, PROPS, seed=4)
    assert torch.equal(a, b) and not torch.equal(a, c)


def test_code_is_k_winners_take_all():
    hub = ObjectHub(MAPS)
    state = torch.zeros(1, 50)
    state[0, [3, 9, 17, 20, 41, 44]] = torch.tensor([0.9, 0.8, 0.95, 0.7, 0.75, 0.1])
    assert hub.code(state)[0].nonzero().flatten().tolist() == [3, 9, 17, 20, 41]
    sparse = torch.zeros(1, 50)
    sparse[0, [5, 6]] = 1.0
    assert hub.code(sparse)[0].nonzero().flatten().tolist() == [5, 6]   # silent neurons never win


def test_batch_of_three_agents_is_independent():
    hub = ObjectHub(MAPS, batch=3)
    winners = torch.tensor([RED_CYL, [0, 1, 1, 1, 0], [3, 2, 0, 4, 0]])
    present = PROPS.expand(3, 5)
    mask = torch.tensor([True, False, True])
    assembly = hub.allocate(winners, present, mask, torch.Generator().manual_seed(0))
    assert assembly.sum(-1).tolist() == [5, 0, 5]
    assert hub.W[1].sum() == 0 and hub.n_assemblies.tolist() == [1, 0, 1]
    u = hub.bottom_up(one_hot(winners, present), present)
    assert torch.equal(u[0], assembly[0].float()) and torch.equal(u[2], assembly[2].float())
    assert u[1].sum() == 0
    # agent 0's object shown to agent 2 activates nothing of agent 2's (all four properties differ)
    shown = one_hot(winners[[0, 0, 0]], present)
    assert hub.bottom_up(shown, present)[2].sum() == 0
    # editing agent 2's strength changes nothing for agent 0
    before = hub.top_down(assembly.float())
    hub.strength[2, :] = 0.5
    after = hub.top_down(assembly.float())
    assert torch.equal(before[0], after[0]) and torch.equal(after[2], 0.5 * before[2])


def test_state_dict_round_trip_and_bad_input():
    hub = ObjectHub(MAPS, batch=2)
    store(hub, [RED_CYL, [0, 1, 1, 1, 0]], PROPS)
    other = ObjectHub(MAPS, batch=2)
    other.load_state_dict(hub.state_dict())
    acts, present = one_hot(torch.tensor([RED_CYL, RED_CYL]), PROPS.expand(2, 5)), PROPS.expand(2, 5)
    assert torch.equal(other.bottom_up(acts, present), hub.bottom_up(acts, present))
    with pytest.raises(ValueError, match="acts must be"):
        hub.bottom_up(acts[:, :4], present)
    with pytest.raises(ValueError, match="winners out of range"):
        store(hub, [[0, 0, 0, 9, 0], RED_CYL], PROPS)              # the weight map has 5 units
    with pytest.raises(ValueError, match="hub_state"):
        hub.top_down(torch.zeros(2, 49))
    with pytest.raises(ValueError, match="maps"):
        ObjectHub({})


def test_hub_full_raises():
    hub = ObjectHub(MAPS, HubConfig(max_assemblies=2))
    store(hub, RED_CYL, PROPS)
    store(hub, RED_CYL, PROPS)
    with pytest.raises(ValueError, match="full"):
        store(hub, RED_CYL, PROPS)


def test_reward_code_round_trip():
    code = RewardCode()
    step = math.log(2000.0 / 0.5) / 624                 # 625 levels from 0.5 to 2000 cm^3, a log scale
    assert code.step == pytest.approx(step)
    row = code.encode(torch.tensor(365.0))
    assert row.sum() == 2
    level = round(math.log(365.0 / 0.5) / step)        # 496: coarse unit 19 (496 // 25), fine unit 25 + 21
    assert row.nonzero().flatten().tolist() == [level // 25, 25 + level % 25]
    assert code.decode(row).item() == pytest.approx(0.5 * math.exp(level * step), rel=1e-6)
    vals = torch.tensor([[2.0, 24.0, 364.0], [1248.0, 5000.0, -3.0]])
    back = code.decode(code.encode(vals))
    assert torch.allclose(back[0], vals[0], rtol=step / 2 + 1e-6)   # within half a step: 0.67 %
    assert back[1].tolist() == pytest.approx([1248.0, 2000.0, 0.5], rel=step / 2)   # clamped to 0.5..2000


def test_reward_decode_flags_invalid_rows():
    code = RewardCode()
    rows = torch.zeros(4, 50)
    rows[1, [3, 30]] = 1.0
    rows[1, 31] = 0.4                              # below 0.5: inactive, still a valid code
    rows[2, [3, 4, 30]] = 1.0                      # two coarse units
    rows[3, [30, 31]] = 1.0                        # no coarse unit
    out = code.decode(rows)
    assert math.isnan(out[0]) and math.isnan(out[2]) and math.isnan(out[3])
    assert out[1].item() == pytest.approx(0.5 * math.exp((3 * 25 + 5) * code.step), rel=1e-6)
    with pytest.raises(ValueError, match="finite"):
        code.encode(torch.tensor([float("nan")]))


def test_graded_storage_keeps_the_bump_and_matches_it_again():
    hub = ObjectHub({"a": 5, "b": 5}, HubConfig(assembly_size=5), batch=1)
    bump = torch.tensor([[[0.02, 0.3, 1.0, 0.3, 0.02], [0.0, 0.0, 0.5, 1.0, 0.5]]])
    assembly = hub.allocate(bump, torch.ones(1, 2, dtype=torch.bool), torch.ones(1, dtype=torch.bool))
    k = int(assembly[0].nonzero()[0])
    # the bump relative to its peak, units below store_floor (0.05) left out
    assert hub.W[0, 0, :, k].tolist() == pytest.approx([0.0, 0.3, 1.0, 0.3, 0.0])
    assert hub.W[0, 1, :, k].tolist() == pytest.approx([0.0, 0.0, 0.5, 1.0, 0.5])
    present = torch.ones(1, 2, dtype=torch.bool)
    assert hub.bottom_up(bump, present)[0, assembly[0]].tolist() == pytest.approx([1.0] * 5)
    # map a's bump moved one unit (its 0.02 below the floor): its match is (W . a') / max(a' . a', W . W)
    # = (0.3 + 0.3) / 1.18, map b still 1
    moved = bump.clone()
    moved[0, 0] = torch.tensor([0.0, 0.02, 0.3, 1.0, 0.3])
    expect = (0.5 * (1.0 * 0.3 + 0.3 * 1.0) / 1.18 + 0.5 * 1.0)
    assert hub.bottom_up(moved, present)[0, k].item() == pytest.approx(expect, rel=1e-5)


def test_an_input_that_covers_a_stored_bump_is_not_that_object():
    """A wider bump holds the stored one under it: W . a > W . W. Divided by the larger energy it scores
    (W . a) / (a . a) = (0.24 + 1 + 0.24) / 2.78, not 1, and the two objects match each other alike."""
    narrow = torch.tensor([[[0.0, 0.3, 1.0, 0.3, 0.0]]])
    wide = torch.tensor([[[0.5, 0.8, 1.0, 0.8, 0.5]]])
    present, mask = torch.ones(1, 1, dtype=torch.bool), torch.ones(1, dtype=torch.bool)
    scores = []
    for stored, shown in ((narrow, wide), (wide, narrow)):
        hub = ObjectHub({"a": 5}, HubConfig(assembly_size=5), batch=1)
        hub.allocate(stored, present, mask)
        assert hub.object_match(stored, present)[0, 0].item() == pytest.approx(1.0)
        scores.append(hub.object_match(shown, present)[0, 0].item())
    assert scores == pytest.approx([1.48 / 2.78] * 2, rel=1e-5)


@pytest.mark.parametrize("hub", [ActionHub(), BodyHub(), Fate()])
def test_named_two_hot_codes_round_trip(hub):
    codes = hub.encode(list(hub.names))
    assert codes.shape == (len(hub.names), 50) and (codes.sum(-1) == 2).all()
    assert (codes.float() @ codes.float().T == 2 * torch.eye(len(hub.names))).all()   # disjoint
    assert hub.decode(codes) == list(hub.names)
    assert hub.decode(hub.encode(hub.names[-1])) == hub.names[-1]
    assert hub.decode(torch.zeros(50)) is None
    assert hub.decode(codes[0] | codes[1]) is None
    with pytest.raises(ValueError, match="unknown"):
        hub.encode("fly")


def test_action_and_body_names():
    assert ActionHub().decode(ActionHub().encode(["reach", "grasp", "drop"])) == ["reach", "grasp", "drop"]
    assert BodyHub().decode(BodyHub().encode(["goal_unreachable", "goal_reached"])) == ["goal_unreachable",
                                                                                         "goal_reached"]
