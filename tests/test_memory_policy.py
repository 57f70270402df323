"""A memory and a hub that can fill (MemoryConfig.when_full, HubConfig.when_full): refuse, forget the oldest, forget
the weakest. Hand-made episodes and objects whose survivors are known by hand; the network after forgetting is the
network of a memory that only ever stored the survivors; agents in a batch stay independent; and whole agents
through lives longer than their memory."""

import math

import pytest
import torch

from aesop_torch import Agent, AgentConfig
from aesop_torch.hub import HubConfig, ObjectHub
from aesop_torch.memory import WHEN_FULL, EpisodicMemory, MemoryConfig

R, C, OBJ = 20, 50, 1
FORGET = ("forget_oldest", "forget_weakest")


def episode(obj, reward, end):
    """An agent-like sheet: 8 neurons every episode shares (rows 0, 2, 3, 4), its object (5 neurons on row 1), its
    reward (row 5) and its end state (row 6)."""
    x = torch.zeros(R, C, dtype=torch.bool)
    for r, idx in [(0, (0, 1)), (OBJ, obj), (2, (2, 3)), (3, (4, 5)), (4, (6, 7)), (5, reward), (6, end)]:
        x[r, list(idx)] = True
    return x


# Shared active neurons of each pair (the 8 common to all, and 1 per object, reward or end neuron in common):
#   E1-E2 8, E1-E3 8, E1-E4 10 (end), E1-E5 10 (end), E2-E3 12 (reward, end), E2-E4 8, E2-E5 8, E3-E4 8, E3-E5 8,
#   E4-E5 16 (4 object neurons, reward, end)
E1 = episode(range(0, 5), (3, 30), (8, 9))
E2 = episode(range(5, 10), (7, 40), (10, 11))
E3 = episode(range(10, 15), (7, 40), (10, 11))
E4 = episode(range(15, 20), (0, 25), (8, 9))
E5 = episode((15, 16, 17, 18, 20), (0, 25), (8, 9))
EPISODES = (E1, E2, E3, E4, E5)
# forget_weakest, by hand (the stored episode sharing the most with another, stored or incoming; the older of a tie):
#   E4 comes into {E1, E2, E3}: E1's most 10 (E4), E2's 12 (E3), E3's 12 (E2): E2 and E3 tie, E2 is older: E2 leaves
#   E5 comes into {E1, E3, E4}: E1's most 10 (E4, E5), E3's 8, E4's 16 (E5): E4 leaves
SURVIVORS = {"forget_oldest": (E3, E4, E5), "forget_weakest": (E1, E3, E5)}
FORGOTTEN = {"forget_oldest": (E1, E2), "forget_weakest": (E2, E4)}


def memory(*episodes, batch=1, **cfg):
    mem = EpisodicMemory(MemoryConfig(**cfg), batch=batch)
    for e in episodes:
        mem.store(e.expand(batch, R, C))
    return mem


def cue(e):
    return e[OBJ].float()[None]


def test_policies_are_checked():
    assert WHEN_FULL == ("refuse", "forget_oldest", "forget_weakest")
    assert MemoryConfig().when_full == HubConfig().when_full == "refuse"   # the library's default
    with pytest.raises(ValueError, match="when_full"):
        MemoryConfig(when_full="forget_newest")
    with pytest.raises(ValueError, match="when_full"):
        HubConfig(when_full="lru")


def test_refuse_raises_one_line_naming_the_limit_and_stores_nothing():
    mem = memory(E1, E2, E3, max_episodes=3)
    before = {k: v.clone() for k, v in mem.state_dict().items()}
    for e in (E4, E5):
        with pytest.raises(RuntimeError) as err:
            mem.store(e[None])
        msg = str(err.value)
        assert "\n" not in msg and "max_episodes=3" in msg and "MemoryConfig.when_full" in msg
        assert all(torch.equal(before[k], v) for k, v in mem.state_dict().items())
    assert mem.count.tolist() == [3]


