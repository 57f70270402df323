"""Episodic memory: an excitatory-inhibitory auto-associative network of 20 x 50 neurons (the paper's sheet).

Each row of the sheet is one event of an episode (object hub, action hub, body hub or reward activity) and the
whole sheet is one episode. Encoding is one-shot; a partial cue (the object hub activity of what is in view)
recalls the whole episode, and several episodes can be recalled for one cue, each with a strength.

The paper defers the network to Mohan et al. 2014 and Hopfield 2008 (not available here); this one is our choice:

- Weights: the covariance rule over the stored episodes, J = sum_mu (xi_mu - p)(xi_mu - p)^T with a zero diagonal,
  where p is each neuron's mean activity over the stored episodes (Hebbian outer products minus the outer product
  of the running mean; both are updated one-shot by each new episode). The nominal-sparsity rule (p = k_r / 50)
  fails on the agent's episodes, which share most rows (the same reach, grasp and drop codes every time): the
  shared rows then pull every recall towards the majority episode. With the actual mean, a row every episode
  shares carries no weight (it is predicted by p alone) and a row no episode uses stays silent (p = 0, no weight).
- Each neuron's deviation counts in units of its own spread sigma_i = sqrt(p_i (1 - p_i)) (MemoryConfig.zscore):
  J~ = D^-1 J D^-1, d~ = (s - p) / sigma. Otherwise a row that takes one of two codes in every episode (the
  object's fate, the goal) outweighs the sparse rows that tell episodes apart.
- Prediction: each neuron estimates its own activity from the others, a_i = p_i + sigma_i sum_j J~_ij d~_j /
  sum_{j!=i} d~_j^2 (p is the neuron's excitability, the division a global divisive inhibition). For a stored
  episode as the state, a = xi exactly when the stored deviations are orthogonal.
- Inhibition: each row has its own inhibitory pool, a k-winners-take-all: at most k_r neurons of row r fire, and
  only those predicted above `threshold`, so a row with no support stays empty.
- Recall: the object row (or rows, `cue_rows`) is clamped to the graded cue while the other rows (unknown at first:
  d = 0) complete the pattern, then it is released and the whole sheet runs freely to a fixed point, so the object row
  becomes a stored binary code rather than the graded cue. Strength = cue . xi_obj / |xi_obj|, the mean cue activity
  on the recalled object code. After each retrieval the retrieved state is transiently depressed (anti-Hebbian: its
  outer product and its share of the mean are taken out for the rest of this recall, i.e. a retrieved stored episode
  is as if not stored) and retrieval restarts from the same cue, until the strength drops below `min_strength`, the
  state is not a fixed point, nothing is left, or `max_recalls` episodes were recalled (if bounded). With
  `cue_power` != 1 the cue's drive loses each retrieved object's neurons, and a retrieval that settles nowhere may
  take the drive's strongest neurons out and go on (`misses`). Results: strongest first.

Nothing dense is stored: J is a sum of outer products, so J d = X^T (X d) - S (S . d) / n - diag(J) d is computed
from the stored patterns X (B, max_episodes, 20, 50) bool, their sum S and count n. X d and X^T (X d) are gathers and
scatters over each pattern's active neurons (~40 of 1000; z-scored, only those that vary across the stored episodes),
with the additions in one fixed order, and every sum over the sheet taken row by row and then over the 20 rows: a
cue's recall does not depend on the batch it is computed in or on the thread count. A depressed state that is a
stored pattern has its term in X d masked; any other (a spurious fixed point, ~1.5 % of the recalls from 230 of the
agent's episodes) is subtracted as Z^T (Z d). A recall leaves out the rows that hold one code in every stored
episode (they settle at it and are no evidence) and writes that code back. `weights(b)` and `mean_activity(b)` give
the dense network of one agent for inspection and tests.

A full memory refuses one more episode, or lets its oldest or its most redundant one go (MemoryConfig.when_full,
`make_room`). Forgetting moves the survivors down in their order (`forget`), so the stored episodes are always the
slots 0 .. count - 1, oldest first, and the memory is exactly one that only ever stored them.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import NamedTuple

import torch
from torch import nn

# Divisive normalisation floor: sum_j d_j^2 of any real state is >= ~1 (a 5-neuron cue alone gives ~4.5), so 1e-3
# only guards against 0/0 and keeps float32 rounding in h (~1e-5) from being amplified.
_EPS = 1e-3


# what a full memory (MemoryConfig.when_full) or a full object hub (hub.HubConfig.when_full) does with one more
WHEN_FULL = ("refuse", "forget_oldest", "forget_weakest")


def _default_row_k() -> tuple[int, ...]:
    # object row (index 1): a 5-neuron hub assembly; every other row: an exact 2-of-50 event code
    return tuple(5 if r == 1 else 2 for r in range(20))


@dataclass
class MemoryConfig:
    rows: int = 20                  # paper: 20 events per episode
    cols: int = 50                  # paper: 50 neurons per event (= one hub)
    # the rows the cue clamps: the object hub's. Row 1 by default (row 0: the body state before acting); the agent's
    # hub spans more rows (agent.OBJECT_ROWS)
    cue_rows: tuple = (1,)
    # the cue enters the sheet relative to its strongest neuron and raised to this power (an expansive
    # nonlinearity): a neuron the cue drives at half the peak clamps at 0.5^p. 1 = as given. With p != 1, the
    # neurons of a retrieved episode's cue rows also leave the cue for the rest of that recall (they led to an
    # episode that is no longer in the weights), so the next retrieval starts from the next strongest. The strength
    # of a recall is still read with the cue as given.
    cue_power: float = 1.0
    # with cue_power != 1, a retrieval that settles nowhere (no fixed point, or strength < min_strength) is a miss:
    # the drive's neurons it clamped at >= 1/2 (drive >= peak * 0.5^(1/cue_power)) leave the drive, and retrieval
    # goes on from what is left. Recall ends after `misses` misses in a row, or with the drive spent. 0: the first
    # miss ends it. (Why: after 230 generated objects, 12 of 16 novel cues of tuning set 1000 ended on a miss with
    # the drive's peak still at 0.34-0.66, after 7-31 episodes instead of 57-92.)
    misses: int = 0
    # active neurons per row (the row's k-WTA): 5 on the object row (hub assembly), 2 elsewhere. Sparse rows give
    # the covariance rule its capacity; 5 on the cue row give the cue enough signal to pull the episode out.
    row_k: tuple = field(default_factory=_default_row_k)
    # buffer size per agent: the paper's ~230 episodes in 1000 neurons. Measured (benches/memory_capacity.py):
    # >= 99 % exact recall of random episodes up to 275, so the paper's 230 is kept, with a margin. (At 230 the
    # buffer is 230 kB per agent: a run of many agents that stores a few episodes each should lower it.)
    max_episodes: int = 230
    # what `store` does for an agent whose memory holds max_episodes already (WHEN_FULL): "refuse" raises and
    # stores nothing; "forget_oldest" lets the oldest stored episode go; "forget_weakest" the one most redundant
    # with the others (see `EpisodicMemory.make_room`). The default refuses: a library memory never loses an
    # episode its caller did not ask it to lose, and a run sized for its objects never needs to (the runner can
    # check the sizes up front). Forgetting is exact either way (the weights are a sum over the stored patterns):
    # the memory is then bit for bit one that only ever stored the survivors, in their order.
    when_full: str = "refuse"
    # clamped (pattern completion) and free (object row released) iterations; each cue stops at its own fixed
    # point. At 230 random episodes completion settles in ~5 clamped steps (exact recall is the same with a cap of
    # 4, 8 or 12), a cue still moving after 8 goes on in the free phase; free running ends in ~2 steps.
    cue_steps: int = 8
    free_steps: int = 12
    # a neuron fires only if the others predict its activity above this (and it wins its row). 1/2 would be "more
    # likely on than off"; a little lower lets rows with partial support join the completion early (300 random
    # episodes, 3 seeds: 98.2 / 98.0 / 97.7 % exact at 0.3 / 0.4 / 0.5; agent-like episodes are indifferent).
    threshold: float = 0.4
    # each neuron's deviation in units of its own spread, sigma_i = sqrt(p_i (1 - p_i)) (the covariance rule on
    # z-scored activity). The plain rule lets a row that takes one of two codes in every episode (floated / sank,
    # goal reached or not: sigma 0.5) outweigh the sparse rows that tell episodes apart. Measured from the object
    # row alone (tests/test_memory.py, benches/memory_capacity.py): the agent's own episodes exact up to ~32
    # instead of ~16, random episodes exact at 300 instead of 97 %. False: the plain covariance rule.
    zscore: bool = True
    # graded recall: every episode the cue touches at all is brought back (strongest first, up to max_recalls), and
    # whoever uses it weighs it by its strength (the agent's readout and rules do). Below this the cue shares
    # nothing with the retrieved state: float rounding, not a memory (the weakest real overlap of two stored bumps,
    # their 0.05 floors through a pathway at 0.05, is ~1e-5). Any higher bound cuts pairs of objects that share
    # little, and which pairs the rules compared then depended on the order the objects came in: generated sets of
    # seeds 1000-1039 agreed in all 24 orders in 87.5 % at 0.05, 97.5 % at 0.001; seeds 1000-1099 at 0.001 lost
    # two more sets, whose sinkers cued each other at 0.0009 one way and 0.0016 the other.
    min_strength: float = 1e-6
    # most episodes recalled for one cue. None: the network's own number, every episode it settles into until a
    # stopping condition above holds (never more than the memory can hold, max_episodes: each retrieval takes one
    # state out). An int is a bound for speed, which cuts a recall that would bring back more (a memory holding no
    # more episodes than it is never cut); the agent recalls unbounded (AgentConfig).
    max_recalls: int | None = 8
    # cues recalled together (agents each with its own memory, or many cues against one): 256 keeps the
    # (256, 1000) working tensors in cache; of 16 to 1024, 256 was fastest for 984 cues against 230 of the agent's
    # episodes (1.14x 1024, 1.6x 32). And a bound on the agents' patterns handled at once (elements per chunk):
    # 2^25 however many episodes they hold.
    chunk_agents: int = 256
    chunk_elements: int = 1 << 25

    def __post_init__(self):
        if self.when_full not in WHEN_FULL:
            raise ValueError(f"MemoryConfig.when_full must be one of {', '.join(WHEN_FULL)}, got {self.when_full!r}")
        self.row_k = tuple(int(k) for k in self.row_k)
        if len(self.row_k) != self.rows:
            raise ValueError(f"MemoryConfig.row_k has {len(self.row_k)} entries, expected rows={self.rows}")
        if not all(1 <= k < self.cols for k in self.row_k):
            raise ValueError(f"MemoryConfig.row_k must lie in [1, cols={self.cols}), got {self.row_k}")
        self.cue_rows = tuple(int(r) for r in self.cue_rows)
        if not self.cue_rows or len(set(self.cue_rows)) != len(self.cue_rows) or \
                not all(0 <= r < self.rows for r in self.cue_rows):
            raise ValueError(f"MemoryConfig.cue_rows must be distinct rows in 0..{self.rows - 1}, got {self.cue_rows}")
        if min(self.max_episodes, 1 if self.max_recalls is None else self.max_recalls, self.cue_steps,
               self.free_steps) < 1:
            raise ValueError("MemoryConfig.max_episodes, max_recalls, cue_steps and free_steps must be >= 1")
        self.misses = int(self.misses)
        if self.misses < 0 or (self.misses and self.cue_power == 1):
            raise ValueError(f"MemoryConfig.misses must be >= 0, and 0 when cue_power is 1 (a miss takes neurons out "
                             f"of the cue's drive, which only cue_power != 1 uses), got misses={self.misses}")


class Recall(NamedTuple):
    """What one cue brought back, strongest first; K = max_recalls (max_episodes where unbounded)."""
    episodes: torch.Tensor  # (B, K, rows, cols) bool, zeros where not valid
    strength: torch.Tensor  # (B, K) float in [0, 1]: mean cue activity on the recalled object code, 0 where not valid
    valid: torch.Tensor     # (B, K) bool
    any: torch.Tensor       # (B,) bool: at least one episode recalled


def k_winners(a: torch.Tensor, row_k: torch.Tensor, threshold: float, finite: bool = False) -> torch.Tensor:
    """Per-row inhibition: (..., R, C) predicted activity -> bool state, the k_r largest of row r firing if above
    threshold. Exact ties go to the lower neuron index, so the result never depends on the batch. finite=True: the
    caller knows `a` holds no NaN (the check is skipped)."""
    return _fire(a, row_k, threshold, finite).bool()


def _fire(a: torch.Tensor, row_k: torch.Tensor, threshold: float, finite: bool = False) -> torch.Tensor:
    """k_winners as 0 / 1 in a's (floating) dtype: torch's CPU kernels that write bool are several times slower
    than its float ones (a comparison into bool, 74 us for 128 sheets; into float, 13 us)."""
    fire = torch.gt(a, threshold, out=a.new_empty(a.shape))   # contiguous, whatever a's strides
    k = row_k.to(a.dtype).expand(a.shape[:-1])    # compared with fire's counts: one dtype, the fast kernel
    # a row with at most k_r neurons above threshold fires them all; only the others need ranking (and a row with a
    # NaN, which the ranking puts first)
    crowded = fire.sum(-1) > k
    if not finite and bool(torch.isnan(a).any()):
        crowded |= torch.isnan(a).any(-1)
    rows = crowded.flatten().nonzero().flatten()      # the crowded rows of the (-1, C) view
    if rows.numel() == 0:
        return fire
    C = a.shape[-1]
    a, k = a.reshape(-1, C).index_select(0, rows), k.reshape(-1).index_select(0, rows)[:, None].long()  # (n, C), (n, 1)
    kmax = int(k.max())
    if kmax > 3 or (not finite and bool(torch.isnan(a).any())):   # a sort (topk ranks NaN above everything)
        kth = a.topk(kmax, dim=-1).values.gather(-1, k - 1)
    else:   # the k-th largest (counted with ties) by stepping down the row's distinct values
        kth = a.amax(-1, keepdim=True)
        for _ in range(kmax - 1):
            short = (a >= kth).sum(-1, keepdim=True) < k
            kth = torch.where(short, torch.where(a < kth, a, -torch.inf).amax(-1, keepdim=True), kth)
    above, tied = a > kth, a == kth
    room = k - above.sum(-1, keepdim=True)    # places left for neurons tied with the k-th
    win = (above | (tied & (tied.cumsum(-1) <= room))) & (a > threshold)
    fire.view(-1, C).index_copy_(0, rows, win.to(fire.dtype))
    return fire


def _differ(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """(B, ...) floats -> (B,) bool: where x and y differ anywhere (compared into floats, as in _fire)."""
    return torch.ne(x, y, out=torch.empty_like(x)).flatten(1).amax(1) > 0


def active_neurons(x: torch.Tensor, width: int | None = None) -> torch.Tensor:
    """(..., N) bool -> (..., width) long: the indices of the active neurons in increasing order, padded with N (a
    neuron that is always silent). width defaults to the most active neurons of any pattern."""
    N = x.shape[-1]
    width = int(x.sum(-1).max()) if width is None and x.numel() else width or 0
    out = torch.full((*x.shape[:-1], width + 1), N, dtype=torch.long, device=x.device)
    slot = torch.where(x, x.cumsum(-1) - 1, width)      # inactive neurons all land in the spare slot `width`
    out.scatter_(-1, slot, torch.arange(N, device=x.device).expand(x.shape))
    return out[..., :width]


_PER_CUE = frozenset({"total", "n", "z", "keep", "p", "inv", "gain", "q", "z_at", "z_real"})
_PER_MEMORY = frozenset({"idx", "sizes", "held", "common"})   # 1 (one memory for all cues) or B


@functools.lru_cache(maxsize=64)
def _owners(M: int, L: int, device) -> torch.Tensor:
    """(M * L,) the pattern each entry of the flattened (M, L) index lists belongs to: 0, 0, ..., 1, 1, ..."""
    return torch.arange(M, device=device).repeat_interleave(L)


class _Net(NamedTuple):
    """The factorised network seen by a batch of cues: the stored patterns as the indices of their active neurons
    idx (1 or B, M, L) (shared or per cue, padded with N), and per cue the sum of the patterns still in play (B, N),
    their number (B, 1), which stored patterns are in play (B, M; 1 or 0) and the depressed states that were no
    stored pattern as their active neurons (B, r, L'). The per-cue constants of a settle (mean p, 1 / sigma,
    sigma / sigma, 1 - p) are computed once by `ready` and carried along."""
    idx: torch.Tensor
    total: torch.Tensor
    n: torch.Tensor
    z: torch.Tensor
    keep: torch.Tensor | None = None
    p: torch.Tensor | None = None
    inv: torch.Tensor | None = None
    gain: torch.Tensor | None = None
    q: torch.Tensor | None = None
    # the depressed states' neurons as flat gather / scatter indices (the padding moved to neuron N - 1) and a mask
    # that is 0 on the padding
    z_at: torch.Tensor | None = None
    z_real: torch.Tensor | None = None
    # one memory for all cues: its active neurons pattern by pattern and its patterns neuron by neuron, as the
    # indices and bag offsets of embedding_bag (cols, starts, owners, firsts)
    lists: tuple | None = None
    # to tell a state that is a stored pattern (1 or B, ...): each pattern's neurons in idx (M), the neurons idx
    # holds (N) and the neurons outside them that every stored pattern has (N)
    sizes: torch.Tensor | None = None
    held: torch.Tensor | None = None
    common: torch.Tensor | None = None
    # the sheet rows the network spans (rows, as a tensor, the sheet's row count), each one's k-WTA, and where the
    # cue rows sit among them; a recall leaves out the rows that hold one code in every stored episode
    layout: tuple | None = None
    row_k: torch.Tensor | None = None
    cue_at: tuple | None = None

    def take(self, i: torch.Tensor) -> "_Net":
        if i.dtype == torch.bool:
            i = i.nonzero().flatten()
        return self._replace(**self._select(i, _PER_CUE | _PER_MEMORY))

    def _select(self, i: torch.Tensor, fields: frozenset) -> dict:
        """Rows i of the named fields that are per cue (a per-memory field of one memory for all cues stays)."""
        return {f: t.index_select(0, i) for f, t in zip(self._fields, self)
                if f in fields and t is not None and (f in _PER_CUE or t.shape[0] != 1)}

    def mean(self) -> torch.Tensor:
        return self.total / self.n.clamp(min=1)

    def sheet_sum(self, v: torch.Tensor) -> torch.Tensor:
        """(B, rows * cols) -> (B, 1): each row summed, then the whole sheet's row sums in their places (0 for a row
        the layout leaves out, where every term is 0), so a sum never depends on the layout or the batch."""
        rows, at, R = self.layout
        r = v.view(v.shape[0], len(rows), -1).sum(-1)
        if len(rows) != R:
            r = v.new_zeros(v.shape[0], R).index_copy_(1, at, r)
        return r.sum(1, keepdim=True)

    def ready(self) -> "_Net":
        """The same network with its per-cue constants: p, 1 / sigma (0 where sigma = 0), sigma / sigma, 1 - p and
        the depressed states' indices."""
        p = self.mean()
        q = 1 - p
        sigma = (p * q).sqrt()
        inv = torch.where(sigma > 1e-6, 1.0 / sigma.clamp_min(1e-6), torch.zeros_like(sigma))
        flat, N = self.z.flatten(1), p.shape[1]
        return self._replace(p=p, inv=inv, gain=sigma * inv, q=q, z_at=flat.clamp(max=N - 1),
                             z_real=(flat < N).to(p.dtype))

    def predict(self, d: torch.Tensor, zscore: bool = True) -> torch.Tensor:
        """a = p + sigma J~ d~ / sum_{j != i} d~_j^2 for deviations d (B, N) from the mean (d is overwritten),
        d~ = d / sigma, and J~ = D^-1 J D^-1 (D = diag(sigma)) of the patterns in play; zscore=False: sigma = 1, the
        plain covariance rule. A neuron that never varies (sigma = 0) is predicted at its mean and is no evidence
        for the others."""
        net = self if self.p is not None else self.ready()
        if zscore:
            h = net.covariance_product(d.mul_(net.inv) * net.inv)  # J (D^-1 d~); times D^-1 and sigma below: 1
            h.mul_(net.gain)
        else:
            h = net.covariance_product(d)
        # in place where a tensor is not needed again (the same operations, the same bits): d is the caller's scratch
        sq = d.mul_(d)
        ssq = net.sheet_sum(sq)
        return h.div_(sq.neg_().add_(ssq).clamp_(min=_EPS)).add_(net.p)

    def forward(self, d: torch.Tensor) -> torch.Tensor:
        """X d for d (B, N): (M, B) for one memory shared by all cues (embedding_bag's layout), else (B, M)."""
        if self.lists is not None:
            # d.T made contiguous with strides (B, 1): for one cue .contiguous() keeps strides (1, N), on which
            # embedding_bag takes a path 18x slower
            dt = d.T.clone(memory_format=torch.contiguous_format)
            return torch.nn.functional.embedding_bag(self.lists[0], dt, self.lists[1], mode="sum")
        B, (M, L) = d.shape[0], self.idx.shape[1:]
        de = torch.nn.functional.pad(d, (0, 1))                  # neuron N: the padding, always 0
        of = _owners(M, L, d.device).expand(B, -1)
        return de.new_zeros(B, M).scatter_add_(1, of, de.gather(1, self.idx.flatten(1)))

    def stored(self, x: torch.Tensor, keep: torch.Tensor, who: torch.Tensor) -> torch.Tensor:
        """For states x (B, N) bool of the cues `who` (B,), whose patterns in play are `keep` (B, M): the first stored
        pattern in play that equals each state, or -1 (B,) long."""
        net = self._replace(keep=keep, **self._select(who, _PER_MEMORY))
        u = net.forward(x.to(keep.dtype))
        shared = u.T if net.lists is not None else u                  # (B, M): the shared neurons, counted
        x8, held8 = x.view(torch.uint8), net.held.view(torch.uint8)   # bytes: torch's bool kernels are slow
        inside = (x8 & held8).sum(1, keepdim=True)
        rest = ((x8 ^ net.common.view(torch.uint8)) & (held8 ^ 1)).amax(1, keepdim=True) == 0   # the common code
        same = (shared == net.sizes) & (net.sizes == inside) & (keep > 0) & rest
        return torch.where(same.any(1), same.to(torch.uint8).argmax(1), -1)

    def covariance_product(self, d: torch.Tensor) -> torch.Tensor:
        """J d for d (B, N), J = sum_mu (x_mu - p)(x_mu - p)^T with a zero diagonal, over the patterns in play.

        X^T (X d) and the depressed states' Z^T (Z d) are gathers and scatters over the active neurons (~40 of
        1000 in a pattern) rather than dense products; each output a sum from 0 in increasing index order."""
        S, n = self.total, self.n
        p = self.p if self.p is not None else S / n.clamp(min=1)
        B, N = d.shape
        u = self.forward(d)
        if self.keep is not None:   # depressed stored patterns out (x 1 leaves a term as it was, bit for bit)
            u.mul_(self.keep.T if self.lists is not None else self.keep)
        if self.lists is not None:   # (M, B) -> (N, B): each bag sums whole rows, in order
            h = torch.nn.functional.embedding_bag(self.lists[2], u, self.lists[3], mode="sum").T.contiguous()
        else:   # each cue its own memory, the additions in the same order: pattern by pattern, then neuron by neuron
            M, L = self.idx.shape[1:]
            flat = self.idx.flatten(1)
            h = d.new_zeros(B, N + 1).scatter_add_(1, flat, u.index_select(1, _owners(M, L, d.device)))[:, :N]
        if self.z.shape[1]:
            # the padding entries (neuron N) gather and scatter zeros at neuron N - 1: a running sum from 0 is never
            # -0, so adding a zero of either sign leaves it as it was
            r, L = self.z.shape[1:]
            of = _owners(r, L, d.device)
            net = self if self.z_at is not None else self.ready()
            flat, real = net.z_at, net.z_real
            w = d.new_zeros(B, r).scatter_add_(1, of.expand(B, -1), d.gather(1, flat) * real)   # (B, r) = Z d
            h.scatter_add_(1, flat, w.neg_().index_select(1, of) * real)
        # minus the mean's outer product n p p^T (S = n p), and the diagonal sum_mu (x_i - p_i)^2 = S_i (1 - p_i)
        t = (1 - p if self.q is None else self.q) * d
        return h.sub_(t.add_(self.sheet_sum(p * d)).mul_(S))


