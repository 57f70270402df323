"""Consolidation by replay (the contextual model): after each episode, the robot at rest re-derives its knowledge per
context from the comparisons of every pair of episodes it has lived, so the knowledge is a function of those episodes
and not of the order they came in.

What is replayed: every episode lived, as the memory's capacity allows (`ContextualRules.lived_*`, the capacity the
memory's max_episodes; when full, the oldest goes), not only the episodes the memory stored. What is stored depends on
the order (an episode like a stored one that went the same way is not encoded, the paper's episode 2), so replaying the
stored ones would bring the order back in. Each lived episode is kept as the robot perceived it: its properties'
decoded values, its outcome as the memory holds it (through the reward code) and its fate. The expected fate is
read from the same store: a boundary fitted over every episode lived (agent.py `_fate_lived`).

Each pair is compared once, when its later episode is lived (`add_episode`: only the new episode's pairs are new),
at full strength, and cached (DeltaProperty changed / unclear per property, the sign of each ordered property's change,
DeltaContradiction, the outcome's dead zone and its sign). The knowledge is then derived from the cache (`derive`)
with the rules' judgments, every pair at once (each distinct pattern of pairs judged once and counted, `patterns`):

- Elimination, in the floating and sinking contexts only, on the clean pairs (one property changed among those the
  context still shows) whose reward held, counted: at least `AgentConfig.elim_pairs` of them, and at least
  `elim_share` of the property's clean pairs, held and moved, each judged as if the property were live. Among the
  ~26,000 pairs of a life of 230 a few look clean with the reward held by noise or a cancellation; a true cause's
  many clean moved pairs outvote them (`--ablate tally`: any clean held pair eliminates). Iterated to a fixpoint:
  an eliminated pathway shows no change, so more pairs become clean.
- No Elimination in the fate context: the fate is a boundary (sink or float), so most single-property changes leave
  it as it was, a true cause included. A property is irrelevant to the fate once both reward contexts eliminated it.
- Growth on a clean pair whose outcome moved (for the fate: a clean flip), and on the one eliminated property that
  alone explains a contradiction nothing live explains (seen at full strength; one eliminated in every context
  explains nothing). Growth outranks Elimination: a grown property is never eliminated, and the eliminations are
  derived again (from none) whenever a Growth is added, until neither changes.
- Signed consistency: Growth also on an ordered property (fill, size, weight; colour and elongation have no sign)
  whose change had the sign of the outcome's change in every clear contradicted pair of the context where it changed
  clearly, at least `AgentConfig.signed_pairs` of them (the fate's sign: sank over floated). Two floaters rarely share
  a mass, so the clean pair that would show weight is rare; heavier floaters displacing more, every time, shows it.
- Uncertainty counted on live undecided properties that did not change in a contradicted pair.
- Comparisons that cannot tell are left out (`comparisons.cannot_tell`), and with `AgentConfig.strict_comparisons`
  every pair with a live property in its dead zone.

Strengths are read back as the sequential rules would leave them: eliminated at `eliminated_strength`, grown at
1 + growth_step per Growth (up to `dominant_strength`), undecided at uncertain_decay^n (never below uncertain_floor).
"""

from __future__ import annotations

import torch

from .comparisons import CONTEXTS, FATE, FLOATING, SINKING, cannot_tell, delta_property
from .fitted_readout import log_mass, log_size
from .rules import ELIMINATION, GROWTH, UNCERTAINTY, contradiction, outcome_unclear


def signed_gaps(values: dict, recalled: dict, config) -> torch.Tensor:
    """(B, K, P) the sign (-1, 0, 1) of each property's change from recalled[p] (B, K, dim) to values[p] (B, dim):
    fill, size, weight and 1-d context properties are ordered; colour and elongation (several dimensions) are not (0)."""
    enc = config.encoder
    out = []
    for p in config.properties:
        if p == "size":
            d = log_size(values, enc)[:, None] - log_size(recalled, enc)
        elif p == "weight":
            d = log_mass(values, enc)[:, None] - log_mass(recalled, enc)
        elif values[p].shape[-1] == 1:
            d = values[p][:, None, 0] - recalled[p][..., 0]
        else:
            d = torch.zeros(recalled[p].shape[:2])
        out.append(torch.sign(torch.nan_to_num(d, nan=0.0)))
    return torch.stack(out, -1).to(torch.int8)