@pytest.mark.parametrize("policy", FORGET)
def test_forgetting_keeps_the_survivors_by_hand_and_each_recalls_exactly(policy):
    mem = memory(*EPISODES, max_episodes=3, when_full=policy)
    survivors = SURVIVORS[policy]
    assert mem.count.tolist() == [3]
    assert all(torch.equal(mem.patterns[0, i], e) for i, e in enumerate(survivors))   # in the order stored
    for e in survivors:
        got = mem.recall(cue(e))
        assert got.valid[0, 0] and torch.equal(got.episodes[0, 0], e) and got.strength[0, 0] == 1.0
    for e in FORGOTTEN[policy]:   # a forgotten episode's cue never brings it back
        got = mem.recall(cue(e))
        assert not any(torch.equal(x, e) for x in got.episodes[0][got.valid[0]])
    if policy == "forget_oldest":   # E1's object is no stored episode's: its cue recalls nothing at all
        assert not mem.recall(cue(E1)).any.item()


@pytest.mark.parametrize("policy", FORGET)
def test_the_network_after_forgetting_is_the_survivors_network(policy):
    mem = memory(*EPISODES, max_episodes=3, when_full=policy)
    only = memory(*SURVIVORS[policy], max_episodes=3)
    assert torch.equal(mem.weights(0), only.weights(0)) and torch.equal(mem.mean_activity(0), only.mean_activity(0))
    assert all(torch.equal(v, only.state_dict()[k]) for k, v in mem.state_dict().items())   # bit for bit
    q = torch.stack([e[OBJ].float() for e in EPISODES]) * torch.tensor([[1.0], [0.7], [0.9], [0.6], [0.8]])
    shared, alone = EpisodicMemory(mem.config), EpisodicMemory(only.config)
    shared.load_state_dict(mem.state_dict())
    alone.load_state_dict(only.state_dict())
    assert all(torch.equal(x, y) for x, y in zip(shared.recall(q), alone.recall(q)))


def test_a_memory_that_never_filled_recalls_as_before():
    q = torch.stack([E1[OBJ].float(), 0.5 * E4[OBJ].float() + 0.3 * E3[OBJ].float()])
    ref = memory(E1, E3, E4, max_episodes=5)
    for policy in FORGET:
        mem = memory(E1, E3, E4, max_episodes=5, when_full=policy)
        for i in range(2):
            assert all(torch.equal(x, y) for x, y in zip(mem.recall(q[i:i + 1]), ref.recall(q[i:i + 1])))


def test_forget_weakest_takes_the_incoming_episode_into_account():
    # E5 is E4's near-twin: stored into {E1, E3, E4} it pushes E4 out; without it E4 would be no more redundant
    # than E1 (both share 10 with each other), and the older, E1, would leave
    mem = memory(E1, E3, E4, max_episodes=3, when_full="forget_weakest")
    left = mem.make_room(torch.tensor([True]))
    assert torch.equal(left[0], E1) and mem.count.tolist() == [2]
    mem = memory(E1, E3, E4, max_episodes=3, when_full="forget_weakest")
    left = mem.make_room(torch.tensor([True]), E5[None])
    assert torch.equal(left[0], E4)
    assert torch.equal(mem.patterns[0, :2], torch.stack([E1, E3])) and not mem.patterns[0, 2].any()


def test_forget_any_slots_keeps_the_order_and_ignores_empty_slots():
    mem = memory(E1, E2, E3, E4, max_episodes=6)
    mem.forget(torch.tensor([[True, False, True, False, False, True]]))   # slot 5 holds nothing: ignored
    assert mem.count.tolist() == [2] and torch.equal(mem.patterns[0, :2], torch.stack([E2, E4]))
    assert not mem.patterns[0, 2:].any()
    with pytest.raises(ValueError, match="drop shape"):
        mem.forget(torch.zeros(1, 5, dtype=torch.bool))


@pytest.mark.parametrize("policy", FORGET)
def test_batched_agents_forget_independently(policy):
    # agent 0 is fed E1..E5, agent 1 E5, E4, E3 and then nothing: agent 1 fills but never overflows, agent 0 forgets
    mem = EpisodicMemory(MemoryConfig(max_episodes=3, when_full=policy), batch=2)
    feeds = [EPISODES, (E5, E4, E3)]
    for t in range(5):
        mask = torch.tensor([True, t < 3])
        mem.store(torch.stack([feeds[0][t], feeds[1][min(t, 2)]]), mask)
    for b in range(2):
        alone = memory(*feeds[b], max_episodes=3, when_full=policy)
        assert torch.equal(mem.patterns[b], alone.patterns[0]) and mem.count[b] == alone.count[0]
    # both full, both forgetting at once, each as it would alone
    mem.store(torch.stack([E2, E1]))
    for b, e in enumerate((E2, E1)):
        alone = memory(*feeds[b], e, max_episodes=3, when_full=policy)
        assert torch.equal(mem.patterns[b], alone.patterns[0])


