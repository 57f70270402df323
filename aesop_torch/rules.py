"""The four learning rules (Elimination, Growth, Uncertainty, Status quo) and the causal knowledge they build.

The paper gives the rules as a truth table over two comparisons of the present with a recalled past episode:
DeltaProperty (a property map's bottom-up activity differs from the activity the episode retro-activates) and
DeltaContradiction (the observed reward differs from the episode's). It leaves open what happens when evidence
conflicts across episodes, and when several properties change at once. Here every comparison is kept as evidence
and the knowledge is a function of the evidence *set*, so it cannot depend on the order the evidence came in (but
for the withdrawal of a context's eliminations below):

- Contexts. A sinker displaces its volume and a floater its weight, so whether a property matters depends on the
  regime: size and shape decide a sinker's displacement and not a floater's, weight the other way round. The robot
  sees what became of each object (it floats, or it rests on the bottom), and each comparison is evidence in its
  context: both floated, both sank, or one of each (`CONTEXTS`).
- Elimination (the property changed, the outcome did not): the property does not matter in this context, when it
  alone changed (besides properties already eliminated there; several changes at once may cancel), unless it also
  changed alone while the outcome moved (a clean Growth outweighs it: that change may have been too small to
  show). Its pathway no longer retro-activates in this context, so later comparisons there no longer see it
  change. An outcome that then moves while nothing the context still sees changed shows that an eliminated
  property mattered after all (a held comparison can hide a change that another cancelled: larger but hollower,
  with the size change in its dead zone): the context's held comparisons are forgotten, its pathways
  retro-activate again, and what they show is judged afresh. This is the one place where the evidence is not
  simply kept, so the order can matter. It fires only on an outcome that nothing seen explains: after a wrong
  elimination, or where changes each too small to be called one add up.
- Growth (the outcome changed, and so did the properties in its change set): at least one of the changed
  properties matters. One changed property is the paper's clean case; several at once are a confound.
- Dominant in a context: the properties of the minimal explanations. An explanation is a set of properties, none
  eliminated in the context (nor, unless the context's evidence needs it, in another), that holds a changed
  property of every contradicted comparison (a hitting set of the change sets); the minimal ones are those that
  leave the fewest held comparisons unexplained (a comparison whose change set holds a cause, yet the outcome
  held), then the smallest: colour changes in every pair of random objects, and only the pairs where it changed
  and the outcome held tell it from weight. In the mixed context, a property eliminated for floaters and for
  sinkers alike cannot explain a floater against a sinker, and of its minimal explanations it keeps those with the
  fewest properties dominant for neither floaters nor sinkers (the two differ by what matters for one of them).
  A clean Growth forces its property in; a confound is resolved by the rest of the evidence (colour changed
  together with weight is explained by weight once weight explains the other contradictions), and a confound
  nothing resolves makes each candidate dominant.
- Knowledge per property, over contexts: dominant if dominant in some context; else irrelevant if eliminated in
  some context; else likely irrelevant if Uncertainty fired (the outcome changed while it did not), with a
  certainty that grows with each firing without reaching 1; else unknown.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from .names import PROPERTIES, STATES  # torch-free (aesop_torch/names.py)

RULE_NAMES = ("S", "E", "G", "U")  # codes 0..3 in `CausalRules.apply`'s output
STATUS_QUO, ELIMINATION, GROWTH, UNCERTAINTY = range(4)
KNOWLEDGE_LETTERS = "ULDI"   # one letter per STATES code, in its order: a knowledge key such as "IDUU"
UNKNOWN, LIKELY_IRRELEVANT, DOMINANT, IRRELEVANT = range(4)
CONTEXTS = ("floating", "sinking", "mixed")   # both floated, both sank, one of each (or a fate not seen)
FLOATING, SINKING, MIXED = range(3)


def context_of(fate_a: torch.Tensor, fate_b: torch.Tensor) -> torch.Tensor:
    """Fates (0 floated, 1 sank, -1 not seen) of the two episodes compared -> the comparison's context code."""
    same = (fate_a == fate_b) & (fate_a >= 0)
    return torch.where(same, fate_a.clamp(min=0), torch.full_like(fate_a, MIXED))


