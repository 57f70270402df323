"""Layer 2: the object hub (with W, maps -> hub, and W', hub -> maps), the action and body hubs, the reward code.

Every hub's output is one 50-neuron row of the episodic memory sheet (20 rows x 50).

Object hub. The paper: "if the net activity due to a neuron i and a neuron j winning in the maps manages to
activate a neuron k in the object hub, set W_ik = 1 and W_jk = 1" - binary, one-shot. Here an object is an
ASSEMBLY of `assembly_size` hub neurons (a sparse 5-of-50 code): the memory recalls reliably from sparse rows, and
one neuron per object would give only 50 codes with no graded overlap. Storing an object sets W = 1 from each map's
winner to each assembly neuron. W' (hub -> maps) is W transposed; the paper's "connection strength between the
object hub and the map" is `strength`, one number per agent and map, gating both directions; the learning rules
edit it in place. A full hub refuses a new object, or first frees its oldest assembly or its weakest (the least
used, the most like another object) (HubConfig.when_full, `ObjectHub.make_room`).

All state has a leading batch dim B: B independent agents (e.g. one per presentation order) share one tensor
program.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

from .memory import WHEN_FULL

N_NEURONS = 50  # one row of the episodic memory sheet


@dataclass
class HubConfig:
    n_neurons: int = N_NEURONS      # neurons per row
    # 5-of-50: sparse enough that two objects' assemblies rarely overlap (10 disjoint assemblies before any neuron
    # is reused), dense enough for a reliable memory cue. Per row when the hub spans several rows.
    assembly_size: int = 5
    # rows of the memory sheet the hub spans (n_neurons each; an assembly has assembly_size neurons on every row):
    # one row by default, the paper's hub. One 50-neuron row holds ~1,200 distinct object codes, but a 5-neuron
    # cue is too little signal to pull one of 230 episodes out of 1,000 neurons (see agent.AgentConfig)
    rows: int = 1
    # the memory holds ~230 episodes, so an agent never needs more distinct objects than that
    max_assemblies: int = 230
    # what `allocate` does for an agent whose hub holds max_assemblies objects already (memory.WHEN_FULL): "refuse"
    # raises and stores nothing; "forget_oldest" frees the oldest assembly, "forget_weakest" of the least used ones
    # the most like another stored object (`ObjectHub.make_room`; an assembly its owner holds no reference to goes
    # first either way). The default refuses, as the memory's does: a library hub never drops an object its caller
    # did not ask it to drop, and a run sized for its objects never needs to.
    when_full: str = "refuse"
    # `match` above this: the object is already known and its assembly is reused. The same object seen again scores
    # 1 (relative activity) or a hair less (a remeasurement within the senses' noise); with graded storage a
    # similar but different object scores high too (one property moved by one map unit: ~0.95 with weight at the
    # dominant strength), and two objects sharing an assembly would blur each other's stored values: 0.97.
    match_threshold: float = 0.97
    # the map that holds names, for `cross_modal`
    word_map: str = "word"
    # bottom_up reads each map's activity relative to its peak (divisive normalisation): the map's winner drives
    # its hub neurons fully however closely the input matches its codebook vector (a remeasured colour activates
    # its unit anywhere from 0.6 to 1.0, see encoders), the graded activity sets how much every other unit drives.
    # So a stored object shown again gives exactly 1 on its assembly. False: raw activities, as given.
    relative_activity: bool = True
    # graded storage keeps the bump's units down to this fraction of its peak: at the maps' activity width that is
    # ~2.5 units either side of the winner, enough for a population read-out to land within ~1 % of a unit
    # between them (SelfOrganizingMap.decode), while W stays sparse
    store_floor: float = 0.05

    def __post_init__(self):
        if self.when_full not in WHEN_FULL:
            raise ValueError(f"HubConfig.when_full must be one of {', '.join(WHEN_FULL)}, got {self.when_full!r}")


def _relative(acts: torch.Tensor) -> torch.Tensor:
    """(..., U) activity relative to its peak; a silent map stays 0. Exact for any positive peak, however small (an
    input far outside a map's range still has its nearest unit as the winner)."""
    peak = acts.amax(-1, keepdim=True)
    return torch.where(peak > 0, acts / torch.where(peak > 0, peak, torch.ones_like(peak)), torch.zeros_like(acts))


class ObjectHub(nn.Module):
    """The object hub of B agents over P maps (properties and the word map), U_max = the largest map's units,
    N = n_neurons * rows hub neurons.

    buffers: strength (B, P) pathway gates (init 1), usage (B, N) assemblies per neuron, assemblies
    (B, max_assemblies, N) bool the stored assemblies, branches (B, max_assemblies, P, U_max) each one's stored
    patterns, branch_norm (B, max_assemblies, P) their energies, graded (B, max_assemblies) bool stored as a graded
    bump (else the binary rule's one unit), n_assemblies (B,). W (B, P, U_max, N), the
    connections from the maps onto each hub neuron, is their union (a property, for inspection).
    """

    def __init__(self, maps: dict[str, int], config: HubConfig | None = None, batch: int = 1):
        super().__init__()
        self.config = c = config or HubConfig()
        if not maps or any(int(n) < 1 for n in maps.values()):
            raise ValueError(f"maps must name at least one map, each with >= 1 unit, got {maps}")
        if not 1 <= c.assembly_size <= c.n_neurons or c.rows < 1:
            raise ValueError(f"assembly_size must be in 1..{c.n_neurons} and rows >= 1, got {c.assembly_size}, "
                             f"{c.rows}")
        if batch < 1:
            raise ValueError(f"batch must be >= 1, got {batch}")
        self.names = tuple(maps)
        P, U, N = len(maps), max(maps.values()), c.n_neurons * c.rows
        self.n_neurons, self.assembly_neurons = N, c.assembly_size * c.rows
        self.register_buffer("sizes", torch.tensor([int(n) for n in maps.values()]), persistent=False)
        self.register_buffer("strength", torch.ones(batch, P))
        self.register_buffer("usage", torch.zeros(batch, N, dtype=torch.long))
        # each stored object's own patterns (its branch on its neurons) and their energies
        self.register_buffer("branches", torch.zeros(batch, c.max_assemblies, P, U))
        self.register_buffer("branch_norm", torch.zeros(batch, c.max_assemblies, P))
        self.register_buffer("graded", torch.zeros(batch, c.max_assemblies, dtype=torch.bool))
        self.register_buffer("assemblies", torch.zeros(batch, c.max_assemblies, N, dtype=torch.bool))
        self.register_buffer("n_assemblies", torch.zeros(batch, dtype=torch.long))

    @property
    def W(self) -> torch.Tensor:
        """(B, P, U_max, N): W_mk, what map m is wired to on hub neuron k, the union (max) of the branches of the
        objects k codes for. Computed on demand: nothing reads it on the hot path."""
        on = self.assemblies.to(self.branches.dtype)
        return (self.branches[..., None] * on[:, :, None, None, :]).amax(1) if on.shape[1] else \
            self.branches.new_zeros(on.shape[0], self.branches.shape[2], self.branches.shape[3], on.shape[2])

    @property
    def W_back(self) -> torch.Tensor:
        """W' (B, P, N, U_max): hub -> maps, the transpose of W."""
        return self.W.transpose(-1, -2)

    def index(self, name: str) -> int:
        if name not in self.names:
            raise ValueError(f"unknown map '{name}' (known: {', '.join(self.names)})")
        return self.names.index(name)

    def _check(self, acts: torch.Tensor, present: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        B, _, P, U = self.branches.shape
        if acts.shape != (B, P, U):
            raise ValueError(f"acts must be (B, P, U_max) = {(B, P, U)}, got {tuple(acts.shape)}")
        if present.shape != (B, P):
            raise ValueError(f"present must be (B, P) = {(B, P)}, got {tuple(present.shape)}")
        return acts.to(self.branches.dtype), present.bool()

    def _floored(self, pattern: torch.Tensor) -> torch.Tensor:
        """A map's pattern as a graded branch holds it: units below `HubConfig.store_floor` left out."""
        return torch.where(pattern >= self.config.store_floor, pattern, torch.zeros_like(pattern))

    # -- activity flows -----------------------------------------------------------------------------------------
    def bottom_up(self, acts: torch.Tensor, present: torch.Tensor, strength: torch.Tensor | None = None
                  ) -> torch.Tensor:
        """Maps -> hub. acts (B, P, U_max) graded map activities, present (B, P) maps with input -> (B, N) in [0, 1].

        u_k = max over the stored objects o whose assembly holds k of sum_m s_m d_om / sum_m s_m over the present
        maps o was stored with, where d_om = (a_m . W_om) / max(a_m . a_m, W_om . W_om) is how well map m's
        activity a_m (relative to its peak, see HubConfig.relative_activity, and below store_floor dropped, as a
        branch holds it) matches the pattern W_om stored for o: 1 only when the stored pattern is shown again
        (Cauchy-Schwarz), falling off smoothly as its value moves away, and the same for o seen as a against a seen
        as o. (Divided by W . W alone, an input wider than a stored bump, or shifted into its wide side, scored 1 on
        it: two distinct objects cued each other's episodes as strongly as their own.) A branch of the binary rule
        holds one unit at 1 whatever the input's width, so there a_m counts as energy 1: d_om = a_m at the stored
        winner. With four equal strengths, one property changed to a clearly different value gives 0.75. A map with
        strength 0 drops out of both sums: it neither helps nor hurts.

        Each object's patterns sit on a branch of its own on each of its neurons (dendritic branches): a neuron
        that codes for several objects fires as much as the best-matching of them, never for a mixture of their
        properties. (Summed onto the neuron, with 230 objects on 50 neurons, every neuron came to match every
        input: the stored object's own assembly was the top 5 of the drive for under a third of the objects.)
        With at most 10 objects the assemblies are disjoint and both readings are the same.
        """
        score = self.object_match(acts, present, strength)                        # (B, A)
        on = self.assemblies.to(score.dtype)
        return (score[:, :, None] * on).amax(1) if on.shape[1] else score.new_zeros(on.shape[0], on.shape[2])

    def object_match(self, acts: torch.Tensor, present: torch.Tensor, strength: torch.Tensor | None = None
                     ) -> torch.Tensor:
        """(B, A): how well the input matches each stored object, the sum in `bottom_up` taken over one object's
        own stored patterns (its branch on the hub neurons), 0 for an empty slot. strength (B, P): the pathway
        strengths to use instead of the hub's own (an ablation's)."""
        acts, present = self._check(acts, present)
        if self.config.relative_activity:
            acts = _relative(acts)
        # the input as a graded branch holds a pattern, and its energy: a binary branch holds one unit at 1 whatever
        # the input's width, so its input counts as energy 1
        acts = self._floored(acts)
        energy = torch.where(self.graded[..., None], (acts ** 2).sum(-1)[:, None, :],
                             torch.ones_like(self.branch_norm))
        drive = torch.einsum("bpu,bapu->bap", acts, self.branches) / torch.maximum(self.branch_norm, energy) \
            .clamp_min(1e-12)
        strength = self.strength if strength is None else strength
        gate = strength[:, None, :] * present[:, None, :] * (self.branch_norm > 0)   # (B, A, P)
        den = gate.sum(-1)
        return torch.where(den > 0, (gate * drive.clamp(0.0, 1.0)).sum(-1) / den.clamp_min(1e-12),
                           torch.zeros_like(den))

    def top_down(self, hub_state: torch.Tensor) -> torch.Tensor:
        """Hub -> maps (retro-activation). hub_state (B, N) -> (B, P, U_max): r_m = s_m sum_o c_o W_om, over the
        stored objects o, with c_o = (mean of hub_state over o's assembly) ** (its size).

        A full stored assembly gives s_m on the units it was stored with, in every map (1.0 at full strength); an
        object that shares one neuron of a 5-neuron assembly, (1/5)^5 = 0.0003 of its own: the power is the
        branches' conjunction (a branch needs its whole assembly), soft so that a state between two assemblies
        recalls a blend."""
        B, N = self.usage.shape
        if hub_state.shape != (B, N):
            raise ValueError(f"hub_state must be (B, N) = {(B, N)}, got {tuple(hub_state.shape)}")
        return self.strength[:, :, None] * self.recall_patterns(hub_state[:, None])[:, 0]

    def recall_patterns(self, hub_states: torch.Tensor) -> torch.Tensor:
        """(B, K, N) hub states -> (B, K, P, U_max): `top_down` of each before its strength gate (what the stored
        objects it holds looked like)."""
        on = self.assemblies.to(self.branches.dtype)                                # (B, A, N)
        c = torch.einsum("bkn,ban->bka", hub_states.to(on.dtype), on) / self.assembly_neurons
        return torch.einsum("bka,bapu->bkpu", c.clamp(0.0, 1.0) ** self.assembly_neurons, self.branches)

    def cross_modal(self, word_acts: torch.Tensor) -> torch.Tensor:
        """Word map -> hub -> every map. word_acts (B, U_word) or (B, U_max) -> (B, P, U_max) retro-activation.

        "blue cylinder" activates the word map, the hub's assemblies stored with that name light up, and they
        retro-activate what a blue cylinder looks like in the colour and shape maps (and the rest of the object)."""
        B, _, P, U = self.branches.shape
        w = self.index(self.config.word_map)
        if word_acts.ndim != 2 or word_acts.shape[0] != B or word_acts.shape[1] > U:
            raise ValueError(f"word_acts must be (B, <= {U}) with B = {B}, got {tuple(word_acts.shape)}")
        acts = self.branches.new_zeros(B, P, U)
        acts[:, w, :word_acts.shape[1]] = word_acts.to(acts.dtype)
        present = torch.zeros(B, P, dtype=torch.bool, device=acts.device)
        present[:, w] = True
        return self.top_down(self.bottom_up(acts, present))

    def code(self, hub_state: torch.Tensor) -> torch.Tensor:
        """(B, N) activity -> (B, N) bool: the assembly_size most active neurons of each row (k-winners-take-all),
        ties to the lower index; neurons with no activity never win, so a silent hub gives an empty code."""
        c = self.config
        rows = hub_state.reshape(-1, c.rows, c.n_neurons)
        order = torch.sort(rows, dim=-1, descending=True, stable=True).indices[..., :c.assembly_size]
        out = torch.zeros_like(rows, dtype=torch.bool)
        out.scatter_(-1, order, True)
        return (out & (rows > 0)).reshape(hub_state.shape)

    # -- objects ------------------------------------------------------------------------------------------------
    def assembly_activity(self, hub_state: torch.Tensor) -> torch.Tensor:
        """(B, N) -> (B, max_assemblies): mean activity over each stored assembly's neurons (0 for empty slots)."""
        a = self.assemblies.to(hub_state.dtype)
        return torch.einsum("bn,ban->ba", hub_state, a) / self.assembly_neurons

    def match(self, acts: torch.Tensor, present: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The stored object most like the input: (its assembly's mean activity (B,), its assembly (B, N) bool).
        An agent with no stored object gets (0, empty assembly)."""
        score = self.object_match(acts, present)
        best, i = score.max(-1)
        assembly = self.assemblies[torch.arange(score.shape[0], device=i.device), i]
        return best, assembly

    @torch.no_grad()
    def allocate(self, winners: torch.Tensor, present: torch.Tensor, mask: torch.Tensor,
                 generator: torch.Generator | None = None) -> torch.Tensor:
        """One-shot storage of a new object for the agents in mask (B,), present (B, P) maps with input.

        winners: (B, P) long map winners (the paper's binary rule: W = 1 from each winner), or (B, P, U_max) graded
        map activities: W onto each assembly neuron is then the activity relative to its peak, the whole bump
        around the winner (1 at the winner), units below `HubConfig.store_floor` left at 0. The bump is what lets
        retro-activation be decoded as a population (SelfOrganizingMap.decode) between units, not only at the
        winner's codebook vector. Picks the assembly by `_pick` (ties broken at random by an
        optional generator, else to the lower index). Returns the new assemblies (B, N) bool (empty where mask is
        False). A masked agent whose hub is full first makes room as HubConfig.when_full says (`make_room`, with no
        reference counts: the hub alone does not know its objects' uses; an owner that does, as the agent does
        with its episodes, calls `make_room` first); under "refuse", ValueError, storing nothing for any agent."""
        B, A, P, U = self.branches.shape
        graded = winners.is_floating_point()
        if (winners.shape != ((B, P, U) if graded else (B, P))) or present.shape != (B, P) or mask.shape != (B,):
            raise ValueError(f"winners must be (B, P) = {(B, P)} or activities (B, P, U) = {(B, P, U)}, present "
                             f"(B, P) and mask (B,) = ({B},), got {tuple(winners.shape)}, {tuple(present.shape)}, "
                             f"{tuple(mask.shape)}")
        present, mask = present.bool(), mask.bool()
        active = present & mask[:, None]
        if graded:
            pattern = self._floored(_relative(winners.to(self.branches.dtype)))
            if (active & (pattern.sum(-1) == 0)).any():
                raise ValueError("a present map has no activity to store")
        else:
            if (active & ((winners < 0) | (winners >= self.sizes))).any():
                raise ValueError(f"winners out of range for the map sizes {self.sizes.tolist()}")
            pattern = torch.zeros(B, P, U, dtype=self.branches.dtype, device=self.branches.device)
            pattern.scatter_(2, winners.clamp(0, U - 1)[:, :, None], 1.0)
        self.make_room(mask)
        assembly = self._pick(generator) & mask[:, None]
        self.usage += assembly.long()
        slot = self.n_assemblies.clamp(max=self.config.max_assemblies - 1)
        rows = torch.arange(B, device=self.branches.device)[mask]
        self.assemblies[rows, slot[mask]] = assembly[mask]
        stored = pattern * active[:, :, None]
        self.branches[rows, slot[mask]] = stored[mask]
        self.branch_norm[rows, slot[mask]] = (stored[mask] ** 2).sum(-1)
        self.graded[rows, slot[mask]] = graded
        self.n_assemblies += mask.long()
        return assembly

    @torch.no_grad()
    def make_room(self, mask: torch.Tensor, held: torch.Tensor | None = None) -> torch.Tensor:
        """For the agents in mask (B,) whose hub is full, one assembly is freed, as HubConfig.when_full says; returns
        the freed assemblies (B, N) bool (empty for the other agents), so that an owner can drop what it bound to
        them (the agent: the episodes stored with that object, which could never be cued right again).

        held (B, M, N) bool: the codes the owner still refers to (the agent: its stored episodes' object rows; rows
        of empty slots all False). An assembly's uses are the held codes equal to it.
        - "refuse": ValueError naming the limit and the field to change; nothing changes.
        - "forget_oldest": an assembly with no use, the oldest of them, else the oldest assembly.
        - "forget_weakest": of the least used assemblies (an unused one first), the object most redundant with
          another stored object (`similarity`: how well each would match the other, through the pathway strengths
          as they are), the older of a pair. Why: an object with more uses is one the agent met more often or
          that surprised it (a contradiction is stored again on the object's own assembly), and freeing an assembly
          takes all of its uses with it; of equal uses, one whose look-alike stays loses least (what the agent knew
          of it, the look-alike still cues), and a property the rules found irrelevant tells no two objects apart.
          The memory's forget_weakest is the same idea (EpisodicMemory.make_room). The hub keeps no count of its
          own (uses live with the owner): without held every assembly counts one use.
        Freeing an unused assembly first loses nothing the owner recalls (a name bound to it goes with it: the word
        map's pattern is one of its branches). The survivors keep their order (`forget`)."""
        c, B = self.config, self.n_assemblies.shape[0]
        mask = mask.to(device=self.n_assemblies.device, dtype=torch.bool)
        if tuple(mask.shape) != (B,):
            raise ValueError(f"mask shape {tuple(mask.shape)}, expected ({B},)")
        freed = torch.zeros_like(self.usage, dtype=torch.bool)
        full = mask & (self.n_assemblies >= c.max_assemblies)
        if not full.any():
            return freed
        if c.when_full == "refuse":
            raise ValueError(f"object hub full: agents {full.nonzero().flatten().tolist()} already hold "
                             f"max_assemblies={c.max_assemblies} objects (nothing stored); raise "
                             f"HubConfig.max_assemblies or set HubConfig.when_full to 'forget_oldest' or "
                             f"'forget_weakest'")
        rows = full.nonzero().flatten()
        stored = self.assemblies[rows]                                                # (F, A, N), every slot filled
        uses = torch.ones(stored.shape[:2], dtype=torch.long, device=stored.device)
        if held is not None:
            if held.ndim != 3 or held.shape[0] != B or held.shape[2] != stored.shape[2]:
                raise ValueError(f"held must be (B, M, N) with B = {B}, N = {stored.shape[2]}, got "
                                 f"{tuple(held.shape)}")
            h, a = held.to(stored.device)[rows].float(), stored.float()
            shared = torch.bmm(h, a.transpose(1, 2))                                   # (F, M, A), exact counts
            same = (shared == h.sum(-1, keepdim=True)) & (shared == a.sum(-1)[:, None, :])
            uses = same.sum(1)
        if c.when_full == "forget_oldest":
            victim = (uses > 0).long().argmin(1)                                      # the first unused, else slot 0
        else:
            sim = self.similarity(rows)
            sim.diagonal(dim1=1, dim2=2).fill_(-1.0)                                   # not with itself
            least = uses == uses.min(1, keepdim=True).values
            victim = torch.where(least, sim.amax(2), torch.full_like(sim[:, 0], -2.0)).argmax(1)   # the oldest of a tie
        drop = torch.zeros_like(self.graded)
        drop[rows, victim] = True
        freed[rows] = stored[torch.arange(rows.numel(), device=rows.device), victim]
        self.forget(drop)
        return freed

    def similarity(self, rows: torch.Tensor | None = None) -> torch.Tensor:
        """(B, A, A) (or the agents `rows`' (F, A, A)): how alike each two stored objects are, the score `object_match`
        gives one's stored patterns shown as the other's: sum_m s_m d_abm / sum_m s_m over the maps both were stored
        with, d_abm = W_am . W_bm / max(W_am . W_am, W_bm . W_bm) (symmetric; 1 for the same pattern, 0 for bumps
        that do not overlap), s_m the pathway strengths. 0 for an empty slot."""
        rows = torch.arange(self.graded.shape[0], device=self.graded.device) if rows is None else rows
        br, norm = self.branches[rows], self.branch_norm[rows]                          # (F, A, P, U), (F, A, P)
        dot = torch.einsum("fapu,fbpu->fabp", br, br)
        d = (dot / torch.maximum(norm[:, :, None], norm[:, None, :]).clamp_min(1e-12)).clamp(0.0, 1.0)
        gate = self.strength[rows][:, None, None, :] * ((norm[:, :, None] > 0) & (norm[:, None, :] > 0))
        den = gate.sum(-1)
        return torch.where(den > 0, (gate * d).sum(-1) / den.clamp_min(1e-12), torch.zeros_like(den))

    @torch.no_grad()
    def forget(self, drop: torch.Tensor) -> None:
        """Agent b's stored objects in the slots where drop (B, max_assemblies) bool is True leave the hub (slots at
        or past n_assemblies are ignored): their assemblies, branches (a name bound to one goes with it) and their
        neurons' usage. The survivors keep their order, moved down to slots 0 .. n_assemblies - 1 with the rest
        zero: the hub is then exactly one that only ever stored the survivors (in that order, with the pathway
        strengths as they are). Other agents are untouched."""
        B, A = self.graded.shape
        drop = drop.to(device=self.graded.device, dtype=torch.bool)
        if tuple(drop.shape) != (B, A):
            raise ValueError(f"drop shape {tuple(drop.shape)}, expected ({B}, {A})")
        slots = torch.arange(A, device=drop.device)
        drop = drop & (slots < self.n_assemblies[:, None])
        rows = drop.any(1).nonzero().flatten()
        if rows.numel() == 0:
            return
        d = drop[rows]
        self.usage[rows] -= (self.assemblies[rows] & d[:, :, None]).sum(1)
        order = torch.sort(d.to(torch.uint8), dim=1, stable=True).indices              # kept first, in order
        n = self.n_assemblies[rows] - d.sum(1)
        live = slots < n[:, None]                                                       # (F, A)
        for name in ("assemblies", "branches", "branch_norm", "graded"):
            buf = getattr(self, name)
            part = buf[rows]
            tail = [1] * (part.ndim - 2)
            kept = part.gather(1, order.view(*order.shape, *tail).expand_as(part))
            buf[rows] = torch.where(live.view(*live.shape, *tail), kept, torch.zeros_like(kept))
        self.n_assemblies[rows] = n

    def _pick(self, generator: torch.Generator | None) -> torch.Tensor:
        """The next assembly (B, N) bool, chosen neuron by neuron so that codes stay apart as objects multiply: each
        next neuron is the one that keeps the largest overlap with any stored assembly smallest, then shares the
        fewest stored assemblies with the neurons already chosen, then is the least used. (Least-used alone dealt
        the 11th object the 1st one's exact code.) Remaining ties: random with a generator (drawn for every agent,
        so it advances the same way whatever the mask); without one, the lower index, which keeps an agent's
        choice independent of the other agents in its batch."""
        (B, N), dev, per_row = self.usage.shape, self.usage.device, self.config.n_neurons
        if generator is None:
            jitter = torch.arange(N, device=dev).expand(B, N) * (0.5 / N)
        else:
            jitter = torch.rand(B, N, generator=generator).to(dev) * 0.5
        stored = self.assemblies.to(torch.float64)                       # (B, A, N), empty slots all zero
        overlap = stored.new_zeros(stored.shape[:2])                     # (B, A) chosen neurons in each
        chosen = torch.zeros(B, N, dtype=torch.bool, device=dev)
        usage = self.usage.to(torch.float64)
        jitter = jitter.to(torch.float64)
        big = float(stored.shape[1] + 1)
        for i in range(self.assembly_neurons):
            # rows fill in turn: only the neurons of this one are candidates (scored alone, 1/rows of the work)
            first = i // self.config.assembly_size * per_row
            cols = slice(first, first + per_row)
            row_stored = stored[:, :, cols]                                # (B, A, per_row)
            worst = (overlap[:, :, None] + row_stored).amax(1)             # (B, per_row)
            shared = torch.einsum("ba,ban->bn", overlap, row_stored)
            # lexicographic: worst overlap (<= S, the assembly's size), shared (< S * A), usage (<= A), jitter (< 0.5)
            score = (worst * self.assembly_neurons * big + shared) * big + usage[:, cols] + jitter[:, cols]
            k = first + torch.where(chosen[:, cols], torch.full_like(score, float("inf")), score).argmin(-1)
            chosen[torch.arange(B, device=dev), k] = True
            overlap += stored[torch.arange(B, device=dev), :, k]
        return chosen


class _TwoHotNames:
    """Named states as 2-hot rows: state i -> neurons 2i and 2i+1. Disjoint codes, decodable, the memory's row
    sparsity (2 active of 50)."""

    names: tuple = ()

    def __init__(self, n_neurons: int = N_NEURONS):
        if 2 * len(self.names) > n_neurons:
            raise ValueError(f"{len(self.names)} names need {2 * len(self.names)} neurons, only {n_neurons}")
        self.n_neurons = n_neurons

    def encode(self, names) -> torch.Tensor:
        """A name -> (N,) bool; a list of B names -> (B, N) bool."""
        single = isinstance(names, str)
        names = [names] if single else list(names)
        out = torch.zeros(len(names), self.n_neurons, dtype=torch.bool)
        for b, n in enumerate(names):
            if n not in self.names:
                raise ValueError(f"unknown {type(self).__name__} name '{n}' (known: {', '.join(self.names)})")
            i = self.names.index(n)
            out[b, 2 * i:2 * i + 2] = True
        return out[0] if single else out

    def decode(self, rows: torch.Tensor):
        """(N,) -> name or None; (B, N) -> list of names (None where the row is not exactly one name's code).
        Float rows count a neuron as active above 0.5."""
        rows = torch.as_tensor(rows)
        if rows.shape[-1] != self.n_neurons or rows.ndim not in (1, 2):
            raise ValueError(f"rows must be (N,) or (B, N) with N = {self.n_neurons}, got {tuple(rows.shape)}")
        single = rows.ndim == 1
        on = (rows > 0.5).reshape(-1, self.n_neurons)
        codes = self.encode(list(self.names))                       # (S, N)
        hit = (on[:, None, :] == codes[None]).all(-1)                # (B, S)
        out = [self.names[int(h.nonzero()[0])] if h.any() else None for h in hit]
        return out[0] if single else out


class ActionHub(_TwoHotNames):
    """Abstract action goals ("what can be done with an object"), the paper's canonical-neuron-like hub."""
    names = ("reach", "grasp", "lift", "carry", "drop", "release")


class BodyHub(_TwoHotNames):
    """States of the body."""
    names = ("goal_unreachable", "goal_reached", "holding", "hand_free")


class Fate(_TwoHotNames):
    """What became of a dropped object, as the robot sees it in the jar: it floats at the surface, or it sank and
    rests on the bottom. Stored with the episode; the rules compare like with like (`rules.CONTEXTS`)."""
    names = ("floated", "sank")


@dataclass
class RewardConfig:
    # volumes from min_cm3 to max_cm3 on a log scale: a relative step, the same at 5 cm^3 as at 500 (a linear 2 cm^3
    # step was 40 % of a 5 cm^3 floater). 1250 cm^3 raises the default jar's water by 11 cm, more than any object
    # that fits through its mouth displaces; smaller and larger volumes are clamped
    min_cm3: float = 0.5
    max_cm3: float = 2000.0
    # 25 coarse x 25 fine units: 625 levels over a factor 4000, a step of 1.3 %, so a volume is stored within 0.7 %,
    # finer than a reading of the smallest displacements (~0.1 cm^3 of level resolution on a few cm^3)
    coarse: int = 25
    fine: int = 25


class RewardCode:
    """A displaced volume as a 2-hot memory row: one of `coarse` units plus one of `fine` units.

    level = coarse_index * fine + fine_index, value = min_cm3 * (max_cm3 / min_cm3) ** (level / (levels - 1)):
    a logarithmic code. Encoding rounds log(volume) to the nearest level and clamps to min_cm3..max_cm3.
    """

    def __init__(self, config: RewardConfig | None = None, n_neurons: int = N_NEURONS):
        self.config = c = config or RewardConfig()
        if c.coarse + c.fine > n_neurons:
            raise ValueError(f"coarse + fine = {c.coarse + c.fine} units do not fit in {n_neurons} neurons")
        if not 0 < c.min_cm3 < c.max_cm3:
            raise ValueError(f"RewardConfig needs 0 < min_cm3 < max_cm3, got {c.min_cm3}, {c.max_cm3}")
        self.n_neurons = n_neurons
        self.levels = c.coarse * c.fine
        self.step = math.log(c.max_cm3 / c.min_cm3) / (self.levels - 1)   # in log(cm^3) per level

    def encode(self, cm3) -> torch.Tensor:
        """(...) volumes in cm^3 -> (..., N) bool 2-hot rows."""
        c = self.config
        v = torch.as_tensor(cm3, dtype=torch.float64)
        if not torch.isfinite(v).all():
            raise ValueError("reward volumes must be finite")
        level = (v.clamp(min=c.min_cm3).log() - math.log(c.min_cm3)) / self.step
        q = torch.floor(level + 0.5).clamp(0, self.levels - 1).long()
        out = torch.zeros(*v.shape, self.n_neurons, dtype=torch.bool)
        out.scatter_(-1, (q // c.fine)[..., None], True)
        out.scatter_(-1, (c.coarse + q % c.fine)[..., None], True)
        return out

    def decode(self, rows: torch.Tensor) -> torch.Tensor:
        """(..., N) rows (bool or float, active above 0.5) -> (...) cm^3, NaN where the row is not exactly one
        coarse and one fine unit (and nothing else)."""
        c = self.config
        rows = torch.as_tensor(rows)
        if rows.ndim == 0 or rows.shape[-1] != self.n_neurons:
            raise ValueError(f"rows must have last dimension {self.n_neurons}, got shape {tuple(rows.shape)}")
        on = rows > 0.5
        coarse, fine, rest = on[..., :c.coarse], on[..., c.coarse:c.coarse + c.fine], on[..., c.coarse + c.fine:]
        valid = (coarse.sum(-1) == 1) & (fine.sum(-1) == 1) & ~rest.any(-1)
        level = (coarse.long().argmax(-1) * c.fine + fine.long().argmax(-1)).double()
        value = (math.log(c.min_cm3) + level * self.step).exp().float()
        return torch.where(valid, value, torch.full_like(value, math.nan))

    def stored(self, cm3) -> torch.Tensor:
        """A volume as the memory holds it: encoded and decoded (within half a level, 0.7 %)."""
        return self.decode(self.encode(cm3))