@pytest.mark.parametrize("policy", FORGET)
def test_state_dict_round_trips_and_forgets_on_the_same(policy):
    mem = memory(E1, E2, E3, E4, max_episodes=3, when_full=policy)
    assert set(mem.state_dict()) == {"patterns", "count"}   # no state beyond the patterns
    copy = EpisodicMemory(MemoryConfig(max_episodes=3, when_full=policy))
    copy.load_state_dict(mem.state_dict())
    for m in (mem, copy):
        m.store(E5[None])
    assert all(torch.equal(v, copy.state_dict()[k]) for k, v in mem.state_dict().items())
    assert all(torch.equal(mem.patterns[0, i], e) for i, e in enumerate(SURVIVORS[policy]))


# -- the object hub -------------------------------------------------------------------------------------------------
MAPS = {"color": 4, "shape": 3, "size": 3, "weight": 5, "word": 6}
PROPS = torch.tensor([True, True, True, True, False])
# the first three differ in every property, the fourth from each of them in three (the shape map has 3 units)
OBJECTS = ([1, 0, 2, 3, 0], [0, 1, 1, 1, 0], [3, 2, 0, 4, 0], [2, 2, 2, 2, 0])


def hub_of(*objects, batch=1, **cfg):
    hub = ObjectHub(MAPS, HubConfig(**cfg), batch=batch)
    for o in objects:
        hub.allocate(torch.tensor([o] * batch), PROPS.expand(batch, 5), torch.ones(batch, dtype=torch.bool))
    return hub


def one_hot(o):
    a = torch.zeros(1, len(MAPS), 6)
    a[0, torch.arange(len(MAPS)), torch.tensor(o)] = 1.0
    return a * PROPS[None, :, None], PROPS[None]


def test_full_hub_refuses_one_line_and_stores_nothing():
    hub = hub_of(*OBJECTS[:2], max_assemblies=2)
    before = {k: v.clone() for k, v in hub.state_dict().items()}
    with pytest.raises(ValueError) as err:
        hub.allocate(torch.tensor([OBJECTS[2]]), PROPS[None], torch.tensor([True]))
    msg = str(err.value)
    assert "\n" not in msg and "max_assemblies=2" in msg and "HubConfig.when_full" in msg
    assert all(torch.equal(before[k], v) for k, v in hub.state_dict().items())


def test_forget_moves_the_survivors_down_and_gives_back_their_neurons():
    hub = hub_of(*OBJECTS[:3], max_assemblies=4)
    before = {k: v.clone() for k, v in hub.state_dict().items()}
    hub.forget(torch.tensor([[True, False, False, True]]))    # slot 3 is empty: ignored
    assert hub.n_assemblies.tolist() == [2]
    for key in ("assemblies", "branches", "branch_norm", "graded"):
        assert torch.equal(getattr(hub, key)[0, :2], before[key][0, 1:3]) and not getattr(hub, key)[0, 2:].any()
    assert torch.equal(hub.usage, before["usage"] - before["assemblies"][:, 0].long())
    assert torch.equal(hub.usage, hub.assemblies.long().sum(1))
    assert torch.equal(hub.strength, before["strength"])
    # the forgotten object is no longer known; the others still are, on their own assemblies
    assert hub.match(*one_hot(OBJECTS[0]))[0].item() == 0.0
    for i in (1, 2):
        best, assembly = hub.match(*one_hot(OBJECTS[i]))
        assert best.item() == 1.0 and torch.equal(assembly[0], before["assemblies"][0, i])


@pytest.mark.parametrize("policy", FORGET)
def test_full_hub_of_unlike_objects_frees_the_oldest_without_reference_counts(policy):
    # the first three share nothing (similarity 0 each): forget_weakest's tie goes to the oldest too
    hub = hub_of(*OBJECTS, max_assemblies=3, when_full=policy)
    assert hub.n_assemblies.tolist() == [3]
    assert hub.match(*one_hot(OBJECTS[0]))[0].item() == 0.25     # the shape it shares with the fourth: not known
    assert all(hub.match(*one_hot(o))[0].item() == 1.0 for o in OBJECTS[1:])
    assert torch.equal(hub.usage, hub.assemblies.long().sum(1))


