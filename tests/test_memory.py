"""Episodic memory: hand-made episodes with known recalls, the paper's capacity, and the dense network as oracle."""

import pytest
import torch

from aesop_torch.memory import EpisodicMemory, MemoryConfig, k_winners

R, C, OBJ = 20, 50, 1


def episode(obj, reward, body_end=(8, 9), extra=()):
    """An agent-like sheet: the same body state and reach/grasp/drop codes every time, its own object and reward."""
    x = torch.zeros(R, C, dtype=torch.bool)
    rows = [(0, (0, 1)), (OBJ, obj), (2, (2, 3)), (3, (4, 5)), (4, (6, 7)), (5, reward), (6, body_end)]
    for r, idx in [*rows, *extra]:
        x[r, list(idx)] = True
    return x


A = episode(range(0, 5), (3, 30))
B = episode(range(5, 10), (7, 40), body_end=(10, 11))
Cc = episode(range(10, 15), (0, 25))


def memory(*episodes, batch=1, **cfg):
    mem = EpisodicMemory(MemoryConfig(**cfg), batch=batch)
    for e in episodes:
        mem.store(e.expand(batch, R, C))
    return mem


def cue(*parts):
    """Object-hub activity: value v on the object neurons of each (episode, v)."""
    q = torch.zeros(C)
    for e, v in parts:
        q = torch.maximum(q, v * e[OBJ].float())
    return q[None]


def agent_like_episodes(n, g):
    """Shared rows, a random 5-neuron object code, one of 3 rewards and one of 2 body states."""
    stored = []
    for _ in range(n):
        obj = torch.randperm(C, generator=g)[:5].tolist()
        reward = [(3, 30), (7, 40), (0, 25)][int(torch.randint(3, (1,), generator=g))]
        stored.append(episode(obj, reward, body_end=[(8, 9), (10, 11)][int(torch.randint(2, (1,), generator=g))]))
    return stored


def random_episodes(n, g, rows=R):
    x = torch.zeros(n, R, C, dtype=torch.bool)
    order = torch.rand(n, R, C, generator=g).argsort(-1)
    for r in range(rows):
        x[:, r].scatter_(1, order[:, r, :5 if r == OBJ else 2], True)
    return x


def test_hand_made_episodes_recalled_exactly_from_their_object_row():
    mem = memory(A, B, Cc)
    for e in (A, B, Cc):
        out = mem.recall(cue((e, 1.0)))
        assert out.any.item() and out.valid[0].tolist() == [True] + [False] * 7
        assert torch.equal(out.episodes[0, 0], e)
        assert out.strength[0, 0].item() == pytest.approx(1.0)
        assert not out.episodes[0, 1:].any() and (out.strength[0, 1:] == 0).all()


def test_empty_memory_and_unknown_cue_recall_nothing():
    out = EpisodicMemory().recall(cue((A, 1.0)))
    assert not out.any.item() and not out.valid.any() and not out.episodes.any()
    q = torch.zeros(1, C)
    q[0, 30:35] = 1.0  # object neurons no stored episode uses
    assert not memory(A, B, Cc).recall(q).any.item()


def test_graded_cue_recalls_the_episode_with_the_cue_strength():
    # an object differing in one property of four: 0.75 on the stored assembly, a little activity elsewhere
    q = cue((A, 0.75)) + 0.03 * (1 - A[OBJ].float())
    out = memory(A, B, Cc).recall(q)
    assert torch.equal(out.episodes[0, 0], A) and out.strength[0, 0].item() == pytest.approx(0.75)
    # what else the faint activity touches comes back too, weakest last, each with the little it shares
    assert (out.strength[0, 1:][out.valid[0, 1:]] <= 0.03 + 1e-6).all()


def test_cue_overlapping_two_objects_recalls_both_strongest_first():
    for first, second in ((A, B), (B, A)):
        out = memory(A, B, Cc).recall(cue((second, 0.5), (first, 0.75)))
        assert out.valid[0].tolist()[:3] == [True, True, False]
        assert torch.equal(out.episodes[0, 0], first) and torch.equal(out.episodes[0, 1], second)
        assert out.strength[0, :2].tolist() == pytest.approx([0.75, 0.5])
    out = memory(A, B, Cc).recall(cue((A, 0.5), (B, 0.5), (Cc, 0.5)))
    got = {tuple(e.flatten().nonzero().flatten().tolist()) for e in out.episodes[0, :3]}
    assert out.valid[0].sum() == 3 and got == {tuple(e.flatten().nonzero().flatten().tolist()) for e in (A, B, Cc)}