def unflatten(flat: torch.Tensor, dims: dict) -> dict:
    """(..., D) the lived store's rows -> {property: (..., dim)}."""
    out, i = {}, 0
    for p, d in dims.items():
        out[p] = flat[..., i:i + d]
        i += d
    return out


@torch.no_grad()
def add_episode(rules, values: dict, outcome: torch.Tensor, fate: torch.Tensor, learn: torch.Tensor, config) -> None:
    """Store the episode (values {property: (B, dim)} decoded, outcome (B,) as the memory holds it, fate (B,) long)
    in the lived store of the agents in learn, and compare it with every earlier one (the new pairs, cached)."""
    rules.ensure_cache(config)
    M = rules.lived_values.shape[1]
    if M == 0:
        return
    full = learn & (rules.lived_count >= M)
    if full.any():
        rules.drop_oldest(full)
    slot = rules.lived_count.clone()                                               # (B,)
    rows = torch.arange(rules.lived_values.shape[0])
    flat = torch.cat([values[p] for p in rules.dims], -1).to(rules.lived_values.dtype)
    stored = {p: v for p, v in unflatten(rules.lived_values, rules.dims).items()}
    changed, unclear = delta_property(values, stored, config)                      # (B, M, P) new against each
    sign = signed_gaps(values, stored, config)
    dc = contradiction(outcome[:, None], rules.lived_outcome, config.rules)
    uc = outcome_unclear(outcome[:, None], rules.lived_outcome, config.rules)
    osign = torch.sign(outcome[:, None] - rules.lived_outcome).to(torch.int8)
    s = slot.clamp(max=M - 1)
    b = rows[learn]
    k = s[learn]
    rules.lived_values[b, k] = flat[learn]
    rules.lived_outcome[b, k] = outcome[learn]
    rules.lived_fate[b, k] = fate[learn]
    # pair [n, j] and [j, n] alike (a against b reads as b against a); the signs from j to n, and back negated
    for name, v, neg in (("pair_changed", changed, False), ("pair_unclear", unclear, False),
                         ("pair_sign", sign, True), ("pair_dc", dc, False), ("pair_uc", uc, False),
                         ("pair_osign", osign, True)):
        buf = getattr(rules, name)
        buf[b, k] = v[learn]
        buf[b, :, k] = -v[learn] if neg else v[learn]
    rules.lived_count[learn] += 1
    rules.cached_count.copy_(rules.lived_count)