@dataclass
class RulesConfig:
    # "drastically reduce": 5 % of the pathway is left, so the property barely moves the hub and no longer
    # retro-activates its map with any weight, yet the connection is not deleted (the paper reduces, not cuts).
    eliminated_strength: float = 0.05
    # "strengthen": a dominant pathway counts as much as the three other properties together at full strength,
    # so recall (and with it prediction) is led by the causal property.
    dominant_strength: float = 3.0
    # the paper model's Growth (incremental_rules.py): each clean firing adds this to the pathway, up to
    # dominant_strength. 1.0: one Growth makes a property dominant (2x), two take it to the cap, so a pathway a later
    # Elimination reduces was not built on one confound alone.
    growth_step: float = 1.0
    # "marginally reduce": each Uncertainty firing keeps 85 % of an undecided pathway.
    uncertain_decay: float = 0.85
    # ... but never below this: Uncertainty cannot tell whether the property matters ("unless further experience is
    # gained"), so its pathway keeps retro-activating (above AgentConfig.retro_floor, unlike an eliminated one) and
    # a later change in it is still seen. Each recalled episode is one comparison, so a long life fires it hundreds
    # of times (108 times for shape in 26 episodes on tuning seed 1055; 0.85^108 = 2e-8, and then a size change
    # that shape's change offset, larger but hollower, eliminated size for sinkers). 0.25 does as well (tuning seeds).
    uncertain_floor: float = 0.5
    # certainty of "likely irrelevant" after n Uncertainty firings: 1 - (1 - step)^n, i.e. 0.3, 0.51, 0.66, ...
    # grows with every firing and never reaches 1 on its own.
    certainty_step: float = 0.3
    # DeltaContradiction, with a dead zone between "as expected" and "contradicted": a comparison whose outcome falls
    # between them says nothing and is left out. As expected: within max(same_abs, same_rel x the larger of the
    # observed and the expected outcome, so that a against b reads as b against a); the level
    # is read to 0.01 mm (0.1 cm^3 in a 12 cm jar) and the simulated water settles within ~0.5 % of Archimedes.
    # Contradicted: off by more than max(abs, rel x the larger). The zone keeps the rules from reading a property's
    # change below what the maps can see as a change of outcome, and the reverse (AgentConfig.delta_p_band): a mass
    # or size change the maps call a change moves a displacement by more than 20 %, one they call no change by less
    # than 5 %, in every context; the paper's contradiction (365 vs 24 cm^3) is 93 %.
    same_abs_cm3: float = 1.0
    same_rel: float = 0.05
    contradiction_abs_cm3: float = 3.0
    contradiction_rel: float = 0.2


def _scale(observed: torch.Tensor, expected: torch.Tensor) -> torch.Tensor:
    """The relative tolerances' base: the larger of the two outcomes, so that comparing a with b reads the same as
    comparing b with a (which of two objects came first cannot change what their comparison says)."""
    return torch.maximum(observed.abs(), expected.abs())


def contradiction(observed: torch.Tensor, expected: torch.Tensor, cfg: RulesConfig) -> torch.Tensor:
    """DeltaContradiction per agent; False where nothing was expected (NaN), since nothing can be contradicted."""
    tol = torch.clamp(cfg.contradiction_rel * _scale(observed, expected), min=cfg.contradiction_abs_cm3)
    return ((observed - expected).abs() > tol) & ~torch.isnan(expected)


def outcome_unclear(observed: torch.Tensor, expected: torch.Tensor, cfg: RulesConfig) -> torch.Tensor:
    """True where the outcome is neither as expected nor contradicted (the dead zone between the two tolerances)."""
    same = torch.clamp(cfg.same_rel * _scale(observed, expected), min=cfg.same_abs_cm3)
    return ((observed - expected).abs() > same) & ~contradiction(observed, expected, cfg) & ~torch.isnan(expected)


