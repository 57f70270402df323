"""The paper's learning rules as the paper states them: each firing edits a pathway's strength in place.

`CausalRules` (rules.py, the extended model) keeps every comparison as evidence and derives the knowledge from the
whole set. Here nothing is kept but the strengths and how often each rule fired; the knowledge is read from them:

- Elimination (the property changed, the outcome did not): "drastically reduce" - the strength drops to
  `RulesConfig.eliminated_strength`, below the floor at which a pathway still retro-activates its map
  (AgentConfig.retro_floor). An eliminated property shows no change in later comparisons, so no rule fires on it
  again: elimination is final.
- Growth (the property changed and so did the outcome): "strengthen" - the strength grows by `growth_step`, up to
  `dominant_strength`.
- Uncertainty (the outcome changed, the property did not): "marginally reduce" - an undecided pathway keeps
  `uncertain_decay` of its strength, never below `uncertain_floor`.
- Status quo: nothing.

The paper leaves open what a comparison in which several properties changed at once says. Here it says nothing about
the changed ones: neither Elimination nor Growth can tell which change did it (two changes can cancel, larger but
lighter; one can hide behind another), so a rule that attributes, E or G, fires only on a clean comparison, one
property changed among those the pathways still show (Uncertainty, on an unchanged property, needs no attribution).
Which comparisons are clean depends on what was eliminated before, so this model's knowledge can depend on the order
the objects came in: that is measured (benches/ablation.py), not built away.

Knowledge per property, read from the strengths and the counts: irrelevant at or below the retro-activation floor,
dominant above the initial strength (it grew more than it shrank), likely irrelevant once Uncertainty fired, else
unknown. Certainty: 1 for dominant and irrelevant, 1 - (1 - certainty_step)^n after n Uncertainty firings.
"""

from __future__ import annotations

import torch
from torch import nn

from .rules import (CONTEXTS, DOMINANT, ELIMINATION, GROWTH, IRRELEVANT, LIKELY_IRRELEVANT, PROPERTIES, STATES,
                    STATUS_QUO, UNCERTAINTY, UNKNOWN, RulesConfig)


def edited(s: torch.Tensor, fired: torch.Tensor, c: RulesConfig) -> torch.Tensor:
    """The strengths s after the firings `fired` (codes into RULE_NAMES, s's shape): Elimination drops a pathway to
    the eliminated strength, Growth adds a step (up to the dominant strength), Uncertainty keeps `uncertain_decay` of
    it (never below the floor, never raising it). Shared with contextual_rules.py, which keeps s per context."""
    s = torch.where(fired == ELIMINATION, s.clamp(max=c.eliminated_strength), s)
    s = torch.where(fired == GROWTH, (s + c.growth_step).clamp(max=c.dominant_strength), s)
    return torch.where(fired == UNCERTAINTY, (s * c.uncertain_decay).clamp(min=c.uncertain_floor).minimum(s), s)


def states_of(s: torch.Tensor, uncertain: torch.Tensor, retro_floor: float) -> torch.Tensor:
    """Knowledge codes (STATES) read from strengths s and Uncertainty counts of s's shape: irrelevant at or below
    the retro-activation floor, dominant above 1, likely irrelevant once Uncertainty fired, else unknown."""
    state = torch.full(s.shape, UNKNOWN, dtype=torch.long, device=s.device)
    state[uncertain > 0] = LIKELY_IRRELEVANT
    state[s > 1.0] = DOMINANT
    state[s <= retro_floor] = IRRELEVANT
    return state


def certainties_of(state: torch.Tensor, uncertain: torch.Tensor, step: float) -> torch.Tensor:
    """Certainty of each state: 1 dominant or irrelevant, 0 unknown, 1 - (1 - step)^n after n Uncertainty firings."""
    grown = 1.0 - (1.0 - step) ** uncertain.to(torch.float32)
    grown[state == UNKNOWN] = 0.0
    grown[(state == DOMINANT) | (state == IRRELEVANT)] = 1.0
    return grown