P, Y, Q, Z = [1, 0, 2, 3, 0], [0, 1, 1, 1, 0], [2, 0, 2, 3, 0], [0, 1, 1, 4, 0]   # P, Q: colour; Y, Z: weight


def test_similarity_is_the_match_of_two_stored_objects_through_the_strengths():
    hub = hub_of(P, Y, Q, Z, max_assemblies=4)
    by_hand = torch.tensor([[1, 0, 3 / 4, 0], [0, 1, 0, 3 / 4], [3 / 4, 0, 1, 0], [0, 3 / 4, 0, 1]])
    assert torch.allclose(hub.similarity()[0], by_hand)
    hub.strength[0, 0] = 0.0      # colour tells nothing: P and Q are one object to this agent, Y and Z 2 of 3 alike
    assert hub.similarity()[0, 0, 2].item() == 1.0 and hub.similarity()[0, 1, 3].item() == pytest.approx(2 / 3)


@pytest.mark.parametrize("policy, unheard, freed", [
    # P-Q and Y-Z are alike (3/4 each), unlike each other (0): the older of the most alike pair goes, P on a tie
    ("forget_weakest", None, 0), ("forget_weakest", 0, 0), ("forget_weakest", 3, 1),
    ("forget_oldest", 3, 0)])      # a pathway at 0 strength (colour 0, weight 3): that property tells no one apart
def test_forget_weakest_frees_the_object_most_like_another(policy, unheard, freed):
    hub = hub_of(P, Y, Q, Z, max_assemblies=4, when_full=policy)
    if unheard is not None:
        hub.strength[0, unheard] = 0.0
    before = hub.assemblies.clone()
    got = hub.make_room(torch.tensor([True]))
    assert torch.equal(got[0], before[0, freed]) and hub.n_assemblies.tolist() == [3]
    assert torch.equal(hub.assemblies[0], torch.cat([before[0, [s for s in range(4) if s != freed]],
                                                     torch.zeros_like(before[0, :1])]))


@pytest.mark.parametrize("policy, uses, freed", [
    # uses of slots 0, 1, 2 (held codes equal to each assembly): an unused one goes first under either policy
    ("forget_oldest", (2, 0, 1), 1), ("forget_weakest", (2, 0, 1), 1),
    ("forget_oldest", (2, 1, 0), 2), ("forget_weakest", (2, 1, 0), 2),
    # all used: the oldest, or the least used (the three share nothing: the older of a tie)
    ("forget_oldest", (2, 1, 1), 0), ("forget_weakest", (2, 1, 1), 1), ("forget_weakest", (1, 3, 1), 0),
])
def test_make_room_frees_an_unused_assembly_first_then_by_policy(policy, uses, freed):
    hub = hub_of(*OBJECTS[:3], max_assemblies=3, when_full=policy)
    before = hub.assemblies.clone()
    held = torch.zeros(1, 8, hub.n_neurons, dtype=torch.bool)    # the owner's references, empty slots all False
    at = 0
    for slot, n in enumerate(uses):
        held[0, at:at + n] = before[0, slot]
        at += n
    got = hub.make_room(torch.tensor([True]), held)
    assert torch.equal(got[0], before[0, freed]) and hub.n_assemblies.tolist() == [2]
    assert torch.equal(hub.assemblies[0, :2], before[0, [s for s in range(3) if s != freed]])


def test_a_hub_with_room_or_out_of_the_mask_is_untouched():
    hub = hub_of(*OBJECTS[:2], batch=2, max_assemblies=2, when_full="forget_oldest")
    hub.allocate(torch.tensor([OBJECTS[2], OBJECTS[2]]), PROPS.expand(2, 5), torch.tensor([True, False]))
    alone = hub_of(*OBJECTS[:3], max_assemblies=2, when_full="forget_oldest")
    for k, v in hub.state_dict().items():
        assert torch.equal(v[0], alone.state_dict()[k][0])
        assert torch.equal(v[1], hub_of(*OBJECTS[:2], max_assemblies=2).state_dict()[k][0])
    assert set(hub.state_dict()) == set(ObjectHub(MAPS).state_dict())
    assert not hub.make_room(torch.tensor([False, False])).any()


