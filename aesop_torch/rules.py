"""The four learning rules (Elimination, Growth, Uncertainty, Status quo) and the causal knowledge they build.

The paper gives the rules as a truth table over two comparisons: DeltaProperty (a property map's bottom-up activity
differs from its top-down activity retro-activated from the recalled episode) and DeltaContradiction (the observed
reward differs from the expected one). It leaves open what happens when evidence conflicts across episodes; the
final knowledge must not depend on the order the objects came in, so knowledge here is the *strongest* kind of
evidence seen so far, under a fixed precedence, never the most recent:

    clean Growth  >  Elimination  >  ambiguous Growth  >  Uncertainty  >  nothing

- clean Growth: this property alone changed (besides properties already known to be irrelevant) and the outcome
  changed. That is an intervention on one variable with an
  effect, the strongest causal evidence there is: the property is *dominant*, and no later null result overturns it.
- Elimination: the property changed and the outcome did not: *irrelevant*. It overrides an ambiguous Growth, which
  is how a property judged dominant on confounded evidence ends irrelevant.
- ambiguous Growth: several properties changed at once and the outcome changed; each is provisionally *dominant*.
- Uncertainty: the outcome changed but this property did not: *likely irrelevant*, a certainty that grows with each
  firing towards 1 without reaching it.

The hub pathway strength of a property is a function of its knowledge (and, while undecided, of its Uncertainty
count), written into the hub's strength tensor in place. Deriving it from the knowledge, rather than multiplying it
episode after episode, keeps the final connectivity as order-independent as the knowledge itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

PROPERTIES = ("color", "shape", "size", "weight")
RULE_NAMES = ("S", "E", "G", "U")  # codes 0..3 in `CausalRules.apply`'s output
STATUS_QUO, ELIMINATION, GROWTH, UNCERTAINTY = range(4)
STATES = ("unknown", "likely_irrelevant", "dominant", "irrelevant")
UNKNOWN, LIKELY_IRRELEVANT, DOMINANT, IRRELEVANT = range(4)


@dataclass
class RulesConfig:
    # "drastically reduce": 5 % of the pathway is left, so the property barely moves the hub and no longer
    # retro-activates its map with any weight, yet the connection is not deleted (the paper reduces, not cuts).
    eliminated_strength: float = 0.05
    # "strengthen": a dominant pathway counts as much as the three other properties together at full strength,
    # so recall (and with it prediction) is led by the causal property.
    dominant_strength: float = 3.0
    # "marginally reduce": each Uncertainty firing keeps 85 % of an undecided pathway.
    uncertain_decay: float = 0.85
    # certainty of "likely irrelevant" after n Uncertainty firings: 1 - (1 - step)^n, i.e. 0.3, 0.51, 0.66, ...
    # grows with every firing and never reaches 1 on its own.
    certainty_step: float = 0.3
    # DeltaContradiction tolerance: |observed - expected| > max(abs, rel * expected). abs: the water level is read
    # to ~1 mm, which in a 12 cm jar is ~11 cm^3; rel: an expectation averaged over similar episodes is not exact,
    # and a 15 % miss is still "behaved as expected" while the paper's contradiction (365 vs 24 cm^3) is 93 %.
    contradiction_abs_cm3: float = 12.0
    contradiction_rel: float = 0.15


def contradiction(observed: torch.Tensor, expected: torch.Tensor, cfg: RulesConfig) -> torch.Tensor:
    """DeltaContradiction per agent; False where nothing was expected (NaN), since nothing can be contradicted."""
    tol = torch.clamp(cfg.contradiction_rel * expected.abs(), min=cfg.contradiction_abs_cm3)
    return ((observed - expected).abs() > tol) & ~torch.isnan(expected)


class CausalRules(nn.Module):
    """Applies E/G/U/S per property and keeps the causal knowledge; batched over agents (leading dim B)."""

    def __init__(self, config: RulesConfig | None = None, batch: int = 1, properties=PROPERTIES):
        super().__init__()
        self.config = config or RulesConfig()
        self.properties = tuple(properties)
        P = len(self.properties)
        self.register_buffer("state", torch.zeros(batch, P, dtype=torch.long))
        self.register_buffer("uncertain_count", torch.zeros(batch, P, dtype=torch.long))
        # dominance shown by a clean Growth: no later Elimination overturns it
        self.register_buffer("proven", torch.zeros(batch, P, dtype=torch.bool))

    @property
    def certainty(self) -> torch.Tensor:
        """0 unknown, 1 dominant or irrelevant, 1 - (1 - step)^n for likely irrelevant after n Uncertainty firings."""
        grown = 1.0 - (1.0 - self.config.certainty_step) ** self.uncertain_count.to(torch.float32)
        grown[self.state == UNKNOWN] = 0.0
        grown[(self.state == DOMINANT) | (self.state == IRRELEVANT)] = 1.0
        return grown

    @torch.no_grad()
    def apply(self, delta_p: torch.Tensor, delta_c: torch.Tensor, compared: torch.Tensor,
              strength: torch.Tensor | None = None) -> torch.Tensor:
        """One episode of rule application.

        delta_p: (B, P) bool, property changed (bottom-up vs top-down); delta_c: (B,) bool, outcome contradicted;
        compared: (B,) bool, the agent recalled an episode to compare with (no recall: no rule fires);
        strength: (B, P) hub pathway strengths to edit in place (optional).
        Returns the rule fired per agent and property, codes into RULE_NAMES.
        """
        dp = delta_p & compared[:, None]
        dc = (delta_c & compared)[:, None]
        undecided = (self.state == UNKNOWN) | (self.state == LIKELY_IRRELEVANT)
        fired = torch.full_like(self.state, STATUS_QUO)
        fired[dp & ~dc] = ELIMINATION
        fired[dp & dc] = GROWTH
        # Uncertainty only examines undecided properties: for a decided one "no change, yet a contradiction" says
        # nothing new (the contradiction is explained elsewhere).
        fired[~dp & dc & undecided] = UNCERTAINTY

        # clean: the only change among properties not already known to be irrelevant (a known-irrelevant change
        # does not confound), or the only change at all (then the earlier Elimination was wrong)
        suspects = dp & (self.state != IRRELEVANT)
        n_suspects = suspects.sum(-1, keepdim=True)
        alone = (suspects & (n_suspects == 1)) | ((n_suspects == 0) & (dp.sum(-1, keepdim=True) == 1))
        clean = (fired == GROWTH) & alone
        proven = self.proven
        new = self.state.clone()
        # Precedence: clean Growth > Elimination > ambiguous Growth > Uncertainty > unknown.
        u = fired == UNCERTAINTY
        self.uncertain_count += u.long()
        new[u & undecided] = LIKELY_IRRELEVANT
        ambiguous = (fired == GROWTH) & ~clean & (self.state != IRRELEVANT)
        new[ambiguous & ~proven] = DOMINANT
        new[(fired == ELIMINATION) & ~proven] = IRRELEVANT
        new[clean] = DOMINANT
        self.proven |= clean
        self.state.copy_(new)
        if strength is not None:
            strength.copy_(self.strength_from_knowledge(strength.dtype))
        return fired

    def strength_from_knowledge(self, dtype=torch.float32) -> torch.Tensor:
        c = self.config
        s = c.uncertain_decay ** self.uncertain_count.to(dtype)
        s = torch.where(self.state == DOMINANT, torch.full_like(s, c.dominant_strength), s)
        return torch.where(self.state == IRRELEVANT, torch.full_like(s, c.eliminated_strength), s)

    def knowledge(self, b: int = 0) -> dict:
        """Agent b's causal knowledge in the summary.json form: {property: {"state", "certainty"}}."""
        cert = self.certainty[b]
        return {p: {"state": STATES[int(self.state[b, i])], "certainty": round(float(cert[i]), 4)}
                for i, p in enumerate(self.properties)}