class CausalRules(nn.Module):
    """Applies E/G/U/S per property and keeps the evidence and the causal knowledge; batched over agents (dim B).

    buffers: the evidence, held (B, C, 2^P) and contradicted (B, C, 2^P) bool, the change sets (bit p: property p
    changed) of the comparisons seen in context c whose outcome was as expected / contradicted, and
    uncertain_count (B, P); and, derived from them after every `apply`, eliminated (B, C, P), dominant (B, C, P)
    and state (B, P) (codes into STATES).
    """

    def __init__(self, config: RulesConfig | None = None, batch: int = 1, properties=PROPERTIES):
        super().__init__()
        self.config = config or RulesConfig()
        self.properties = tuple(properties)
        P, C = len(self.properties), len(CONTEXTS)
        if P > 8:
            raise ValueError(f"at most 8 properties (change sets are enumerated), got {P}")
        self.register_buffer("held", torch.zeros(batch, C, 2 ** P, dtype=torch.bool))
        self.register_buffer("contradicted", torch.zeros(batch, C, 2 ** P, dtype=torch.bool))
        self.register_buffer("eliminated", torch.zeros(batch, C, P, dtype=torch.bool))
        self.register_buffer("uncertain_count", torch.zeros(batch, P, dtype=torch.long))
        self.register_buffer("dominant", torch.zeros(batch, C, P, dtype=torch.bool))
        self.register_buffer("state", torch.zeros(batch, P, dtype=torch.long))
        subsets = torch.arange(2 ** P)
        bits = (subsets[:, None] >> torch.arange(P)) & 1                       # (2^P, P)
        self.register_buffer("_bits", bits.bool(), persistent=False)
        self.register_buffer("_weights", 1 << torch.arange(P), persistent=False)
        self.register_buffer("_hits", (subsets[:, None] & subsets[None, :]) != 0, persistent=False)
        self.register_buffer("_size", bits.sum(-1), persistent=False)

    @property
    def certainty(self) -> torch.Tensor:
        """0 unknown, 1 dominant or irrelevant, 1 - (1 - step)^n for likely irrelevant after n Uncertainty firings."""
        grown = 1.0 - (1.0 - self.config.certainty_step) ** self.uncertain_count.to(torch.float32)
        grown[self.state == UNKNOWN] = 0.0
        grown[(self.state == DOMINANT) | (self.state == IRRELEVANT)] = 1.0
        return grown

    @torch.no_grad()
    def apply(self, delta_p: torch.Tensor, delta_c: torch.Tensor, compared: torch.Tensor,
              strength: torch.Tensor | None = None, context: torch.Tensor | None = None) -> torch.Tensor:
        """One comparison per agent: its evidence joins the agent's, and the knowledge is derived again.

        delta_p: (B, P) bool, property changed (bottom-up vs top-down); delta_c: (B,) bool, outcome contradicted;
        compared: (B,) bool, the agent recalled an episode to compare with (no recall: no rule fires);
        strength: (B, P) hub pathway strengths to rewrite from the knowledge (optional); context: (B,) long codes
        into CONTEXTS (default MIXED, e.g. when the fates are not seen). A property eliminated in the context does
        not retro-activate there, so it shows no change. Returns the rule fired per agent and property, codes into
        RULE_NAMES (Uncertainty is reported only for an undecided property; its evidence is counted always)."""
        B, P = self.state.shape
        ctx = torch.full((B,), MIXED, dtype=torch.long, device=self.state.device) if context is None else context
        rows = torch.arange(B, device=ctx.device)
        dp = delta_p & compared[:, None] & ~self.eliminated[rows, ctx]
        dc = (delta_c & compared)[:, None]
        fired = torch.full_like(self.state, STATUS_QUO)
        fired[dp & ~dc] = ELIMINATION
        fired[dp & dc] = GROWTH
        undecided = (self.state == UNKNOWN) | (self.state == LIKELY_IRRELEVANT)
        fired[~dp & dc & undecided] = UNCERTAINTY
        # the evidence keeps the whole change set: what is eliminated is decided from all of it (see _derive), and
        # a property eliminated now may not be once a clean Growth shows up
        raw = delta_p & compared[:, None]
        changed = (raw.long() * self._weights).sum(-1)                              # the change set's index
        # the outcome moved while nothing the context still sees changed: a property eliminated there mattered after
        # all (its change was hidden by another's: larger but hollower). The held comparisons that eliminated it
        # are forgotten, so its pathways retro-activate there again and what they show is judged afresh
        hidden = dc[:, 0] & ~raw.any(-1) & self.eliminated[rows, ctx].any(-1)
        self.held[rows[hidden], ctx[hidden]] = False
        self.held[rows, ctx, changed] |= ~dc[:, 0] & raw.any(-1)
        self.contradicted[rows, ctx, changed] |= dc[:, 0] & raw.any(-1)
        self.uncertain_count += (~dp & dc).long()
        self._derive()
        if strength is not None:
            strength.copy_(self.strength_from_knowledge(strength.dtype))
        return fired

    def _derive(self) -> None:
        """dominant and state from the evidence (a pure function of it: the order it came in cannot matter)."""
        B, C, P = self.eliminated.shape
        n = 2 ** P
        sets = torch.arange(n, device=self.held.device)
        single = self._size == 1
        # Elimination is clean: a comparison where one property changed (besides ones already eliminated) and the
        # outcome held. When several changed and the outcome held, their effects may cancel (larger but hollower):
        # no verdict. Eliminating one can make another comparison clean, so repeat until nothing changes.
        # A property that also changed alone while the outcome moved matters (its held comparison was a change too
        # small to show, or one that cancelled): Growth outweighs Elimination.
        excl = torch.zeros(B, C, dtype=torch.long, device=sets.device)
        for _ in range(P):
            rest, grew = self._without(self.held, excl), self._without(self.contradicted, excl)
            new = excl | ((rest & ~grew & single).long() * sets).sum(-1)
            if torch.equal(new, excl):
                break
            excl = new
        self.eliminated.copy_((excl[..., None] & self._weights) != 0)
        # A property eliminated in one context is presumed irrelevant in the others too, unless a contradiction
        # there can only be explained by it (Occam: no cause is added that the evidence does not need).
        anywhere = (self.eliminated.any(1).long() * self._weights).sum(-1)        # (B,) eliminated in any context
        presumed = excl | anywhere[:, None]
        needs = (self.contradicted & ((sets & ~presumed[..., None]) == 0) & ((sets & ~excl[..., None]) != 0)).any(-1)
        excl = torch.where(needs, excl, presumed)
        # what matters for neither a floater nor a sinker cannot explain a floater against a sinker
        both = (self.eliminated[:, FLOATING] & self.eliminated[:, SINKING]).long() @ self._weights
        excl[:, MIXED] |= both
        # each contradicted change set without its excluded properties; an emptied set is noise nothing explains
        eff = self._without(self.contradicted, excl)
        eff[..., 0] = False
        # an explanation uses no eliminated property and holds a changed property of every contradicted set; of
        # those, the ones that leave the fewest held comparisons unexplained (a held comparison whose change set
        # holds a cause should have seen the outcome move, unless effects cancelled), then the smallest
        held = self._without(self.held, excl)
        held[..., 0] = False
        allowed = (sets & excl[..., None]) == 0                                       # (B, C, n)
        explains = (~eff[:, :, None, :] | self._hits).all(-1) & allowed & (sets > 0)  # (B, C, n)
        against = (held[:, :, None, :] & self._hits).sum(-1)                          # (B, C, n)
        key = torch.where(explains, against * (P + 1) + self._size, torch.full_like(against, n * (P + 1)))
        minimal = explains & (key == key.min(-1, keepdim=True).values) & eff.any(-1, keepdim=True)
        # a floater against a sinker differs by what matters for floaters or for sinkers: of the mixed context's
        # minimal explanations, those with the fewest properties dominant in neither fate
        pure = (minimal[:, :MIXED, :, None] & self._bits).any(2).any(1)                 # (B, P)
        outside = (self._bits & ~pure[:, None]).sum(-1)                                  # (B, n)
        mixed = minimal[:, MIXED]
        fewest = torch.where(mixed, outside, torch.full_like(outside, P + 1)).min(-1, keepdim=True).values
        minimal[:, MIXED] = mixed & (outside == fewest)
        self.dominant.copy_((minimal[..., None] & self._bits).any(2))
        state = torch.full_like(self.state, UNKNOWN)
        state[self.uncertain_count > 0] = LIKELY_IRRELEVANT
        state[self.eliminated.any(1)] = IRRELEVANT
        state[self.dominant.any(1)] = DOMINANT
        self.state.copy_(state)

    @staticmethod
    def _without(evidence: torch.Tensor, excl: torch.Tensor) -> torch.Tensor:
        """(B, C, 2^P) change sets seen -> the same with the properties excluded in each context (excl (B, C), a
        bit mask) taken out of every set: a set left empty lands on index 0."""
        sets = torch.arange(evidence.shape[-1], device=evidence.device)
        out = torch.zeros_like(evidence)
        return out.scatter_reduce_(2, (sets & ~excl[..., None]).expand_as(evidence), evidence, reduce="amax")

    def strength_from_knowledge(self, dtype=torch.float32) -> torch.Tensor:
        """(B, P) hub pathway strengths: dominant strengthened, irrelevant drastically reduced, likely irrelevant
        marginally reduced per Uncertainty firing (down to `RulesConfig.uncertain_floor`)."""
        c = self.config
        s = (c.uncertain_decay ** self.uncertain_count.to(dtype)).clamp_min(c.uncertain_floor)
        s = torch.where(self.state == DOMINANT, torch.full_like(s, c.dominant_strength), s)
        return torch.where(self.state == IRRELEVANT, torch.full_like(s, c.eliminated_strength), s)

    def context_strength(self, dtype=torch.float32) -> torch.Tensor:
        """(B, C, P) the pathway strength within each context: drastically reduced where the property was eliminated
        in that context; elsewhere the agent's overall strength, except that a property irrelevant only because of
        another context keeps its pathway here (1): whether it matters here is this context's evidence to show, and
        the knowledge presumes it irrelevant anyway unless that evidence needs it (see `_derive`)."""
        s = self.strength_from_knowledge(dtype)
        s = torch.where(self.state == IRRELEVANT, torch.ones_like(s), s)[:, None, :].expand(self.eliminated.shape)
        return torch.where(self.eliminated, torch.full_like(s, self.config.eliminated_strength), s)

    def knowledge(self, b: int = 0) -> dict:
        """Agent b's causal knowledge in the summary.json form: {property: {"state", "certainty"}}."""
        cert = self.certainty[b]
        return {p: {"state": STATES[int(self.state[b, i])], "certainty": round(float(cert[i]), 4)}
                for i, p in enumerate(self.properties)}

    @property
    def confounded(self) -> torch.Tensor:
        """(B, P) bool: dominant, but never shown alone. In no context where the property is dominant did it change
        alone (besides the properties eliminated there) while the outcome moved: its dominance rests on comparisons
        where it changed together with others (a minimal explanation of a confound), not on a clean Growth."""
        excl = (self.eliminated.long() * self._weights).sum(-1)                      # (B, C)
        alone = self._without(self.contradicted, excl)[..., self._weights]           # (B, C, P): {p} contradicted
        return (self.state == DOMINANT) & ~(alone & self.dominant).any(1)

    def by_context(self, b: int = 0) -> dict:
        """Agent b's knowledge per context: {context: {"dominant": [...], "irrelevant": [...]}}."""
        return {c: {"dominant": [p for i, p in enumerate(self.properties) if self.dominant[b, k, i]],
                    "irrelevant": [p for i, p in enumerate(self.properties) if self.eliminated[b, k, i]]}
                for k, c in enumerate(CONTEXTS)}