# -- through the agent ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def maps():
    return Agent(AgentConfig(seed=0)).maps       # the property maps, developed once (they never change after)


def agent_with(maps, episodes, assemblies, policy, model="paper", batch=1):
    cfg = AgentConfig.named(model, seed=0)
    cfg.memory.max_episodes, cfg.hub.max_assemblies = episodes, assemblies
    cfg.memory.when_full = cfg.hub.when_full = policy
    agent = Agent(cfg, batch=batch, develop=False)
    agent.maps = maps
    return agent


def cylinder(rgb, d, h, mass):
    """An upright cylinder as the robot measures it, what it displaces (Archimedes, fully covered), and whether it
    sinks."""
    volume = math.pi * d * d / 4 * h
    m = {"rgb": torch.tensor([rgb]), "extent_cm": torch.tensor([sorted([d, d, h], reverse=True)]),
         "fill": torch.tensor([math.pi / 4]), "mass_g": torch.tensor([float(mass)])}
    return m, min(mass, volume), mass > volume


EIGHT = [   # colour, diameter, height, mass: cylinders, every two of a different colour, size and mass
    ((0.85, 0.1, 0.1), 5.0, 8.0, 400.0), ((0.1, 0.2, 0.85), 3.0, 4.8, 15.0), ((0.1, 0.8, 0.1), 7.0, 11.2, 900.0),
    ((0.9, 0.85, 0.1), 4.0, 6.4, 30.0), ((0.6, 0.1, 0.7), 6.0, 9.6, 150.0), ((0.1, 0.8, 0.8), 3.5, 5.6, 250.0),
    ((0.95, 0.5, 0.1), 8.0, 12.8, 300.0), ((0.5, 0.5, 0.5), 4.5, 7.2, 600.0)]


def step(agent, obj, learn=None, observed=None, words=None):
    """Every agent of the batch lifts and drops the object (those in learn take part) and sees it displace its
    Archimedes volume (or `observed`); words: the teacher names it. The object is perceived once and shown to all
    (the last bits of a perception depend on its batch)."""
    m, v, sinks = cylinder(*obj)
    v = v if observed is None else observed
    B = agent.batch
    m = {k: t.expand(B, *t.shape[1:]) for k, t in m.items()}
    if words is not None:
        m["words"] = [words] * B
    acts, present = agent.activities({k: t[:1] for k, t in m.items()})
    return agent.step(m, torch.full((B,), v),
                      torch.zeros(B, dtype=torch.bool), torch.zeros(B, dtype=torch.bool), learn=learn,
                      sank=torch.full((B,), sinks), perceived=(acts.expand(B, -1, -1), present.expand(B, -1)))


def stored_rewards(agent, b=0):
    n = int(agent.memory.count[b])
    return agent.reward.decode(agent._reward_row(agent.memory.patterns[b, :n])).tolist()


def codes_in_hub(agent, b=0):
    """Each stored episode's object code is one of the hub's assemblies (no episode was left on a freed one)."""
    held = agent._assemblies(agent.memory.patterns[b, :int(agent.memory.count[b])])
    asm = agent.hub.assemblies[b, :int(agent.hub.n_assemblies[b])]
    return bool((held[:, None] == asm[None]).all(-1).any(1).all())


def test_an_agent_refuses_the_fifth_object_in_one_line(maps):
    agent = agent_with(maps, 4, 4, "refuse")
    for obj in EIGHT[:4]:
        assert step(agent, obj).encoded.item()
    with pytest.raises(ValueError) as err:
        step(agent, EIGHT[4])
    assert "\n" not in str(err.value) and "max_assemblies=4" in str(err.value)
    assert agent.memory.count.tolist() == [4] and agent.hub.n_assemblies.tolist() == [4]   # nothing stored


