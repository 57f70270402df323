"""Independent subjects in one agent batch: each row of the batch perceives and decodes through maps developed from
its own seed (train/battery/tasks.py's subjects), while hub, memory and rules stay batched as the Agent has them.

The Agent shares one set of maps over its batch (they never change after development). A battery subject is an
animal of its own, so its maps are its own: `OwnMapsAgent` keeps one map set per subject and, for every row, which
set it perceives through (`rows`); `activities` and `decode` run each set on its own rows. Everything else (recall,
comparisons, rules, storing) is the Agent's, row by row as always. `select` keeps the subclass and the rows, so a
view of several copies of a subject (one per option) still perceives through that subject's maps.

`give` hands the agent the anticipation it has just made of what it will drop (the battery's choice anticipates every
option; the chosen one's row is what `Agent.step` would recompute from the same map activities and the same learned
state): its next `anticipate_acts` with exactly those activities returns it instead of recalling again.
"""

from __future__ import annotations

from dataclasses import fields

import torch
from torch import nn

from aesop_torch.agent import Agent, Anticipation
from aesop_torch.agent_config import AgentConfig
from aesop_torch.encoders import train_property_maps
from aesop_torch.hub import ObjectHub

_DEVELOPED: dict = {}


def developed_maps(config: AgentConfig) -> nn.ModuleDict:
    """The maps an Agent of `config` develops (from config.seed), made once per process and config: maps never
    change after development, so subjects of one seed in several conditions share them."""
    key = (config.seed, config.som_samples, config.som_epochs, repr(config.encoder))
    if key not in _DEVELOPED:
        g = torch.Generator().manual_seed(config.seed)
        _DEVELOPED[key] = train_property_maps(config.som_samples, g, epochs=config.som_epochs, config=config.encoder)
    return _DEVELOPED[key]


def _rows_of(measurement: dict, idx: torch.Tensor) -> dict:
    out = {}
    for k, v in measurement.items():
        out[k] = _rows_of(v, idx) if isinstance(v, dict) else torch.as_tensor(v)[idx]
    return out


class OwnMapsAgent(Agent):
    """An Agent batch whose row b perceives through map_sets[rows[b]]."""

    map_sets: list
    rows: torch.Tensor

    @classmethod
    def of_seeds(cls, config: AgentConfig, seeds: list[int]) -> "OwnMapsAgent":
        """One subject per seed, each with the maps `config` develops from that seed (config.seed is ignored)."""
        from dataclasses import replace
        agent = cls(config, batch=len(seeds), develop=False)
        agent.map_sets = [developed_maps(replace(config, seed=s)) for s in seeds]
        agent.rows = torch.arange(len(seeds))
        agent.maps = agent.map_sets[0]
        agent.hub = ObjectHub({n: m.weights.shape[0] for n, m in agent.maps.items()}, config.hub, batch=len(seeds))
        return agent

    def _groups(self):
        for s in torch.unique(self.rows).tolist():
            yield s, (self.rows == s).nonzero().flatten()

    def activities(self, measurement: dict) -> tuple[torch.Tensor, torch.Tensor]:
        acts = present = None
        for s, idx in self._groups():
            self.maps = self.map_sets[s]
            a, p = Agent.activities(self, _rows_of(measurement, idx))
            if acts is None:
                acts = torch.zeros(self.batch, *a.shape[1:], dtype=a.dtype)
                present = torch.zeros(self.batch, *p.shape[1:], dtype=p.dtype)
            acts[idx], present[idx] = a, p
        return acts, present

    def decode(self, acts: torch.Tensor) -> dict:
        """(B, ..., P_all, U) -> per property (B, ..., dim): each row through its own subject's maps (SOM.decode's
        population read-out, batched over the rows' codebooks). Silent rows (no activity: an empty memory slot)
        decode to NaN as SOM.decode gives them, without the least squares."""
        out = {}
        flat = acts.reshape(acts.shape[0], -1, *acts.shape[-2:])                  # (B, M, P_all, U)
        for i, name in enumerate(self.maps):
            if name not in self.properties:
                continue
            som = self.map_sets[0][name]
            a = flat[:, :, i, :som.n_units]
            W = torch.stack([s[name].weights for s in self.map_sets])[self.rows]      # (B, n, D)
            x = torch.full((*a.shape[:2], W.shape[-1]), float("nan"), dtype=a.dtype)
            b, m = (a.amax(-1) > 0).nonzero(as_tuple=True)
            if len(b):
                x[b, m] = batched_decode(a[b, m][:, None], W[b], som.config.activity_sigma)[:, 0].to(a.dtype)
            out[name] = x.reshape(*acts.shape[:-2], W.shape[-1])
        return out

    def retro_activate(self, assemblies: torch.Tensor) -> torch.Tensor:
        """hub.ObjectHub.recall_patterns computed for the hub states that are not all zero only (an empty or
        unrecalled memory slot retro-activates nothing): the same values at a fraction of the cost."""
        hub = self.hub
        B, K, _ = assemblies.shape
        P, U = hub.branches.shape[2:]
        out = torch.zeros(B, K, P, U, dtype=hub.branches.dtype)
        on = hub.assemblies.to(hub.branches.dtype)
        for b in range(B):
            ks = assemblies[b].any(-1).nonzero().flatten()
            if not len(ks):
                continue
            c = (assemblies[b, ks].to(on.dtype) @ on[b].T / hub.assembly_neurons).clamp(0.0, 1.0) ** \
                hub.assembly_neurons                                                  # (k, A)
            used = (c > 0).any(0).nonzero().flatten()
            if len(used):
                out[b, ks] = torch.einsum("ka,apu->kpu", c[:, used], hub.branches[b, used])
        return out

    def give(self, anticipation: Anticipation) -> None:
        """The next anticipate_acts, if asked with exactly anticipation.acts and .present (and decoded), returns it:
        the caller made it from these activities with this learned state (rows_of of a batch of option copies), so
        recalling again would give it anew (recall, readout and rules are row by row). Used once, then dropped."""
        self._given = anticipation

    def anticipate_acts(self, acts: torch.Tensor, present: torch.Tensor, decoded: bool = True) -> Anticipation:
        given, self._given = getattr(self, "_given", None), None
        if given is not None and decoded and torch.equal(acts, given.acts) and torch.equal(present, given.present):
            return given
        return Agent.anticipate_acts(self, acts, present, decoded)

    def select(self, index) -> "OwnMapsAgent":
        new = Agent.select(self, index)
        new.__class__ = OwnMapsAgent
        new.map_sets = self.map_sets
        new.rows = self.rows[torch.as_tensor(index)]
        return new