class EpisodicMemory(nn.Module):
    """B independent episodic memories (leading batch dim), one-shot store and multi-episode recall."""

    def __init__(self, config: MemoryConfig | None = None, batch: int = 1):
        super().__init__()
        self.config = c = config or MemoryConfig()
        self.batch = batch
        self.register_buffer("patterns", torch.zeros(batch, c.max_episodes, c.rows, c.cols, dtype=torch.bool))
        self.register_buffer("count", torch.zeros(batch, dtype=torch.long))
        self.register_buffer("row_k", torch.tensor(c.row_k, dtype=torch.long), persistent=False)

    # -- encoding ---------------------------------------------------------------------------------------------
    @torch.no_grad()
    def store(self, episode: torch.Tensor, mask: torch.Tensor | None = None) -> None:
        """One-shot encoding of episode (B, rows, cols) bool for the agents where mask (B,) is True (default all).

        Each row r of an episode holds either nothing or exactly `config.row_k[r]` active neurons (the row's
        inhibitory pool lets no more fire in recall): by default 5 on the object row (a hub assembly) and 2 on every
        other row (a 2-hot event code); the cue rows must not all be empty, since they are what cues the episode.
        ValueError otherwise. A masked agent whose memory is full first makes room as MemoryConfig.when_full says
        (`make_room`): under "refuse", RuntimeError, storing nothing for any agent."""
        c, B = self.config, self.batch
        if tuple(episode.shape) != (B, c.rows, c.cols):
            raise ValueError(f"episode shape {tuple(episode.shape)}, expected ({B}, {c.rows}, {c.cols})")
        if episode.dtype != torch.bool:
            if ((episode != 0) & (episode != 1)).any():
                raise ValueError("episode must be binary (bool or 0/1)")
            episode = episode != 0
        mask = torch.ones(B, dtype=torch.bool) if mask is None else mask.to(torch.bool)
        if tuple(mask.shape) != (B,):
            raise ValueError(f"mask shape {tuple(mask.shape)}, expected ({B},)")
        episode, mask = episode.to(self.patterns.device), mask.to(self.patterns.device)
        n = episode.sum(-1)  # (B, rows)
        bad = mask[:, None] & (n != 0) & (n != self.row_k)
        if bad.any():
            b, r = bad.nonzero()[0].tolist()
            raise ValueError(f"episode of agent {b}: row {r} has {int(n[b, r])} active neurons, "
                             f"expected 0 or {int(self.row_k[r])}")
        if (mask & (n[:, list(c.cue_rows)].sum(-1) == 0)).any():
            raise ValueError(f"episode has empty cue rows {c.cue_rows}: it could never be cued")
        self.make_room(mask, episode)
        idx = mask.nonzero().flatten()
        self.patterns[idx, self.count[idx]] = episode[idx]
        self.count[idx] += 1

    @torch.no_grad()
    def make_room(self, mask: torch.Tensor, incoming: torch.Tensor | None = None) -> torch.Tensor:
        """For the agents in mask (B,) whose memory is full, one stored episode leaves, as MemoryConfig.when_full
        says; returns the episodes that left (B, rows, cols) bool (empty for the other agents). incoming (B, rows,
        cols): the episodes about to be stored (what "forget_weakest" weighs the stored ones against), or None.

        - "refuse": RuntimeError naming the limit and the field to change; nothing changes.
        - "forget_oldest": the episode stored first (slot 0).
        - "forget_weakest": the episode most redundant with the others: the one that shares the most active neurons
          with another episode (stored, or the one coming in); of a tie (two episodes as alike as each other), the
          older. Why: the memory is a covariance network, so what an episode adds is what the others do not already
          hold. One whose near-twin stays loses least when it goes (the same object stored again after a
          contradiction: its older outcome leaves, its newer one comes in), and overlapping patterns are what the
          rule stores worst (each pulls the other's recall), so the most overlapping is also the one whose leaving
          relieves the others most. It needs nothing beyond the stored patterns: a recall still changes nothing (a
          probe of an agent, a goal recall through a view of its memory, a shared recall cache stay what they
          are) and the state dict is as before. Not chosen: the episode recalled least often. A count kept at
          recall makes every query learn (probing an agent would change what it later forgets), and it starves the
          newest episode, which has had no chance to be recalled yet: each new one would push out the one stored
          just before it.

        The survivors keep their order (`forget`): the memory is exactly one that stored only them."""
        c, B = self.config, self.batch
        mask = mask.to(device=self.count.device, dtype=torch.bool)
        if tuple(mask.shape) != (B,):
            raise ValueError(f"mask shape {tuple(mask.shape)}, expected ({B},)")
        left = torch.zeros(B, c.rows, c.cols, dtype=torch.bool, device=self.patterns.device)
        full = mask & (self.count >= c.max_episodes)
        if not full.any():
            return left
        if c.when_full == "refuse":
            raise RuntimeError(f"episodic memory full: agents {full.nonzero().flatten().tolist()} already hold "
                               f"max_episodes={c.max_episodes} episodes (nothing stored); raise "
                               f"MemoryConfig.max_episodes or set MemoryConfig.when_full to 'forget_oldest' or "
                               f"'forget_weakest'")
        rows = full.nonzero().flatten()
        victim = torch.zeros(rows.numel(), dtype=torch.long, device=rows.device)     # forget_oldest: slot 0
        if c.when_full == "forget_weakest":
            # a full memory holds max_episodes episodes: (F, M, N) against themselves and the incoming ones
            x = self.patterns[rows].flatten(2).float()
            shared = torch.bmm(x, x.transpose(1, 2))                                   # exact: counts <= rows*cols
            shared.diagonal(dim1=1, dim2=2).fill_(-1.0)                                # not with itself
            most = shared.amax(2)
            if incoming is not None:
                new = incoming.to(self.patterns.device)[rows].flatten(1).float()
                most = torch.maximum(most, torch.bmm(x, new[:, :, None])[:, :, 0])
            victim = most.argmax(1)            # the first of the most redundant: the oldest of a tie
        drop = torch.zeros_like(self.patterns[:, :, 0, 0])
        drop[rows, victim] = True
        left[rows] = self.patterns[rows, victim]
        self.forget(drop)
        return left

    @torch.no_grad()
    def forget(self, drop: torch.Tensor) -> None:
        """Agent b's stored episodes in the slots where drop (B, max_episodes) bool is True leave its memory (slots
        at or past its count are ignored). The survivors keep their order, moved down to slots 0.. count - 1 with
        the rest zero, so the memory is bit for bit one that only ever stored the survivors in that order: its
        weights (a sum over the stored patterns) lose exactly the forgotten terms, and its recalls are that
        memory's. Other agents are untouched."""
        c, B, M = self.config, self.batch, self.patterns.shape[1]
        drop = drop.to(device=self.patterns.device, dtype=torch.bool)
        if tuple(drop.shape) != (B, M):
            raise ValueError(f"drop shape {tuple(drop.shape)}, expected ({B}, {M})")
        slots = torch.arange(M, device=drop.device)
        drop = drop & (slots < self.count[:, None])
        rows = drop.any(1).nonzero().flatten()
        if rows.numel() == 0:
            return
        d = drop[rows]
        order = torch.sort(d.to(torch.uint8), dim=1, stable=True).indices             # kept first, in order
        kept = self.patterns[rows].gather(1, order[:, :, None, None].expand(-1, -1, c.rows, c.cols))
        n = self.count[rows] - d.sum(1)
        self.patterns[rows] = kept & (slots < n[:, None])[:, :, None, None]
        self.count[rows] = n

    @torch.no_grad()
    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Forget everything (for the agents where mask is True, default all)."""
        mask = torch.ones(self.batch, dtype=torch.bool) if mask is None else mask.to(torch.bool)
        mask = mask.to(self.count.device)
        self.patterns[mask] = False
        self.count[mask] = 0

    # -- the network, dense (inspection) and factorised -------------------------------------------------------
    def _stored(self, b: int) -> torch.Tensor:
        return self.patterns[b, :int(self.count[b])].flatten(1).double()

    def mean_activity(self, b: int = 0) -> torch.Tensor:
        """Agent b's (N,) mean activity p over its stored episodes (zeros when empty)."""
        x = self._stored(b)
        return x.mean(0) if x.shape[0] else torch.zeros(x.shape[1], dtype=x.dtype, device=x.device)

    def weights(self, b: int = 0) -> torch.Tensor:
        """Agent b's dense (N, N) weights J = sum_mu y_mu y_mu^T with a zero diagonal, y = (xi_mu - p) / sigma
        (0 where sigma = 0) with MemoryConfig.zscore, else y = xi_mu - p."""
        p = self.mean_activity(b)
        y = self._stored(b) - p
        if self.config.zscore:
            sigma = (p * (1 - p)).sqrt()
            y = torch.where(sigma > 1e-6, y / sigma.clamp_min(1e-6), torch.zeros_like(y))
        J = y.T @ y
        J.fill_diagonal_(0.0)
        return J

    def _net(self, mem: slice, batch: int, compact: bool = False) -> tuple[_Net, torch.Tensor]:
        """The network of memories `mem` for `batch` cues, and the code (1 or B, rows, cols) bool that every stored
        episode of a memory holds on each row (all False where the episodes differ). compact=True: the network
        spans only the cue rows and the rows where the episodes differ. A row that holds one code in every episode
        settles at it in every recall (those neurons are predicted at their mean, 0 or 1, and give no evidence),
        so a recall leaves it out and writes the code back: the agent's sheet has 5 such rows of 20."""
        c = self.config
        x = self.patterns[mem, :int(self.count[mem].max())]
        total, count = x.sum(1), self.count[mem][:, None, None]
        code, varies = (total == count) & (count > 0), (total > 0) & (total < count)     # (b, rows, cols)
        rows = tuple(r for r in range(c.rows) if not compact or varies[:, r].any() or r in c.cue_rows)
        x, total, count = x[:, :, list(rows)].flatten(2), total[:, list(rows)].flatten(1), count[:, :, 0]
        held = torch.ones_like(total, dtype=torch.bool)
        if c.zscore:
            # a neuron every stored episode uses or none does (p = 0 or 1, sigma = 0; and so for the rest of a recall,
            # depression only takes episodes out) is predicted at its mean whatever J says, and its deviation
            # counts 0 for the others: its synapses are left out of the products
            held = varies[:, list(rows)].flatten(1)
            x = x & held[:, None]
        lists = None
        if x.shape[0] == 1:
            def bags(m: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
                size = m.sum(1)
                return m.nonzero()[:, 1], size.cumsum(0) - size
            lists = (*bags(x[0]), *bags(x[0].T))
        M = x.shape[1]
        keep = (torch.arange(M, device=x.device) < count).float()      # patterns beyond a memory's count: none
        return _Net(active_neurons(x), total.float().expand(batch, -1).contiguous(),
                    count.float().expand(batch, 1).contiguous(),
                    torch.zeros(batch, 0, 0, dtype=torch.long, device=x.device),
                    keep=keep.expand(batch, -1).contiguous(), lists=lists, sizes=x.sum(-1).float(), held=held,
                    common=~held & code[:, list(rows)].flatten(1),
                    layout=(rows, torch.tensor(rows, device=x.device), c.rows), row_k=self.row_k[list(rows)],
                    cue_at=tuple(rows.index(r) for r in c.cue_rows)), code

    @torch.no_grad()
    def predict(self, state: torch.Tensor) -> torch.Tensor:
        """What the network predicts for every neuron given the others, for states (B, rows, cols) in [0, 1]."""
        net, _ = self._net(slice(None), self.batch)
        s = state.flatten(1).to(net.total)
        return net.predict(s - net.mean(), self.config.zscore).view(state.shape)

    # -- recall -----------------------------------------------------------------------------------------------
    @torch.no_grad()
    def recall(self, cue: torch.Tensor, max_recalls: int | None = None) -> Recall:
        """Recall the episodes the graded object-hub cue (B, cols * len(cue_rows)) in [0, 1] points to, strongest
        first (a cue of one row may also be given as (B, cols), of several as (B, len(cue_rows), cols)). max_recalls:
        the config's by default; None there: no bound (K = max_episodes slots, the rest invalid).

        B equals the memory's batch, or the memory has batch 1 and serves B cues (many cues, one memory)."""
        c = self.config
        K = c.max_recalls if max_recalls is None else int(max_recalls)
        K = c.max_episodes if K is None else K
        if K < 1:
            raise ValueError(f"max_recalls must be >= 1, got {K}")
        n_cue = len(c.cue_rows) * c.cols
        if cue.dim() == 3 and tuple(cue.shape[1:]) == (len(c.cue_rows), c.cols):
            cue = cue.flatten(1)
        if cue.dim() != 2 or cue.shape[1] != n_cue:
            raise ValueError(f"cue shape {tuple(cue.shape)}, expected (B, {n_cue})")
        if cue.shape[0] != self.batch and self.batch != 1:
            raise ValueError(f"cue batch {cue.shape[0]} does not match the memory batch {self.batch}")
        cue = cue.to(self.patterns.device, torch.float32)
        if not ((cue >= -1e-5) & (cue <= 1 + 1e-5)).all():   # float rounding of a normalised activity is fine
            raise ValueError("cue activity must lie in [0, 1] (and not be NaN)")
        cue = cue.clamp(0.0, 1.0)
        B, M, dev = cue.shape[0], int(self.count.max()), cue.device
        episodes = torch.zeros(B, K, c.rows, c.cols, dtype=torch.bool, device=dev)
        strength = torch.zeros(B, K, device=dev)
        valid = torch.zeros(B, K, dtype=torch.bool, device=dev)
        if M > 0:
            shared = self.batch == 1
            step = c.chunk_agents if shared else max(1, min(c.chunk_agents, c.chunk_elements // (M * c.rows * c.cols)))
            for lo in range(0, B, step):
                sl = slice(lo, min(B, lo + step))
                with torch.inference_mode():   # no autograd bookkeeping on the ~10^4 small operations: ~6 % faster
                    net, code = self._net(slice(0, 1) if shared else sl, sl.stop - sl.start, compact=True)
                    self._recall(cue[sl], net, code, episodes[sl], strength[sl], valid[sl])
        # strongest first, valid before invalid (stable: equal strengths keep their retrieval order)
        key = torch.where(valid, strength, torch.full_like(strength, -1.0))
        order = torch.sort(key, dim=1, descending=True, stable=True).indices
        episodes = episodes.gather(1, order[:, :, None, None].expand_as(episodes))
        return Recall(episodes, strength.gather(1, order), valid.gather(1, order), valid.any(1))

    def _recall(self, cue, net, code, episodes, strength, valid):
        """Retrieve, depress, retrieve again; writes into the (B, K, ...) outputs (the rows the network leaves out
        from `code`)."""
        c = self.config
        B, K = cue.shape[0], episodes.shape[1]
        rows = list(net.layout[0])
        got = torch.zeros(B, K, len(rows), c.cols, dtype=torch.bool, device=cue.device)
        # depressed states that were no stored pattern (spurious fixed points), each cue's in order
        z = torch.full((B, K, sum(c.row_k)), net.total.shape[1], dtype=torch.long, device=cue.device)
        spurious = torch.zeros(B, dtype=torch.long, device=cue.device)
        slot = torch.zeros(B, dtype=torch.long, device=cue.device)     # episodes recalled so far
        missed = torch.zeros(B, dtype=torch.long, device=cue.device)   # retrievals in a row that settled nowhere
        total, n, keep = net.total.clone(), net.n.clone(), net.keep.clone()
        idx = torch.arange(B, device=cue.device)[n[:, 0] > 0]
        drive = cue.clone()               # the cue less the objects already retrieved (with cue_power != 1)
        while idx.numel():
            zr = int(spurious[idx].max())
            sub = net._replace(total=total, n=n, z=z[:, :zr], keep=keep).take(idx).ready()
            state, fixed = self._settle(cue[idx] if c.cue_power == 1 else drive[idx], sub)
            obj = state[:, list(net.cue_at)].flatten(1).float()
            s = (cue[idx] * obj).sum(1) / obj.sum(1).clamp(min=1.0)
            ok = fixed & (s >= c.min_strength)
            good, bad = idx[ok], idx[~ok]
            r = slot[good]
            got[good, r], strength[good, r], valid[good, r] = state[ok], s[ok], True
            slot[good] += 1
            missed[good] = 0
            if good.numel():
                # depression: the retrieved state leaves the weights and the mean for the rest of this recall; a
                # stored pattern by masking its term, any other state by subtracting its outer product
                kept = state[ok].flatten(1)
                m = net.stored(kept, keep.index_select(0, good), good)
                hit = m >= 0
                keep[good[hit], m[hit]] = 0.0
                odd = good[~hit]
                z[odd, spurious[odd]] = active_neurons(kept[~hit], z.shape[2])   # at most sum(row_k) active
                spurious[odd] += 1
                total[good] -= kept.float()
                n[good] -= 1
                drive[good] *= 1 - obj[ok]
                good = good[(n[good, 0] > 0) & (slot[good] < K)]
            missed[bad] += 1
            bad = bad[missed[bad] <= c.misses]
            if bad.numel():
                # a miss: the drive's neurons clamped at >= 1/2 leave it (its peak among them, so each miss takes
                # at least one out); a cue whose drive is spent is done
                d = drive[bad]
                d = torch.where(d >= d.amax(1, keepdim=True) * 0.5 ** (1 / c.cue_power), torch.zeros_like(d), d)
                drive[bad] = d
                bad = bad[d.amax(1) > 0]
            idx = torch.cat([good, bad]).sort().values
        episodes.copy_(code[:, None] & valid[:, :, None, None])
        episodes[:, :, rows] = got

    def _settle(self, cue: torch.Tensor, net: _Net) -> tuple[torch.Tensor, torch.Tensor]:
        """Clamped pattern completion, then free running; returns (state (B, rows, cols) bool, fixed point (B,)).

        Each cue stops iterating at its own fixed point (the dynamics are deterministic, so it would stay there):
        only the cues still moving are carried on. A cue whose clamped phase ends at a fixed point starts the free
        phase from that state, whose prediction the clamped phase's last step has just made: its winners are taken
        as the free phase's first step (13 % fewer steps for 8 recalls from 230 of the agent's episodes). A cue
        whose free state comes back to where it was two steps before alternates for ever: it is let go as not fixed
        at once instead of after `free_steps` (3 % of the settles of 16 recalls from 230 of the agent's episodes,
        8 % of their steps)."""
        c = self.config
        B, R, C = cue.shape[0], len(net.layout[0]), c.cols
        s = net.p.view(B, R, C).clone()    # unknown rows sit at the mean: no evidence either way
        rows = list(net.cue_at)
        if c.cue_power != 1:              # relative to the strongest neuron, then the power
            peak = cue.amax(1, keepdim=True)
            cue = torch.where(peak > 0, cue / peak.clamp_min(1e-12), cue) ** c.cue_power
        cue = cue.view(B, len(rows), C)
        s[:, rows] = cue
        runs, at = [], 0   # the cue rows as runs of consecutive rows: (first cue row of the run, (lo, hi))
        for r in rows:
            if runs and runs[-1][1][1] == r:
                runs[-1] = (runs[-1][0], (runs[-1][1][0], r + 1))
            else:
                runs.append((at, (r, r + 1)))
            at += 1
        # a prediction is NaN only where sigma is (p outside [0, 1], after depressing a state that was no stored
        # episode); otherwise k_winners need not look for NaN
        finite = not c.zscore or not bool(torch.isnan(net.gain).any())
        # the winners of the clamped phase's last step (before the cue rows are clamped again) for the cues that
        # end it at a fixed point: the free phase's first step
        ahead = torch.zeros(B, R, C, device=cue.device)
        known = torch.zeros(B, dtype=torch.bool, device=cue.device)
        fixed = torch.ones(B, dtype=torch.bool, device=cue.device)
        for clamp, steps in ((True, c.cue_steps), (False, c.free_steps)):
            idx, sub, cur, q = torch.arange(B, device=cue.device), net, s, cue   # the cues still moving
            prev = prev2 = None   # the winners one and two steps back, once cur is binary (the free phase)
            for step in range(steps):
                if clamp or step or not bool(known.any()):
                    fired = self._winners(sub, cur, finite)
                else:
                    fired, todo = ahead, ~known
                    if bool(todo.any()):
                        fired[todo] = self._winners(sub.take(todo), cur[todo], finite)
                new = fired.clone() if clamp else fired
                if clamp:
                    for at, (lo, hi) in runs:   # new[:, rows] = q, a slice per run of consecutive rows
                        new[:, lo:hi] = q[:, at:at + hi - lo]
                moving = _differ(new, cur) if prev is None else _differ(fired, prev)
                if clamp and not bool(moving.all()):
                    done = ~moving
                    ahead[idx[done]] = fired[done]
                    known[idx[done]] = True
                if prev2 is not None:   # back where it was two steps ago: it alternates for ever, never fixed
                    cycle = moving & ~_differ(fired, prev2)
                    if bool(cycle.any()):
                        fixed[idx[cycle]] = False
                        moving &= ~cycle
                if moving.all():
                    cur, prev2, prev = new, prev, None if clamp else fired
                    continue
                s[idx] = new
                keep = moving.nonzero().flatten()
                idx, sub, cur, q = idx[keep], sub.take(keep), new.index_select(0, keep), q.index_select(0, keep)
                prev2 = None if prev is None else prev.index_select(0, keep)
                prev = None if clamp else fired.index_select(0, keep)
                if idx.numel() == 0:
                    break
            else:
                s[idx] = cur
        fixed[idx] = False                  # still moving when the free phase ran out of steps
        return s.bool(), fixed

    def _winners(self, net: _Net, state: torch.Tensor, finite: bool) -> torch.Tensor:
        """One step of the dynamics: the row-wise k-winners (0 / 1) of what the network predicts for states
        (B, R, C)."""
        c = self.config
        a = net.predict((state - net.p.view_as(state)).flatten(1), c.zscore).view_as(state)
        return _fire(a, net.row_k, c.threshold, finite)