def patterns(pairs, seen, fi, fj, dc, uc, osign, changed, unclear, sign):
    """The pairs (each (B, N), or (B, N, P) per property) as their distinct patterns: (w, the same tensors over U
    patterns), w (B, U) how many of each agent's pairs show each pattern (0: none). A life of 230 has ~26,000 pairs
    and a few thousand patterns (per property changed, unclear or neither, and the sign of its change; the outcome's;
    the two fates), and derive's fixpoints judge each pattern once instead of each pair."""
    B, N = pairs.shape
    kind = torch.where(fi == fj, fi.clamp(min=0) + 2, torch.where(fi > fj, 4, 5))   # 2..5: ff ss sf fs
    kind = torch.where(seen, kind, pairs.long())                                    # 1: a pair, a fate unseen
    code = ((kind * 2 + dc) * 2 + uc) * 3 + osign.long() + 1
    for p in range(changed.shape[-1]):
        code = (code * 3 + changed[..., p] * 2 + unclear[..., p]) * 3 + sign[..., p].long() + 1
    ok = kind > 0
    u, inv = torch.unique(code[ok], return_inverse=True)
    w = torch.zeros(B, len(u), dtype=torch.long)
    w.index_put_((torch.arange(B)[:, None].expand(B, N)[ok], inv), torch.ones_like(inv), accumulate=True)
    digits = []
    for _ in range(changed.shape[-1]):
        digits.append((u % 3 - 1, u // 3 % 3))
        u = u // 9
    sign = torch.stack([s for s, _ in digits[::-1]], -1).to(torch.int8)
    state = torch.stack([c for _, c in digits[::-1]], -1)
    osign, u = (u % 3 - 1).to(torch.int8), u // 3
    uc, u = (u % 2).bool(), u // 2
    dc, kind = (u % 2).bool(), u // 2
    fi = torch.tensor([-1, -1, 0, 1, 1, 0])[kind]
    fj = torch.tensor([-1, -1, 0, 1, 0, 1])[kind]
    out = (kind >= 1, kind >= 2, fi, fj, dc, uc, osign, state == 2, state == 1, sign)
    return w, tuple(x[None].expand(B, *x.shape) for x in out)


@torch.no_grad()
def derive(rules, config) -> None:
    """Re-derive the rules' strengths and firing counts from every cached pair (see the module's doc)."""
    rules.ensure_cache(config)
    B = rules.lived_outcome.shape[0]
    C, P = len(CONTEXTS), len(rules.properties)
    rc = config.rules
    n = rules.lived_count
    m = int(n.max()) if B else 0
    # each pair once (i < j), over the episodes lived so far: dims (B, N) per pair, (B, C, N) per context
    i, j = torch.triu_indices(m, m, 1)
    pairs = (j[None] < n[:, None])                                                           # (B, N)
    f = rules.lived_fate[:, :m]
    fi, fj = f[:, i], f[:, j]
    seen = pairs & (fi >= 0) & (fj >= 0)
    pick = lambda t: t[:, :m, :m][:, i, j]                                                   # noqa: E731
    w, (pairs, seen, fi, fj, r_dc, r_uc, r_os, changed, unclear, sign) = patterns(
        pairs, seen, fi, fj, pick(rules.pair_dc), pick(rules.pair_uc), pick(rules.pair_osign),
        pick(rules.pair_changed), pick(rules.pair_unclear), pick(rules.pair_sign))
    # from here a "pair" is one pattern of pairs, counted w (B, N) times in each agent: every judgment below is a
    # count over pairs (or whether there is one), so judging each pattern once gives the same counts
    contexts = "context" not in config.ablate
    if contexts:
        in_ctx = torch.stack([seen & (fi == 0) & (fj == 0), seen & (fi == 1) & (fj == 1), seen], 1)   # (B, C, N)
        dc = torch.stack([r_dc, r_dc, fi != fj], 1)
        uc = torch.stack([r_uc, r_uc, torch.zeros_like(r_uc)], 1)
        osign = torch.stack([r_os, r_os, (fi - fj).to(torch.int8)], 1)                       # i's over j's
    else:   # the "context" ablation: every pair judged on its reward, alike in all three
        in_ctx, dc = pairs[:, None].expand(-1, C, -1), r_dc[:, None].expand(-1, C, -1)
        uc, osign = r_uc[:, None].expand(-1, C, -1), r_os[:, None].expand(-1, C, -1)
    in_ctx = in_ctx & (w > 0)[:, None]
    w4 = w[:, None, :, None]

    def count(x):
        """(B, C, P) how many pairs x (B, C, N, P) holds."""
        return (x * w4).sum(2)
    changed, unclear = changed[:, None], unclear[:, None]                                    # (B, 1, N, P)
    clear_full = changed & ~unclear.any(-1, keepdim=True)
    signed_on = "signed" not in config.ablate
    tally = "tally" not in config.ablate
    ordered = (sign != 0)[:, None]
    agrees = (sign[:, None] * osign[..., None]) > 0                                          # (B, C, N, P)

    def judge(elim):
        """The pairs' judgments with `elim` (B, C, P) eliminated: (use, dp, clean) per context."""
        live = ~elim[:, :, None, :]
        un = unclear & live
        use = in_ctx & ~cannot_tell(un, dc, uc)
        if config.strict_comparisons:
            use &= ~un.any(-1)
        dp = changed & live & use[..., None]
        clean = dp.sum(-1) == 1
        return use, dp, clean

    def clean_for(use, dp):
        """(B, C, N, P) the pairs clean for each property as if its pathway were live: it changed, nothing else live
        did (for a live property, the pair is clean; for an eliminated one, what it would show at full strength)."""
        return changed & use[..., None] & ((dp.sum(-1, keepdim=True) - dp.long()) == 0)

    def eliminations(grown):
        """The least fixpoint of Elimination (reward contexts) given the grown properties, the fate's derived: a
        property goes when its clean held pairs are at least elim_pairs and at least elim_share of its clean pairs
        (held and moved, each judged as if it were live)."""
        elim = torch.zeros(B, C, P, dtype=torch.bool)
        for _ in range(C * P + 1):
            use, dp, clean = judge(elim)
            cp = clean_for(use, dp)
            n_held, n_moved = count(cp & (use & ~dc)[..., None]), count(cp & (use & dc)[..., None])
            if tally:
                cand = (n_held >= config.elim_pairs) & (n_held >= config.elim_share * (n_held + n_moved))
            else:   # one clean held pair is enough (the sequential rules' Elimination, replayed)
                cand = (dp & (use & ~dc & clean)[..., None]).any(2)                          # (B, C, P)
            new = (elim | cand) & ~grown
            if contexts:
                new[:, FATE] = elim[:, FLOATING] & elim[:, SINKING] & ~grown[:, FATE]
            if torch.equal(new, elim):
                break
            elim = new
        return elim

    grown = torch.zeros(B, C, P, dtype=torch.bool)
    for _ in range(C * P + 1):
        elim = eliminations(grown)
        use, dp, clean = judge(elim)
        moved = use & dc
        n_grow = count(dp & (moved & clean)[..., None])
        # an outcome nothing live explains: the one eliminated property that changed clearly, unless eliminated
        # everywhere
        nowhere = elim.all(1)[:, None, None, :]
        back = clear_full & elim[:, :, None, :] & ~nowhere & (moved & ~dp.any(-1))[..., None]
        back &= back.sum(-1, keepdim=True) == 1
        n_grow = n_grow + count(back)
        if signed_on:
            clear = changed & ~elim[:, :, None, :] & moved[..., None] & ordered
            n_clear, n_agree = count(clear), count(clear & agrees)
            n_grow = n_grow + ((n_clear >= config.signed_pairs) & (n_agree == n_clear)) * n_agree
        new = grown | (n_grow > 0)
        if torch.equal(new, grown):
            break
        grown = new
    undecided = ~elim & ~grown
    n_unc = count(~dp & ~elim[:, :, None, :] & moved[..., None]) * undecided
    # the held pairs where an eliminated property alone changed (it shows no change now: count it at full strength)
    n_elim = count(changed & (use & ~dc & ~dp.any(-1))[..., None]) * elim
    if contexts:
        n_elim[:, FATE] = elim[:, FATE].long()                            # the fate's: derived, counted once
    s = torch.ones(B, C, P)
    s = torch.where(undecided, (rc.uncertain_decay ** n_unc.float()).clamp(min=rc.uncertain_floor), s)
    s = torch.where(grown, (1.0 + rc.growth_step * n_grow.clamp(min=1).float()).clamp(max=rc.dominant_strength), s)
    s = torch.where(elim, torch.full_like(s, rc.eliminated_strength), s)
    rules.strength.copy_(s)
    fired = torch.zeros_like(rules.fired)
    fired[..., ELIMINATION] = n_elim.clamp(min=1) * elim
    fired[..., GROWTH] = n_grow * grown
    fired[..., UNCERTAINTY] = n_unc
    rules.fired.copy_(fired)
    rules._read_state()