def test_empty_rows_stay_empty():
    # B2 uses row 12, which A shares five of its seven rows with: recalling A must not borrow it
    B2 = episode(range(5, 10), (7, 40), extra=[(12, (20, 21))])
    mem = memory(A, B2, Cc)
    out = mem.recall(cue((A, 1.0)))
    assert torch.equal(out.episodes[0, 0], A)
    assert not out.episodes[0, 0, 7:].any()  # rows no episode of A uses, including B2's row 12
    assert torch.equal(mem.recall(cue((B2, 1.0))).episodes[0, 0], B2)


def test_paper_capacity_230_random_episodes():
    # Hopfield 2008 / the paper: ~230 episodes in 1000 neurons; all 20 rows random (5-hot object row, 2-hot others)
    x = random_episodes(230, torch.Generator().manual_seed(0))
    mem = memory()
    for e in x:
        mem.store(e[None])
    # the strongest of the first two recalls: a stored neighbour sharing 4 of the 5 object neurons may come first
    out = mem.recall(x[:, OBJ].float(), max_recalls=2)
    exact = (out.episodes[:, 0] == x).flatten(1).all(1).float().mean().item()
    assert exact >= 0.99


def test_weights_are_the_covariance_of_the_stored_episodes():
    # two episodes: p = (A + B) / 2, so J = 2 * ((A - B) / 2)((A - B) / 2)^T = (A - B)(A - B)^T / 2, zero diagonal.
    # z-scored: a neuron where A and B differ has p = 1/2 and sigma = 1/2, so y = +-1 there and 0 elsewhere:
    # J~ = 2 (A - B)(A - B)^T
    d = (A.flatten().double() - B.flatten().double())
    for zscore, scale in ((False, 0.5), (True, 2.0)):
        mem = memory(A, B, zscore=zscore)
        expected = torch.outer(d, d) * scale
        expected.fill_diagonal_(0)
        assert torch.equal(mem.weights(0), expected)
        assert torch.equal(mem.mean_activity(0), (A.flatten().double() + B.flatten().double()) / 2)


def dense_predict(J, p, s):
    """J from mem.weights (z-scored): a = p + sigma J~ d~ / sum_{j != i} d~_j^2, d~ = (s - p) / sigma."""
    sigma = (p * (1 - p)).sqrt()
    inv = torch.where(sigma > 1e-6, 1 / sigma.clamp_min(1e-6), torch.zeros_like(sigma))
    d = (s - p) * inv
    return p + sigma * (J @ d) / ((d * d).sum() - d * d).clamp(min=1e-3)


def dense_recall(stored, q, cfg, K, in_order=False):
    """The two-phase recall on the dense network; each retrieved state is then depressed: J and p as if it had been
    stored with weight -1 (a retrieved stored episode is as if not stored). With cfg.cue_power != 1 the sheet is
    clamped to the drive, (drive / its peak)^power, and each retrieved object's neurons leave the drive; the first
    retrieval that settles nowhere ends the recall (misses = 0). Strongest first, or in retrieval order."""
    row_k = torch.tensor(cfg.row_k)
    x = torch.stack([e.flatten().double() for e in stored])
    sign = torch.ones(len(stored), dtype=torch.double)
    found, drive = [], q.clone()
    for _ in range(K):
        if sign.sum() < 0.5:
            break
        clamp_to = q if cfg.cue_power == 1 else (drive / drive.max() if drive.max() > 0 else drive) ** cfg.cue_power
        p = (sign[:, None] * x).sum(0) / sign.sum()
        sigma = (p * (1 - p)).sqrt()
        y = torch.where(sigma > 1e-6, (x - p) / sigma.clamp_min(1e-6), torch.zeros_like(x))
        J = (y.T * sign) @ y
        J.fill_diagonal_(0)
        s = p.clone().view(R, C)
        s[OBJ] = clamp_to
        for clamp, steps in ((True, cfg.cue_steps), (False, cfg.free_steps)):
            for _ in range(steps):
                new = k_winners(dense_predict(J, p, s.flatten()).view(R, C), row_k, cfg.threshold).double()
                if clamp:
                    new[OBJ] = clamp_to
                moved = not torch.equal(new, s)
                s = new
                if not moved:
                    break
        strength = (q * s[OBJ]).sum() / s[OBJ].sum().clamp(min=1)
        if moved or strength < cfg.min_strength:
            break
        found.append((s.bool(), strength.item()))
        drive = drive * (1 - s[OBJ])
        x, sign = torch.cat([x, s.flatten()[None]]), torch.cat([sign, -torch.ones(1, dtype=torch.double)])
    return found if in_order else sorted(found, key=lambda f: -f[1])


