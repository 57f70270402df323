"""The paper's four rules, kept per context the robot sees: what decides the fate, and what decides the reward within
each fate.

A sinker displaces its volume and a floater its weight, so whether a property matters depends on what became of the
object, and whether it floats depends on properties of its own. The robot sees each object float or rest on the
bottom, stores that fate with the episode, and keeps three sets of pathway strengths (`CONTEXTS`):

- "fate": judged on every comparison of two episodes whose fates were seen, the outcome being the fate. The paper's
  episode 3 is such a comparison: the 14 g cylinder floats where the 420 g one sank, weight alone changed, so Growth
  on weight as what decides the fate.
- "floating" and "sinking": judged on comparisons within one fate, the outcome being the reward (DeltaContradiction).

Each firing edits one pathway strength in place, as the paper states the rules (incremental_rules.py holds the same
arithmetic for one context): Elimination drops it below the retro-activation floor, Growth adds `growth_step` (up to
`dominant_strength`), Uncertainty keeps `uncertain_decay` of an undecided pathway (never below `uncertain_floor`),
Status quo nothing. E and G attribute only on a clean comparison (one property changed among those the context's
pathways still show). Two choices the paper leaves open, made so the rules keep learning:

- A grown pathway is not eliminated. A clean change that moved the outcome shows the property can matter; a clean
  change that did not shows only that this change was too small to (whether an object floats flips at a boundary:
  most weight changes leave the fate as it was). The Elimination is then a Status quo.
- An eliminated pathway grows back. An outcome that moved while no pathway the context still shows changed is
  explained by an eliminated property that changed, seen bottom-up at full strength. When exactly one such property
  may matter somewhere (one eliminated in every context is known to matter nowhere: colour, once every context has
  eliminated it, changes in almost every comparison and explains none), Growth fires on it (from the eliminated
  strength, so it is dominant at once).

These are the sequential rules (`--ablate replay`). By default each episode's comparisons fire them as it happens,
and then, at rest, replay.py re-derives the strengths and counts from every pair of episodes lived (kept here, in
the `lived_*` buffers), so the knowledge does not depend on the order the objects came in.

Knowledge per context is read from the strengths: irrelevant at or below the retro-activation floor, dominant above
1, likely irrelevant once Uncertainty fired there, else unknown. Over contexts (`state`): dominant in some context,
else irrelevant in some, else likely irrelevant, else unknown. With contexts off (the "context" ablation) every
comparison is judged on its reward in one context and all three hold the same strengths.
"""

from __future__ import annotations

import torch
from torch import nn

from .incremental_rules import certainties_of, edited, states_of
from .comparisons import CONTEXTS, FATE, FLOATING, SINKING  # noqa: F401   (the model's contexts, named here too)
from .replay import add_episode, unflatten
from .rules import (DOMINANT, ELIMINATION, GROWTH, IRRELEVANT, LIKELY_IRRELEVANT, PROPERTIES, STATES, STATUS_QUO,
                    UNCERTAINTY, UNKNOWN, RulesConfig)


