"""How the present episode is compared with recalled ones, for the rules: DeltaProperty and DeltaContradiction.

Which recalled episodes the rules compare against: the strongest (paper), each of them (extended;
AgentConfig.compare_with). Every compared episode is one comparison, with DeltaProperty (the property's decoded
bottom-up value against the value that episode retro-activates, through the pathway's strength in the comparison's
context: an eliminated pathway retro-activates nothing, so it shows no change) and DeltaContradiction (the observed
volume against that episode's) judged against the same past event. A comparison that cannot tell (a property or the
outcome in its dead zone, `cannot_tell`) is left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from .fitted_readout import log_mass, log_size
from .rules import STATUS_QUO, context_of, contradiction, outcome_unclear

# the contextual model's contexts (contextual_rules.ContextualRules keeps a set of strengths for each): what decides
# the reward among floaters, among sinkers, and what decides the fate. Here, below the rules and replay that use them
CONTEXTS = ("floating", "sinking", "fate")
FLOATING, SINKING, FATE = range(3)


def cannot_tell(unclear: torch.Tensor, contradicted: torch.Tensor, outcome_unclear: torch.Tensor) -> torch.Tensor:
    """A comparison left out (the agent's and the batch answer's alike): the outcome in its dead zone, or a
    contradiction that a property in its dead zone (unclear (..., P)) may have caused. Where the outcome held, such a
    property did not change it: the properties that clearly changed still did nothing (generated sets of seeds
    1000-1099: colour dominant in 0 sets instead of 12, when the felt mass of light colour twins fell in weight's dead
    zone)."""
    return (unclear.any(-1) & contradicted) | outcome_unclear


def delta_property(values: dict, recalled: dict, config, strength: torch.Tensor | None = None
                   ) -> tuple[torch.Tensor, torch.Tensor]:
    """DeltaProperty: does a property's decoded bottom-up value (values[p]: (B, dim)) differ from the value each
    recalled episode retro-activates (recalled[p]: (B, K, dim))? Returns (changed, unclear), both (B, K, P)
    bool, P the judged properties (AgentConfig.properties: the object's, then the context's, each as far as its
    decoded value moved): changed beyond the property's band, or inside it (config: the AgentConfig, its
    delta_p_band, felt mass noise and retro_floor). strength (B, K, P): the
    pathway's strength for each comparison (default 1); at or below `retro_floor` the pathway retro-activates
    nothing, so there is nothing to differ from (neither changed nor unclear)."""
    enc = config.encoder
    size, size_k = log_size(values, enc)[:, None], log_size(recalled, enc)
    mass, mass_k = log_mass(values, enc)[:, None], log_mass(recalled, enc)
    gaps = {"size": (size - size_k).abs(), "weight": (mass - mass_k).abs()}
    # colour as RGB distance, shape and elongation as the distance of their values, fill as |log ratio| (volume
    # is proportional to it), a context property (EncoderConfig.context) as its decoded value in 0..1 moved
    for p in ("color", "shape", "elongation", *enc.context):
        if p in values:
            gaps[p] = (values[p][:, None] - recalled[p]).norm(dim=-1)
    if "fill" in values:
        gaps["fill"] = (values["fill"][:, None, 0].clamp_min(1e-3).log()
                        - recalled["fill"][..., 0].clamp_min(1e-3).log()).abs()
    noise = 3.0 * config.felt_mass_noise_g / torch.minimum(mass, mass_k).exp()
    changed, unclear = [], []
    for i, p in enumerate(config.properties):
        lo, hi = config.delta_p_band[i]
        if p == "weight":
            # unchanged within weight_unchanged_sigmas sigma of the felt mass, changed beyond 3
            lo, hi = (lo + config.weight_unchanged_sigmas * noise / 3).clamp_min(0.0), hi + noise
        gap = torch.nan_to_num(gaps[p], nan=0.0)
        changed.append(gap > hi)
        unclear.append((gap > lo) & (gap <= hi))
    changed, unclear = torch.stack(changed, -1), torch.stack(unclear, -1)
    if strength is not None:
        live = strength > config.retro_floor
        changed, unclear = changed & live, unclear & live
    return changed, unclear


@dataclass
class Comparisons:
    """The present episode against its recalled ones (leading dims B, K: strongest recall first)."""
    delta_p: torch.Tensor    # (B, K, P) bool: DeltaProperty, False in a comparison left out
    delta_c: torch.Tensor    # (B, K) bool: DeltaContradiction, for every compared episode
    unclear_c: torch.Tensor  # (B, K) bool: the outcome in its dead zone against that episode's
    fired: torch.Tensor      # (B, K, P) the rule each comparison fired (rules.RULE_NAMES codes)
    skipped: torch.Tensor    # (B, K) bool: compared but left out (`cannot_tell`)
    compared: torch.Tensor   # (B, K) bool: compared (valid, learning, within compare_with and compare_floor)


def judgments(config, fate: torch.Tensor, fates_k: torch.Tensor, stored: torch.Tensor, reward_k: torch.Tensor
              ) -> list[tuple]:
    """What one comparison (the present, fate (B,), against a recalled episode, fates_k (B,)) is judged on: a list
    of (context (B,) long or None, delta_c (B,), unclear_c (B,), applies (B,)), one per set of pathways it teaches.

    incremental and evidence rules: one, the reward, in the comparison's context (rules.context_of: both floated,
    both sank, or mixed). contextual rules (contextual_rules.py): the fate, on every comparison whose fates were
    both seen (its outcome is whether the fate differs, which cannot be unclear), and the reward, in the fate, on
    those whose fates were the same; with contexts off (the "context" ablation) only the reward, in every context
    at once (None)."""
    delta_c = contradiction(stored, reward_k, config.rules)
    unclear_c = outcome_unclear(stored, reward_k, config.rules)
    if config.learning != "contextual":
        return [(context_of(fate, fates_k), delta_c, unclear_c, torch.ones_like(delta_c))]
    if "context" in config.ablate:
        return [(None, delta_c, unclear_c, torch.ones_like(delta_c))]
    seen = (fate >= 0) & (fates_k >= 0)
    return [(torch.full_like(fate, FATE), fate != fates_k, torch.zeros_like(seen), seen),
            (fate.clamp(min=0), delta_c, unclear_c, seen & (fate == fates_k))]


def compare(a, stored: torch.Tensor, fate: torch.Tensor, learn: torch.Tensor, config, rules,
            strength: torch.Tensor) -> Comparisons:
    """Compare the present episode with its recalled ones and apply the rules to each comparison in turn.

    a: the agent's Anticipation of the present object; stored (B, 1): the observed outcome as the memory will hold
    it (through the reward code); fate (B,) long: 0 floated, 1 sank, -1 not seen; learn (B,) bool: agents that take
    part; rules: the agent's rules (edited in place); strength (B, P): the property pathways' strengths.
    Which recalled episodes: the strongest config.compare_with of them (None: all), each recalled at least
    config.compare_floor strongly (the contextual rules'; 0 for the others)."""
    recall = a.recall
    B = fate.shape[0]
    compared = recall.valid & learn[:, None]                                   # (B, K)
    if config.compare_with is not None:
        compared[:, config.compare_with:] = False
    if config.learning == "contextual":
        compared &= recall.strength >= config.compare_floor
    K = compared.shape[1]
    P = rules.state.shape[1]
    fired = torch.full((B, K, P), STATUS_QUO, dtype=rules.state.dtype, device=compared.device)
    delta_p = torch.zeros(B, K, P, dtype=torch.bool, device=compared.device)
    delta_c = torch.zeros(B, K, dtype=torch.bool, device=compared.device)
    unclear_out = torch.zeros_like(delta_c)
    skipped = torch.zeros_like(compared)
    rank = torch.tensor([0, 3, 2, 1], device=compared.device)                  # S < U < G < E
    regrow = config.learning == "contextual"
    rows = torch.arange(B, device=compared.device)
    # recalls come strongest first, the valid ones before the rest: past the most any agent compared with, a
    # slot compares nothing and fires no rule (its comparisons are left out, not run; unbounded, K = the slots
    # of a whole memory)
    used = max(1, int(compared.sum(1).max()))
    for k in range(used):
        # what changed at full strength: what each context's pathways show of it, and (contextual) what may grow an
        # eliminated pathway back
        full, full_unclear = delta_property(a.values, {p: v[:, k:k + 1] for p, v in a.recalled_values.items()},
                                            config)
        full, full_unclear = full[:, 0], full_unclear[:, 0]
        if regrow:
            bottom_up = full & ~full_unclear.any(-1, keepdim=True)
        for ctx, dc, unclear_c, applies in judgments(config, fate, a.fates[:, k], stored[:, 0], a.rewards[:, k]):
            # each comparison sees the pathways as they are in its context, after the comparisons before it: an
            # eliminated one (at or below the retro-activation floor) shows no change (delta_property's gate)
            cs = rules.context_strength()
            live = (cs[rows, ctx] if ctx is not None else cs[:, 0]) > config.retro_floor
            unclear = full_unclear & live
            on = compared[:, k] & applies
            use = on & ~cannot_tell(unclear, dc, unclear_c)
            if config.strict_comparisons:   # a property in its dead zone may have cancelled a change
                use &= ~unclear.any(-1)
            dp = full & live & use[:, None]
            delta_p[:, k] |= dp
            delta_c[:, k] |= dc & on
            unclear_out[:, k] |= unclear_c & on
            skipped[:, k] |= on & ~use
            if "rules" not in config.ablate:
                kw = {"bottom_up": bottom_up & use[:, None]} if regrow else {}
                f = rules.apply(dp, dc & use, use, strength=strength, context=ctx, **kw)
                fired[:, k] = torch.where(rank[f] > rank[fired[:, k]], f, fired[:, k])
    return Comparisons(delta_p, delta_c, unclear_out, fired, skipped, compared)


def pairwise(values: dict, observed: torch.Tensor, sank: torch.Tensor, config
             ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Every pair of n episodes compared at full strength, as `rules.batch_knowledge` reads them: values, the n
    objects' decoded values; observed (n,), their outcomes as the memory holds them (through the reward code).
    Returns (delta_p (n, n, P), delta_c (n, n), context (n, n)), episode j against episode i at [i, j]. A pair that
    cannot tell shows no change and no contradiction, as the agent leaves such a comparison out."""
    n = observed.shape[0]
    dp, unclear = delta_property(values, {p: v[None].expand(n, n, -1) for p, v in values.items()}, config)
    dp, unclear = dp.transpose(0, 1), unclear.transpose(0, 1)                 # [i, j]: j against i
    dc = contradiction(observed[None, :], observed[:, None], config.rules)
    skip = cannot_tell(unclear, dc, outcome_unclear(observed[None, :], observed[:, None], config.rules))
    fate = torch.as_tensor(sank).long()
    context = context_of(fate[:, None].expand(n, n), fate[None, :].expand(n, n))
    return dp & ~skip[..., None], dc & ~skip, context