def test_factorised_network_equals_dense_network():
    g = torch.Generator().manual_seed(3)
    stored = list(random_episodes(12, g, rows=9))
    mem = memory(*stored)
    J, p = mem.weights(0), mem.mean_activity(0)
    states = torch.rand(4, R, C, generator=g).double()
    states[:2] = (states[:2] < 0.1).double()  # two binary states, two graded
    got = mem.predict(states)
    for s, a in zip(states, got):
        assert torch.allclose(a.flatten().double(), dense_predict(J, p, s.flatten()), atol=1e-4)
    # whole recalls: single objects, graded and mixed cues
    cues = torch.stack([stored[0][OBJ].float(), 0.75 * stored[1][OBJ].float(),
                        torch.maximum(0.8 * stored[2][OBJ].float(), 0.5 * stored[3][OBJ].float())])
    out = mem.recall(cues, max_recalls=3)
    for b in range(len(cues)):
        want = dense_recall(stored, cues[b].double(), mem.config, 3)
        assert out.valid[b].sum().item() == len(want) >= 1
        for k, (e, strength) in enumerate(want):
            assert torch.equal(out.episodes[b, k], e)
            assert out.strength[b, k].item() == pytest.approx(strength, abs=1e-6)


def test_a_spurious_fixed_point_is_depressed_as_its_outer_product():
    """Agent-like episodes (shared rows, 3 rewards, 2 body states) and random graded cues: some cues settle into a
    state no episode holds, others alternate between two states (never fixed: the recall stops there, at once
    instead of after free_steps). A stored episode is depressed by masking its term, any other state by subtracting
    its outer product; both as the dense network that stores each retrieved state with weight -1."""
    g = torch.Generator().manual_seed(3)
    stored = agent_like_episodes(8, g)
    mem = memory(*stored)
    cues = torch.rand(20, C, generator=g) ** 3
    out = mem.recall(cues, max_recalls=6)
    spurious_then_more = 0
    for b in range(len(cues)):
        want = dense_recall(stored, cues[b].double(), mem.config, 6, in_order=True)
        assert out.valid[b].sum().item() == len(want)
        for k, (e, strength) in enumerate(sorted(want, key=lambda f: -f[1])):
            assert torch.equal(out.episodes[b, k], e)
            assert out.strength[b, k].item() == pytest.approx(strength, abs=1e-6)
        spurious_then_more += any(not any(torch.equal(e, x) for x in stored) for e, _ in want[:-1])
    assert spurious_then_more >= 1    # a spurious state was depressed and the recall went on


def test_unbounded_recall_is_the_networks_own_number_and_a_bound_cuts_only_beyond_it():
    """max_recalls=None: every state the network settles into until a stop (the dense reference, run until it
    stops by itself), in max_episodes slots. A bound at least the number the network brings back for a cue changes
    nothing; a lower one cuts that cue's recall to its first retrievals."""
    g = torch.Generator().manual_seed(5)
    codes = torch.randperm(C, generator=g)[:40].view(8, 5)        # 8 objects, no neuron shared
    stored = [episode(code.tolist(), (3, 30 + i)) for i, code in enumerate(codes)]
    mem = memory(*stored, max_recalls=None, max_episodes=10)
    # each cue touches 1 to 4 of the objects, each at its own graded activity
    cues = torch.cat([cue(*[(stored[int(i)], 0.3 + 0.7 * float(torch.rand(1, generator=g)))
                            for i in torch.randperm(8, generator=g)[:1 + b % 4]]) for b in range(12)])
    free = mem.recall(cues)
    assert free.valid.shape == (12, 10)
    n = free.valid.sum(1)
    for b in range(len(cues)):
        want = dense_recall(stored, cues[b].double(), mem.config, 100)   # far more than can ever come back
        assert n[b].item() == len(want)
        assert all(torch.equal(free.episodes[b, k], e) for k, (e, _) in enumerate(want))
    assert int(n.max()) >= 4 and int(n.min()) < int(n.max())
    for bound in range(1, 9):
        cut = mem.recall(cues, max_recalls=bound)
        whole = n <= bound
        assert torch.equal(cut.valid[whole], free.valid[whole, :bound])
        assert torch.equal(cut.episodes[whole], free.episodes[whole, :bound])
        assert torch.equal(cut.strength[whole], free.strength[whole, :bound])
        assert (cut.valid[~whole].sum(1) == bound).all()