def batch_knowledge(delta_p: torch.Tensor, delta_c: torch.Tensor, context: torch.Tensor,
                    config: RulesConfig | None = None, properties: tuple | None = None) -> torch.Tensor:
    """The batch answer: the knowledge (P,) state codes the rules reach when every pair of a set's episodes is
    compared at once. delta_p (n, n, P) bool, delta_c (n, n) bool and context (n, n) long hold the comparison of
    episode j with episode i at [i, j]; only i < j is read (a pair is compared once, at full strength).
    properties: the P judged properties' names (default the first P of PROPERTIES; AgentConfig.properties with
    context)."""
    n = delta_c.shape[0]
    i, j = torch.triu_indices(n, n, offset=1)
    properties = PROPERTIES[:delta_p.shape[-1]] if properties is None else tuple(properties)
    rules = CausalRules(config, batch=len(i), properties=properties)
    if len(i) == 0:
        return torch.zeros(delta_p.shape[-1], dtype=torch.long)
    rules.apply(delta_p[i, j], delta_c[i, j], torch.ones(len(i), dtype=torch.bool), context=context[i, j])
    # every pair is one agent's single comparison; the set's evidence is their union
    merged = CausalRules(config, batch=1, properties=rules.properties)
    merged.held.copy_(rules.held.any(0, keepdim=True))
    merged.contradicted.copy_(rules.contradicted.any(0, keepdim=True))
    merged.uncertain_count.copy_(rules.uncertain_count.sum(0, keepdim=True))
    merged._derive()
    return merged.state[0]
