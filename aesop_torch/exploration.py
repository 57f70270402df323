"""The robot chooses its next object (AgentConfig.explore "active"): the one on the stand whose comparison with a
remembered episode would be cleanest for what is still unknown.

The rules attribute a change of outcome only on a clean comparison: one property changed among those the pathways
still show. A teacher's order (or a random one) rarely offers one: random objects differ in most properties at once.
The robot looks at what is on the stand (colour, size, shape, and the weight it feels when it lifts each one) and
compares each object, as the rules would, with every episode it remembers (DeltaProperty at the pathways' strengths:
a property eliminated everywhere shows no change); an object's score is its best comparison's count of live
properties changed or in their dead zone (a dead-zone property spoils a comparison as a change does), a single
change counted half a step worse when that property is already decided in every context (dominant or irrelevant:
nothing left to learn from it). The lowest score is dropped next; none changed (an object like one remembered) is
the last choice; ties go to the teacher's order. Deterministic, batched over agents.
"""

from __future__ import annotations

import torch

from .comparisons import delta_property
from .rules import DOMINANT, IRRELEVANT

EXPLORE = ("teacher", "active")


@torch.no_grad()
def next_object(agent, acts: torch.Tensor, present: torch.Tensor, available: torch.Tensor,
                rank: torch.Tensor) -> torch.Tensor:
    """(B,) the index of each agent's next object among R candidates.

    agent: an aesop_torch.Agent (batch B). acts (R, P_all, U), present (R, P_all): the candidates as perceived
    (Agent.activities of the R measurements). available (B, R) bool: on the agent's stand (at least one each).
    rank (B, R) long: the teacher's order of the candidates (lower first), which breaks ties."""
    B, R = available.shape
    values = agent.decode(acts)                                                # {p: (R, dim)}
    mem = agent.memory
    M = mem.patterns.shape[1]
    stored = agent.decode(agent.retro_activate(agent._assemblies(mem.patterns).to(acts.dtype)))   # {p: (B, M, dim)}
    valid = torch.arange(M) < mem.count[:, None]                               # (B, M)
    strength = agent.judged_strength()                                         # (B, P): the largest over contexts
    flat_v = {p: v[None].expand(B, -1, -1).reshape(B * R, -1) for p, v in values.items()}
    flat_s = {p: v.repeat_interleave(R, 0) for p, v in stored.items()}
    live = strength.repeat_interleave(R, 0)[:, None].expand(-1, M, -1)
    changed, unclear = delta_property(flat_v, flat_s, agent.config, live)
    n = (changed | unclear).sum(-1).view(B, R, M)                              # live properties changed, per pair
    rules = agent.rules
    cs = rules.context_state if hasattr(rules, "context_state") else rules.state[:, None]
    decided = ((cs == DOMINANT) | (cs == IRRELEVANT)).all(1)                   # (B, P)
    single_decided = ((changed & decided.repeat_interleave(R, 0)[:, None]).any(-1).view(B, R, M) & (n == 1))
    big = 4 * len(agent.properties) + 4
    score = torch.where(n > 0, 2 * n + single_decided.long(), torch.full_like(n, big))
    score = torch.where(valid[:, None], score, torch.full_like(score, big)).amin(-1)     # (B, R): the best pair
    key = torch.where(available, score * (R + 1) + rank, torch.full_like(score, (big + 1) * (R + 1) + R))
    return key.argmin(-1)


@torch.no_grad()
def choose_in_order(agent, acts: torch.Tensor, present: torch.Tensor, orders: torch.Tensor, t: int) -> torch.Tensor:
    """(B,) each agent's object for episode t, chosen among those its order has not yet presented (positions t..),
    and moved to position t of `orders` (B, n) long, in place; the rest keep the teacher's order. acts, present: all n
    objects as perceived (indexed by object). The first object is the teacher's (nothing is remembered yet)."""
    B, n = orders.shape
    if t == 0:
        return orders[:, 0].clone()
    rank = torch.empty_like(orders)
    rank.scatter_(1, orders, torch.arange(n).expand(B, n).contiguous())      # rank[b, object] = its position
    chosen = next_object(agent, acts, present, rank >= t, rank)
    for b, (c, pos) in enumerate(zip(chosen.tolist(), rank.gather(1, chosen[:, None])[:, 0].tolist())):
        orders[b, t + 1:pos + 1] = orders[b, t:pos].clone()
        orders[b, t] = c
    return chosen