@pytest.mark.parametrize("policy", FORGET)
@pytest.mark.parametrize("model", ["paper", "extended"])
def test_an_agent_lives_through_eight_objects_in_a_memory_of_four(maps, policy, model):
    agent = agent_with(maps, 4, 4, policy, model)
    for obj in EIGHT:
        assert step(agent, obj).encoded.item()
        assert codes_in_hub(agent)
    assert agent.memory.count.tolist() == [4] and agent.hub.n_assemblies.tolist() == [4]
    # every object got an assembly of its own and one episode, and its episode leaves with its assembly. The hub
    # frees the oldest: objects 5-8 are left. Or, all used once, the one most like another: four of the eight,
    # in the order they came, the last one among them
    v = [agent.reward.stored(torch.tensor([cylinder(*o)[1]])).item() for o in EIGHT]
    left = [v.index(r) for r in stored_rewards(agent)]
    assert left == [4, 5, 6, 7] if policy == "forget_oldest" else (left == sorted(set(left)) and left[-1] == 7)
    for o in (EIGHT[i] for i in left):   # each still recalled first and exact from its own cue, with its own reward
        got = agent.anticipate(cylinder(*o)[0])
        assert got.recall.strength[0, 0].item() > 0.99
        assert got.rewards[0, 0].item() == agent.reward.stored(torch.tensor([cylinder(*o)[1]])).item()


@pytest.mark.parametrize("policy", FORGET)
def test_a_full_hub_frees_the_oldest_or_the_least_used_object_and_its_episodes_leave_with_it(maps, policy):
    # object 0 twice (the second time it displaces far less: a contradiction, stored again on its own assembly),
    # then objects 1, 2, 3: the hub of 4 is full, object 0 has 2 episodes, the others 1. Object 4: forget_oldest
    # frees object 0 and both its episodes leave; forget_weakest frees one of objects 1-3 (the least used; of them
    # the one most like another), and object 0's two episodes stay
    agent = agent_with(maps, 6, 4, policy)
    assert step(agent, EIGHT[0]).encoded.item()
    assert step(agent, EIGHT[0], observed=60.0).encoded.item() and agent.hub.n_assemblies.item() == 1
    for obj in EIGHT[1:5]:
        assert step(agent, obj).encoded.item()
        assert codes_in_hub(agent)
    v = [agent.reward.stored(torch.tensor([cylinder(*o)[1]])).item() for o in EIGHT]    # as the memory holds them
    again = agent.reward.stored(torch.tensor([60.0])).item()
    got = stored_rewards(agent)
    if policy == "forget_oldest":
        assert got == [v[1], v[2], v[3], v[4]]
    else:
        assert got[:2] == [v[0], again] and got[-1] == v[4] and len(got) == 5 and set(got[2:4]) < {v[1], v[2], v[3]}
    assert agent.hub.n_assemblies.item() == 4


@pytest.mark.parametrize("policy", FORGET)
def test_a_name_goes_with_its_assembly_and_naming_a_look_alike_makes_room_too(maps, policy):
    # a hub of 2: the red cylinder and a green one fill it. A blue cylinder like the red one, which went the same
    # way, is not encoded (nothing new), but its name needs an assembly of its own (Agent._name): the hub frees
    # the oldest (both used once), the red one, and the red one's episode leaves with it; its name too
    red, blue = ((0.85, 0.1, 0.1), 5.0, 8.0, 400.0), ((0.1, 0.2, 0.85), 5.0, 8.0, 400.0)
    agent = agent_with(maps, 4, 2, policy)
    assert step(agent, red, words="red heavy cylinder").encoded.item()
    assert step(agent, EIGHT[2], words="green large cylinder").encoded.item()
    assert agent.imagine("red heavy cylinder").score.item() == pytest.approx(1.0, abs=1e-4)
    assert not step(agent, blue, words="blue heavy cylinder").encoded.item()
    assert agent.hub.n_assemblies.item() == 2 and agent.memory.count.item() == 1 and codes_in_hub(agent)
    assert agent.imagine("blue heavy cylinder").score.item() == pytest.approx(1.0, abs=1e-4)
    assert agent.imagine("green large cylinder").score.item() == pytest.approx(1.0, abs=1e-4)
    assert agent.imagine("red heavy cylinder").score.item() < 0.9        # only the blue one's two words of three
    # and a hub full of objects with episodes frees the named-only one first: the blue name leaves, no episode does
    assert step(agent, EIGHT[3], words="yellow small cylinder").encoded.item()
    assert agent.memory.count.item() == 2 and codes_in_hub(agent)
    assert agent.imagine("blue heavy cylinder").score.item() < 0.9