def test_a_miss_takes_the_cues_strongest_neurons_out_and_the_recall_goes_on(monkeypatch):
    """Cue A at 1 and B at 0.8, to the 16th power: the drive clamps A at 1 and B at 0.8^16 = 0.03. If that first
    retrieval settles nowhere, misses=0 ends the recall with nothing; misses=1 takes out the drive's neurons at
    >= 0.5^(1/16) = 0.96 of its peak (A's: 1, not B's: 0.8) and retrieves again from B alone, at B's strength."""
    q = cue((A, 1.0), (B, 0.8))
    seen = []
    real = EpisodicMemory._settle

    def first_misses(self, drive, net):
        seen.append(drive.clone())
        state, fixed = real(self, drive, net)
        return state, fixed & (len(seen) > 1)
    monkeypatch.setattr(EpisodicMemory, "_settle", first_misses)
    assert not memory(A, B, Cc, cue_power=16.0).recall(q).any.item() and len(seen) == 1
    seen.clear()
    out = memory(A, B, Cc, cue_power=16.0, misses=1).recall(q)
    assert torch.equal(seen[1], q * (1 - A[OBJ].float()))
    assert torch.equal(out.episodes[0, 1], B) and out.strength[0, 1].item() == pytest.approx(0.8)
    # B's neurons leave the drive in turn; from the spent drive (all 0) the sheet still settles, into A, which
    # comes back at its strength from the cue as given, 1
    assert not seen[2].any() and torch.equal(out.episodes[0, 0], A) and out.strength[0, 0].item() == 1.0
    with pytest.raises(ValueError, match="misses"):
        MemoryConfig(misses=1)    # cue_power 1: the cue is clamped as given, there is no drive to take from


def test_misses_leave_the_recall_before_the_first_miss_as_it_was():
    """Agent-like episodes and random graded cues to the 16th power: with misses=0 the recall is the dense
    reference's (first miss ends it); with misses=2 every episode of that recall comes back with the same strength,
    and some cues go on past a miss to recall more."""
    g = torch.Generator().manual_seed(7)
    stored = agent_like_episodes(12, g)
    cues = torch.rand(24, C, generator=g) ** 2
    base = memory(*stored, cue_power=16.0, max_recalls=None, max_episodes=12).recall(cues)
    more = memory(*stored, cue_power=16.0, misses=2, max_recalls=None, max_episodes=12).recall(cues)
    went_on = 0
    for b in range(len(cues)):
        want = dense_recall(stored, cues[b].double(), MemoryConfig(cue_power=16.0), 100)
        assert base.valid[b].sum().item() == len(want)
        for k, (e, strength) in enumerate(want):
            assert torch.equal(base.episodes[b, k], e)
            assert base.strength[b, k].item() == pytest.approx(strength, abs=1e-6)
        got = [(more.episodes[b, k], more.strength[b, k].item()) for k in range(int(more.valid[b].sum()))]
        for e, strength in want:
            assert any(torch.equal(e, f) and t == pytest.approx(strength, abs=1e-6) for f, t in got)
        went_on += len(got) > len(want)
    assert went_on >= 3