class ContextualRules(nn.Module):
    """E/G/U/S on per-context pathway strengths; batched over agents (dim B).

    buffers: strength (B, C, P) the pathways' strengths per context (init 1), fired (B, C, P, 4) how often each rule
    fired there (codes into rules.RULE_NAMES), state (B, P) the knowledge over contexts (codes into rules.STATES)."""

    contexts = CONTEXTS

    def __init__(self, config: RulesConfig | None = None, batch: int = 1, properties=PROPERTIES,
                 retro_floor: float = 0.1, capacity: int = 0, dims: dict | None = None):
        """capacity, dims: the lived store replay.py consolidates from (episodes, and {property: decoded dims})."""
        super().__init__()
        self.config = config or RulesConfig()
        self.properties = tuple(properties)
        self.retro_floor = retro_floor
        self.dims = dict(dims or {p: 1 for p in self.properties})
        P, C, M, D = len(self.properties), len(CONTEXTS), capacity, sum(self.dims.values())
        self.register_buffer("strength", torch.ones(batch, C, P))
        self.register_buffer("fired", torch.zeros(batch, C, P, 4, dtype=torch.long))
        self.register_buffer("state", torch.zeros(batch, P, dtype=torch.long))
        # every episode lived (replay.py): its decoded values, its outcome as the memory holds it, its fate
        self.register_buffer("lived_values", torch.zeros(batch, M, D))
        self.register_buffer("lived_outcome", torch.zeros(batch, M))
        self.register_buffer("lived_fate", torch.full((batch, M), -1, dtype=torch.long))
        self.register_buffer("lived_count", torch.zeros(batch, dtype=torch.long))
        self._empty_cache(batch, M, P)

    # -- the pairs of lived episodes, compared once (replay.py); derived from the lived store, so not saved ---------
    def _empty_cache(self, B: int, M: int, P: int) -> None:
        for name, shape, dtype in (("pair_changed", (B, M, M, P), torch.bool), ("pair_unclear", (B, M, M, P), torch.bool),
                                   ("pair_sign", (B, M, M, P), torch.int8), ("pair_dc", (B, M, M), torch.bool),
                                   ("pair_uc", (B, M, M), torch.bool), ("pair_osign", (B, M, M), torch.int8)):
            self.register_buffer(name, torch.zeros(shape, dtype=dtype), persistent=False)
        self.register_buffer("cached_count", torch.zeros(B, dtype=torch.long), persistent=False)

    def ensure_cache(self, config) -> None:
        """Rebuild the pair cache from the lived store when it does not hold its pairs (after a load or a select)."""
        B, M = self.lived_outcome.shape
        if self.pair_dc.shape[:2] == (B, M) and torch.equal(self.cached_count, self.lived_count):
            return
        values, outcome, fate, count = (self.lived_values.clone(), self.lived_outcome.clone(), self.lived_fate.clone(),
                                        self.lived_count.clone())
        self._empty_cache(B, M, len(self.properties))
        self.lived_count.zero_()
        self.lived_fate.fill_(-1)
        for k in range(int(count.max()) if B else 0):
            add_episode(self, unflatten(values[:, k], self.dims), outcome[:, k], fate[:, k], k < count, config)

    def drop_oldest(self, mask: torch.Tensor) -> None:
        """Let the oldest lived episode of the agents in mask go (a full store), with its pairs."""
        for name in ("lived_values", "lived_outcome", "lived_fate"):
            buf = getattr(self, name)
            buf[mask] = torch.cat([buf[mask][:, 1:], buf[mask][:, :1]], 1)
        self.lived_fate[mask, -1] = -1
        for name in ("pair_changed", "pair_unclear", "pair_sign", "pair_dc", "pair_uc", "pair_osign"):
            buf = getattr(self, name)
            buf[mask] = buf[mask].roll((-1, -1), (1, 2))
        self.lived_count[mask] -= 1
        self.cached_count[mask] -= 1

    # -- knowledge read from the strengths --------------------------------------------------------------------
    @property
    def context_state(self) -> torch.Tensor:
        """(B, C, P) the knowledge in each context (codes into STATES)."""
        return states_of(self.strength, self.fired[..., UNCERTAINTY], self.retro_floor)

    @property
    def eliminated(self) -> torch.Tensor:
        return self.strength <= self.retro_floor

    @property
    def dominant(self) -> torch.Tensor:
        return self.strength > 1.0

    @property
    def confounded(self) -> torch.Tensor:
        """(B, P) all False: Growth fires only on a clean comparison, so no dominance rests on a confound."""
        return torch.zeros_like(self.state, dtype=torch.bool)

    @property
    def context_certainty(self) -> torch.Tensor:
        """(B, C, P) 1 for dominant and irrelevant, 1 - (1 - step)^n after n Uncertainty firings, 0 unknown."""
        return certainties_of(self.context_state, self.fired[..., UNCERTAINTY], self.config.certainty_step)

    @property
    def certainty(self) -> torch.Tensor:
        """(B, P) the certainty of the context that decides `state` (its highest where several agree)."""
        state, cert = self.context_state, self.context_certainty
        return torch.where(state == self.state[:, None], cert, torch.zeros_like(cert)).amax(1)

    def context_strength(self, dtype=torch.float32) -> torch.Tensor:
        return self.strength.to(dtype)

    def strength_from_knowledge(self, dtype=torch.float32) -> torch.Tensor:
        """(B, P) one strength per pathway for the hub (which tells stored objects apart): the largest over contexts,
        so a property that matters anywhere still tells two objects apart."""
        return self.strength.amax(1).to(dtype)

    def _read_state(self) -> None:
        cs = self.context_state
        state = torch.full_like(self.state, UNKNOWN)
        state[(cs == LIKELY_IRRELEVANT).any(1)] = LIKELY_IRRELEVANT
        state[(cs == IRRELEVANT).any(1)] = IRRELEVANT
        state[(cs == DOMINANT).any(1)] = DOMINANT
        self.state.copy_(state)

    # -- one comparison -----------------------------------------------------------------------------------------
    @torch.no_grad()
    def apply(self, delta_p: torch.Tensor, delta_c: torch.Tensor, compared: torch.Tensor,
              strength: torch.Tensor | None = None, context: torch.Tensor | None = None,
              bottom_up: torch.Tensor | None = None) -> torch.Tensor:
        """One comparison per agent, judged in `context` (B,) long codes into CONTEXTS, or None: in every context
        at once (contexts off). delta_p (B, P) bool: the property changed as the context's pathways show it;
        delta_c (B,): the outcome (the fate, or the reward) contradicted the recalled one; compared (B,): the
        comparison counts. bottom_up (B, P) bool, optional: the properties changed at full strength (clearly),
        for growing back an eliminated pathway. strength (B, P), optional: rewritten with
        `strength_from_knowledge`. Returns the rule fired per agent and property (codes into RULE_NAMES)."""
        B, C, P = self.strength.shape
        rows = torch.arange(B, device=self.strength.device)
        slots = range(C) if context is None else [None]
        fired = None
        # a property eliminated in every context is known to matter nowhere: it explains no contradiction
        nowhere = (self.strength <= self.retro_floor).all(1)
        for slot in slots:
            ctx = torch.full((B,), slot, dtype=torch.long, device=rows.device) if slot is not None else context
            up = None if bottom_up is None else bottom_up & ~nowhere
            f = self._fire(self.strength[rows, ctx], delta_p, delta_c, compared, up)
            self.strength[rows, ctx] = edited(self.strength[rows, ctx], f, self.config)
            self.fired[rows, ctx] += torch.nn.functional.one_hot(f, 4)
            fired = f
        self._read_state()
        if strength is not None:
            strength.copy_(self.strength_from_knowledge(strength.dtype))
        return fired

    def _fire(self, s, delta_p, delta_c, compared, bottom_up) -> torch.Tensor:
        live = s > self.retro_floor
        dp = delta_p & compared[:, None] & live
        dc = (delta_c & compared)[:, None]
        clean = dp.sum(-1, keepdim=True) == 1
        undecided = live & (s <= 1.0)
        fired = torch.full(s.shape, STATUS_QUO, dtype=torch.long, device=s.device)
        fired[dp & ~dc & clean & undecided] = ELIMINATION
        fired[dp & dc & clean] = GROWTH
        fired[~dp & dc & undecided] = UNCERTAINTY
        if bottom_up is not None:
            # nothing the context shows changed, yet the outcome moved: of the eliminated properties that changed,
            # seen at full strength, one alone may matter somewhere (bottom_up leaves out those eliminated in every
            # context)
            seen = bottom_up & compared[:, None] & ~live
            alone = (seen.sum(-1, keepdim=True) == 1) & ~dp.any(-1, keepdim=True)
            back = seen & alone & dc
            fired[back] = GROWTH
            fired[back.any(-1, keepdim=True).expand_as(fired) & (fired == UNCERTAINTY)] = STATUS_QUO
        return fired

    # -- reading ------------------------------------------------------------------------------------------------
    def knowledge(self, b: int = 0) -> dict:
        cert = self.certainty[b]
        return {p: {"state": STATES[int(self.state[b, i])], "certainty": round(float(cert[i]), 4)}
                for i, p in enumerate(self.properties)}

    def by_context(self, b: int = 0) -> dict:
        """Agent b's knowledge per context: {context: {"dominant": [...], "irrelevant": [...]}}."""
        cs = self.context_state[b]
        return {c: {"dominant": [p for i, p in enumerate(self.properties) if cs[k, i] == DOMINANT],
                    "irrelevant": [p for i, p in enumerate(self.properties) if cs[k, i] == IRRELEVANT]}
                for k, c in enumerate(CONTEXTS)}