class IncrementalRules(nn.Module):
    """E/G/U/S applied one comparison at a time to per-property pathway strengths; batched over agents (dim B).

    buffers: strength (B, P) the pathways' strengths (init 1), fired (B, P, 4) how often each rule fired (codes
    into rules.RULE_NAMES), state (B, P) the knowledge read from them (codes into rules.STATES)."""

    def __init__(self, config: RulesConfig | None = None, batch: int = 1, properties=PROPERTIES,
                 retro_floor: float = 0.1):
        super().__init__()
        self.config = config or RulesConfig()
        self.properties = tuple(properties)
        self.retro_floor = retro_floor
        P = len(self.properties)
        self.register_buffer("strength", torch.ones(batch, P))
        self.register_buffer("fired", torch.zeros(batch, P, 4, dtype=torch.long))
        self.register_buffer("state", torch.zeros(batch, P, dtype=torch.long))

    @property
    def certainty(self) -> torch.Tensor:
        return certainties_of(self.state, self.fired[..., UNCERTAINTY], self.config.certainty_step)

    # the extended model's per-context views, for code that reads either model: one context holds for all
    @property
    def eliminated(self) -> torch.Tensor:
        return (self.state == IRRELEVANT)[:, None].expand(-1, len(CONTEXTS), -1)

    @property
    def dominant(self) -> torch.Tensor:
        return (self.state == DOMINANT)[:, None].expand(-1, len(CONTEXTS), -1)

    @property
    def confounded(self) -> torch.Tensor:
        """(B, P) all False: here Growth fires only on a clean comparison, so no dominance rests on a confound."""
        return torch.zeros_like(self.state, dtype=torch.bool)

    def context_strength(self, dtype=torch.float32) -> torch.Tensor:
        return self.strength.to(dtype)[:, None].expand(-1, len(CONTEXTS), -1)

    def strength_from_knowledge(self, dtype=torch.float32) -> torch.Tensor:
        return self.strength.to(dtype)

    @torch.no_grad()
    def apply(self, delta_p: torch.Tensor, delta_c: torch.Tensor, compared: torch.Tensor,
              strength: torch.Tensor | None = None, context: torch.Tensor | None = None) -> torch.Tensor:
        """One comparison per agent. delta_p (B, P) bool: the property changed (as the pathway shows it: an
        eliminated pathway shows none); delta_c (B,) bool: the outcome contradicted the recalled one; compared (B,):
        the agent had an episode to compare with. strength (B, P), optional: the hub's pathway strengths, rewritten
        with the new ones. context is accepted for the extended model's signature and ignored. Returns the rule
        fired per agent and property (codes into RULE_NAMES)."""
        c = self.config
        live = self.strength > self.retro_floor
        dp = delta_p & compared[:, None] & live
        dc = (delta_c & compared)[:, None]
        clean = dp.sum(-1, keepdim=True) == 1
        undecided = live & (self.strength <= 1.0)
        fired = torch.full_like(self.state, STATUS_QUO)
        fired[dp & ~dc & clean] = ELIMINATION
        fired[dp & dc & clean] = GROWTH
        fired[~dp & dc & undecided] = UNCERTAINTY
        self.strength.copy_(edited(self.strength, fired, c))
        self.fired.scatter_add_(2, fired[..., None], torch.ones_like(fired[..., None]))
        self._read_state()
        if strength is not None:
            strength.copy_(self.strength.to(strength.dtype))
        return fired

    def _read_state(self) -> None:
        self.state.copy_(states_of(self.strength, self.fired[..., UNCERTAINTY], self.retro_floor))

    def knowledge(self, b: int = 0) -> dict:
        cert = self.certainty[b]
        return {p: {"state": STATES[int(self.state[b, i])], "certainty": round(float(cert[i]), 4)}
                for i, p in enumerate(self.properties)}

    def by_context(self, b: int = 0) -> dict:
        """The same lists in every context: this model has none."""
        one = {"dominant": [p for i, p in enumerate(self.properties) if self.state[b, i] == DOMINANT],
               "irrelevant": [p for i, p in enumerate(self.properties) if self.state[b, i] == IRRELEVANT]}
        return {k: dict(one) for k in CONTEXTS}