def test_the_free_phase_starts_from_the_clamped_phase_last_prediction(monkeypatch):
    """Cue A's exact object row (binary, as stored): the first clamped step completes A, the second finds A fixed, and
    the free phase starts from that same state, so its first step is the second's prediction, not computed again:
    it finds A fixed too (its cue row is A's binary one). 2 predictions for the recall, not 3; the same recall as
    the dense network's, which computes every step."""
    mem = memory(A, B, Cc)
    calls = []
    winners = EpisodicMemory._winners

    def counted(self, net, state, finite):
        calls.append(state.shape[0])
        return winners(self, net, state, finite)

    monkeypatch.setattr(EpisodicMemory, "_winners", counted)
    out = mem.recall(cue((A, 1.0)), max_recalls=1)
    assert calls == [1, 1]
    assert out.valid[0, 0] and torch.equal(out.episodes[0, 0], A)
    want = dense_recall([A, B, Cc], A[OBJ].double(), mem.config, 1)
    assert len(want) == 1 and torch.equal(want[0][0], A)


def test_agents_are_independent_and_many_cues_share_one_memory():
    both = EpisodicMemory(batch=2)
    both.store(torch.stack([A, B]))
    both.store(torch.stack([Cc, Cc]), mask=torch.tensor([False, True]))  # only agent 1 learns C
    assert both.count.tolist() == [1, 2]
    for q in (cue((Cc, 0.8)).repeat(2, 1), torch.cat([cue((A, 1.0)), cue((B, 0.75))])):
        out = both.recall(q)
        for b, alone in enumerate((memory(A), memory(B, Cc))):
            one = alone.recall(q[b:b + 1])
            assert all(torch.equal(x[b:b + 1], y) for x, y in zip(out, one))
    assert torch.equal(out.episodes[0, 0], A) and torch.equal(out.episodes[1, 0], B)
    out = both.recall(cue((Cc, 0.8)).repeat(2, 1))
    assert out.any.tolist() == [False, True] and torch.equal(out.episodes[1, 0], Cc)  # agent 0 never saw C
    shared = memory(A, B, Cc).recall(torch.cat([cue((A, 1.0)), cue((B, 0.75)), cue((Cc, 0.5))]))
    for b, e in enumerate((A, B, Cc)):
        assert torch.equal(shared.episodes[b, 0], e) and shared.valid[b].sum() == 1


def test_same_seed_same_result():
    def run(seed):
        x = random_episodes(60, torch.Generator().manual_seed(seed))
        mem = memory()
        for e in x:
            mem.store(e[None])
        return mem.recall(x[:, OBJ].float() * 0.9, max_recalls=2)
    a, b, c = run(5), run(5), run(6)
    assert all(torch.equal(x, y) for x, y in zip(a, b))
    assert not torch.equal(a.episodes, c.episodes)


def test_full_memory_refuses_and_keeps_what_it_has():
    mem = memory(A, B, max_episodes=2)
    with pytest.raises(RuntimeError, match="full"):
        mem.store(Cc[None])
    assert mem.count.tolist() == [2] and torch.equal(mem.patterns[0, 0], A) and torch.equal(mem.patterns[0, 1], B)
    mem.store(Cc[None], mask=torch.tensor([False]))  # a masked-out agent is not written, so no error
    mem.reset()
    assert mem.count.tolist() == [0] and not mem.patterns.any() and not mem.recall(cue((A, 1.0))).any.item()


def test_bad_input_is_refused():
    mem = memory(A)
    bad = A.clone()
    bad[5, 44] = True  # three active neurons on a 2-of-50 row
    with pytest.raises(ValueError, match="row 5 has 3"):
        mem.store(bad[None])
    with pytest.raises(ValueError, match="empty cue rows"):
        mem.store(torch.zeros(1, R, C, dtype=torch.bool))
    with pytest.raises(ValueError, match="shape"):
        mem.store(A)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        mem.recall(2 * cue((A, 1.0)))
    with pytest.raises(ValueError, match="batch"):
        EpisodicMemory(batch=2).recall(torch.zeros(3, C))
    with pytest.raises(ValueError, match="row_k"):
        MemoryConfig(row_k=(2,) * 19)
    with pytest.raises(ValueError, match="max_recalls"):
        MemoryConfig(max_recalls=0)                       # None is no bound; 0 is no recall at all: refused
    with pytest.raises(ValueError, match="max_recalls"):
        mem.recall(cue((A, 1.0)), max_recalls=0)
    assert mem.count.tolist() == [1]


def test_state_dict_round_trip_and_device():
    mem = memory(A, B, Cc)
    copy = EpisodicMemory()
    copy.load_state_dict(mem.state_dict())
    assert set(mem.state_dict()) == {"patterns", "count"}
    moved = copy.to(torch.device("cpu"))
    q = cue((B, 0.75), (A, 0.5))
    assert all(torch.equal(x, y) for x, y in zip(mem.recall(q), moved.recall(q)))


