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

from .fitted_readout import readout_features
from .rules import STATUS_QUO, context_of, contradiction, outcome_unclear


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
    x, xk = readout_features(values, config.encoder)[:, None], readout_features(recalled, config.encoder)
    gaps = {"color": (values["color"][:, None] - recalled["color"]).norm(dim=-1),
            "shape": (values["shape"][:, None] - recalled["shape"]).norm(dim=-1),
            "size": (x[..., 4] - xk[..., 4]).abs(), "weight": (x[..., 5] - xk[..., 5]).abs()}
    # a context property (EncoderConfig.context): its decoded value in 0..1, as its map reads it
    gaps.update({p: (values[p][:, None] - recalled[p]).norm(dim=-1) for p in config.encoder.context})
    noise = 3.0 * config.felt_mass_noise_g / torch.minimum(x[..., 5], xk[..., 5]).exp()
    changed, unclear = [], []
    for i, p in enumerate(config.properties):
        lo, hi = config.delta_p_band[i]
        if p == "weight":
            lo, hi = lo + noise / 3, hi + noise   # unchanged within 1 sigma of the felt mass, changed beyond 3
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


def compare(a, stored: torch.Tensor, fate: torch.Tensor, learn: torch.Tensor, config, rules,
            strength: torch.Tensor) -> Comparisons:
    """Compare the present episode with its recalled ones and apply the rules to each comparison in turn.

    a: the agent's Anticipation of the present object; stored (B, 1): the observed outcome as the memory will hold
    it (through the reward code); fate (B,) long: 0 floated, 1 sank, -1 not seen; learn (B,) bool: agents that take
    part; rules: the agent's rules (edited in place); strength (B, P): the property pathways' strengths."""
    recall = a.recall
    B = fate.shape[0]
    compared = recall.valid & learn[:, None]                                   # (B, K)
    if config.compare_with is not None:
        compared[:, config.compare_with:] = False
    K = compared.shape[1]
    context = context_of(fate[:, None].expand(B, K), a.fates)                  # (B, K)
    # the outcome as the memory will hold it, against the outcomes it holds: both read through the reward code
    delta_c = contradiction(stored, a.rewards, config.rules) & compared
    unclear_c = outcome_unclear(stored, a.rewards, config.rules)
    P = rules.state.shape[1]
    fired = torch.full((B, K, P), STATUS_QUO, dtype=rules.state.dtype, device=compared.device)
    delta_p = torch.zeros(B, K, P, dtype=torch.bool, device=compared.device)
    skipped = torch.zeros_like(compared)
    # recalls come strongest first, the valid ones before the rest: past the most any agent compared with, a
    # slot compares nothing and fires no rule (its comparisons are left out, not run; unbounded, K = the slots
    # of a whole memory)
    used = max(1, int(compared.sum(1).max()))
    for k in range(used):
        # each comparison sees the pathways as they are in its context, after the comparisons before it
        gate = rules.context_strength()[torch.arange(B), context[:, k]]
        dp, unclear = delta_property(a.values, {p: v[:, k:k + 1] for p, v in a.recalled_values.items()}, config,
                                     gate[:, None])
        use = compared[:, k] & ~cannot_tell(unclear[:, 0], delta_c[:, k], unclear_c[:, k])
        delta_p[:, k] = dp = dp[:, 0] & use[:, None]
        skipped[:, k] = compared[:, k] & ~use
        if "rules" not in config.ablate:
            fired[:, k] = rules.apply(dp, delta_c[:, k] & use, use, strength=strength, context=context[:, k])
    return Comparisons(delta_p, delta_c, unclear_c, fired, skipped)


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