@pytest.mark.parametrize("policy", FORGET)
def test_a_memory_smaller_than_the_hub_forgets_episodes_and_the_hub_frees_unused_assemblies_first(maps, policy):
    # memory 4, hub 6: objects 5 and 6 push episodes 1 and 2 out of the memory (their assemblies stay, unused);
    # objects 7 and 8 find the hub full and free those two first, so no stored episode loses its object
    agent = agent_with(maps, 4, 6, policy)
    for t, obj in enumerate(EIGHT):
        step(agent, obj)
        assert codes_in_hub(agent)
        assert agent.memory.count.item() == min(t + 1, 4) and agent.hub.n_assemblies.item() == min(t + 1, 6)
    if policy == "forget_oldest":
        want = [agent.reward.stored(torch.tensor([cylinder(*o)[1]])).item() for o in EIGHT[4:]]
        assert stored_rewards(agent) == want
    # the hub still knows the objects whose episodes left last (3 and 4 under forget_oldest), unused
    held = agent._assemblies(agent.memory.patterns[0, :4])
    used = (agent.hub.assemblies[0][:, None] == held[None]).all(-1).any(1)
    assert used.sum().item() == 4 and (~used[:6]).sum().item() == 2


@pytest.mark.parametrize("policy", FORGET)
def test_batched_agents_forget_independently_and_select_copies_them(maps, policy):
    # agent 0 sees all eight objects, agent 1 learns only the first three: agent 1 is as an agent that saw three
    both = agent_with(maps, 4, 4, policy, batch=2)
    alone = agent_with(maps, 4, 4, policy)
    for t, obj in enumerate(EIGHT):
        step(both, obj, learn=torch.tensor([True, t < 3]))
        if t < 3:
            step(alone, obj)
    for part in ("memory", "hub"):
        for k, v in getattr(both, part).state_dict().items():
            assert torch.equal(v[1], getattr(alone, part).state_dict()[k][0])
    assert both.memory.count.tolist() == [4, 3]
    # a copy of agent 0 carries its (forgotten-into) state and forgets on as it does
    copy = both.select([0])
    ninth = ((0.3, 0.3, 0.9), 5.5, 8.8, 700.0)
    step(both, ninth, learn=torch.tensor([True, False]))
    step(copy, ninth)
    assert copy.memory.count.item() == 4 and codes_in_hub(copy)
    for part in ("memory", "hub"):
        for k, v in getattr(both, part).state_dict().items():
            assert torch.equal(v[0], getattr(copy, part).state_dict()[k][0])


@pytest.mark.parametrize("policy", FORGET)
def test_a_life_of_40_generated_objects_in_a_memory_of_16(maps, policy):
    """A cheaper version of a 330-object life in a memory of 230: it runs to the end, stays consistent (every
    episode on an assembly the hub holds), and still predicts the probes."""
    from sim.make_objects import generate
    from sim.objects import parse_objects
    from sim.sensor_model import SensorModel
    from train.learning.experiment import closed_form_outcomes, stack_measurements

    objs = parse_objects(generate(0, 40, 8, pairs=True))
    outcomes, probes = closed_form_outcomes(objs, sensor=SensorModel(), seed=0)
    agent = agent_with(maps, 16, 16, policy, model="extended")
    for s in objs.train:
        r = outcomes[s.name]
        agent.step(stack_measurements([r["measurement"]]),
                   torch.tensor([r["observed_cm3"]]), torch.tensor([r["goal_before"]]),
                   torch.tensor([r["goal_after"]]), sank=torch.tensor([r["sank"]]))
        assert codes_in_hub(agent)
    assert agent.memory.count.item() == 16 and agent.hub.n_assemblies.item() <= 16
    pmeas = stack_measurements([probes[o.name]["measurement"] for o in objs.probe])
    truth = torch.tensor([probes[o.name]["archimedes_cm3"] for o in objs.probe])
    pred = agent.select(torch.zeros(len(truth), dtype=torch.long)).anticipate(pmeas).expected
    err = ((pred - truth).abs() / truth).nan_to_num(1.0)
    assert err.median().item() < 0.2