def batched_decode(a: torch.Tensor, W: torch.Tensor, sigma: float, floor: float = 0.05) -> torch.Tensor:
    """aesop_torch.som.SelfOrganizingMap.decode with a codebook per row: a (B, M, n) activities, W (B, n, D) ->
    (B, M, D). The same least squares (units above floor x the peak; fewer than D + 1 of them: the weighted mean)."""
    a = a.to(W.dtype)
    D = W.shape[-1]
    peak = a.amax(-1, keepdim=True)
    on = (a >= floor * peak) & (peak > 0)
    w = torch.where(on, a, torch.zeros_like(a))
    mean = torch.einsum("bmu,bud->bmd", w, W) / w.sum(-1, keepdim=True)
    Wd = W.double()
    lhs = torch.cat([Wd, torch.full_like(Wd[..., :1], -0.5)], -1)                  # (B, n, D + 1)
    rhs = sigma ** 2 * torch.where(on, a, torch.ones_like(a)).double().log() + 0.5 * (Wd * Wd).sum(-1)[:, None, :]
    sw = (w / peak.clamp_min(1e-30)).double()
    A = torch.einsum("bmu,buf,bug->bmfg", sw, lhs, lhs) + 1e-9 * torch.eye(D + 1, dtype=Wd.dtype)
    b = torch.einsum("bmu,buf,bmu->bmf", sw, lhs, rhs)
    ok = on.sum(-1) > D
    x = torch.linalg.solve(A, b)[..., :D].to(a.dtype) if ok.any() else mean
    return torch.where(ok[..., None], x, mean)


def rows_of(a: Anticipation, idx) -> Anticipation:
    """The anticipation of rows idx (each field's leading dim indexed; values and recalled values per map)."""
    idx = torch.as_tensor(idx)

    def pick(v):
        if v is None:
            return None
        if isinstance(v, dict):
            return {k: pick(x) for k, x in v.items()}
        if isinstance(v, tuple):   # memory.Recall
            return type(v)(*(pick(x) for x in v))
        return v[idx]
    return Anticipation(**{f.name: pick(getattr(a, f.name)) for f in fields(a)})