def test_capacity_of_a_small_sheet_by_hand():
    """A 2 x 4 sheet, one neuron per row (row_k 1): an object row (the cue) and a reward row. Its capacity for
    exact recall is 4 episodes, one per object neuron. By hand, for 4 episodes pairing object i with reward pi(i):
    every neuron has p = 1/4, sigma^2 = 3/16, and the z-scored weight from object i to reward j is
    sum_mu y_mu,i y_mu,j = (3/4 * 3/4 + 3 * 1/4 * 1/4) / (3/16) = 4 when j = pi(i) (the episode they share) and
    (2 * -3/4 * 1/4 + 2 * 1/16) / (3/16) = -4/3 otherwise: the cue drives its own reward alone. A fifth episode has
    no object neuron of its own: sharing object 0 with the first, its cue is the first's, which recalls both
    episodes, each with the whole cue (strength 1), so neither is told apart by its object any more."""
    pi = (2, 0, 3, 1)
    cfg = dict(rows=2, cols=4, row_k=(1, 1), cue_rows=(0,), max_episodes=5, max_recalls=4)

    def ep(obj, reward):
        x = torch.zeros(2, 4, dtype=torch.bool)
        x[0, obj] = x[1, reward] = True
        return x[None]

    mem = EpisodicMemory(MemoryConfig(**cfg))
    for i, j in enumerate(pi):
        mem.store(ep(i, j))
    J = mem.weights(0).view(2, 4, 2, 4)[0, :, 1, :]             # object neuron i -> reward neuron j
    expected = torch.full((4, 4), -4 / 3, dtype=J.dtype)
    expected[torch.arange(4), torch.tensor(pi)] = 4.0
    assert torch.allclose(J, expected)
    cues = torch.eye(4)                                          # each object neuron alone
    out = mem.recall(cues)
    assert out.valid[:, 0].all() and (out.valid[:, 1:].sum(1) == 0).all()
    for i, j in enumerate(pi):
        assert torch.equal(out.episodes[i, 0], ep(i, j)[0])
    mem.store(ep(0, 3))                                          # a fifth: object 0 again, another reward
    out = mem.recall(cues[:1])
    got = {int(e[1].nonzero()) for e, v in zip(out.episodes[0], out.valid[0]) if v}
    assert got == {pi[0], 3} and out.strength[0, :2].tolist() == pytest.approx([1.0, 1.0])


def test_a_recall_does_not_depend_on_the_batch_it_is_in():
    # graded cues against 150 random episodes, several recalls each: near ties that float rounding could settle
    # either way, so the sums must run in the same order for a cue alone as among others
    g = torch.Generator().manual_seed(7)
    x = random_episodes(150, g)
    mem = memory(*x[:, None])
    cues = (0.8 * x[:40, OBJ].float() + 0.3 * torch.rand(40, C, generator=g)).clamp(max=1.0)
    states = torch.rand(40, R, C, generator=g)
    states[:20] = (states[:20] < 0.05).float()
    together = mem.predict(states)                      # what the network predicts, bit for bit
    for i in range(0, 40, 3):
        assert torch.equal(mem.predict(states[i:i + 1])[0], together[i])
    together = mem.recall(cues, max_recalls=4)
    assert together.valid.sum() > 40                     # more than one episode per cue on average
    for i in range(0, 40, 3):
        alone = mem.recall(cues[i:i + 1], max_recalls=4)
        assert all(torch.equal(a[0], t[i]) for a, t in zip(alone, together))
    # agents each with their own memory: in one batch, or each alone
    agents = EpisodicMemory(MemoryConfig(max_episodes=30), batch=4)
    for m in range(30):
        agents.store(x[m::30][:4], mask=torch.tensor([True, m < 20, m < 10, True]))
    q = cues[:4]
    together = agents.recall(q, max_recalls=4)
    for b in range(4):
        alone = EpisodicMemory(MemoryConfig(max_episodes=30))
        alone.patterns[0], alone.count[0] = agents.patterns[b], agents.count[b]
        assert all(torch.equal(a[0], t[b]) for a, t in zip(alone.recall(q[b:b + 1], max_recalls=4), together))
