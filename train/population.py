"""Every presentation order at once: the final knowledge and probe error of a large population of orders.

`train.experiment.Experiment` runs one agent per order and records every episode; for all 8! = 40,320 orders that
is too slow and too big. Here only the end of each order is kept, and work that orders share is done once:

- Prefix sharing. With the jar reset between episodes an agent's state after t episodes depends only on the first t
  objects of its order, so the orders form a trie (level t: the distinct prefixes of length t + 1) and each trie node
  is one agent-step. A node's children start as copies of it (`Agent.select`), then each steps with its own next
  object. All orders of 8 objects: 109,600 agent-steps instead of 322,560.
- Shared recall (`SharedRecallMemory`, `RecallCache`). Orders that differ only in when an object that changed
  nothing came end up with the same memory and cue it alike; each distinct (memory, cue) pair is recalled once per
  run (all orders of 8 objects: 45,063 recalls instead of 311,200), the rest copied from the first.
- Bounded memory. The trie is walked depth first in pieces of at most `chunk` sibling nodes, so at most chunk agents
  per level are alive, whatever the number of orders.

Results agree with `Experiment` on the same orders (tests/test_population.py): the same final knowledge, and the same
probe predictions up to float rounding. Not bit for bit: the agent's float results depend in their last bits on the
batch an agent is computed in (permuting Experiment's own agents changes a few probe predictions by ~1e-6
relative), and the batches here differ from Experiment's. Same inputs, same outputs, bit for bit.
"""

from __future__ import annotations

import copy
import time
from collections import Counter

import numpy as np
import torch

from aesop_torch.agent import Agent, AgentConfig
from aesop_torch.memory import EpisodicMemory, Recall
from train.experiment import stack_measurements
from train.summary import KNOWLEDGE_LETTERS

# Sibling trie nodes stepped together. All 40,320 orders of the default set, 2 threads, shared recall cache:
# 32.8 s / 0.7 GB peak at 512, 31.2 s / 0.9 GB at 1024, ~31.5 s / 1.4 GB at 2048, 31.5 s / 2.1 GB at 4096 (each
# level of the depth-first walk holds one piece alive, ~110 kB per agent, mostly the hub's W): 1024 is as fast as
# any and lean.
DEFAULT_CHUNK = 1024
# torch threads of a population run. 2,000 orders of the default set (closed-form outcomes, as benches/population.py)
# on the shared 2-core machine while other jobs ran: 19.7 s on 1 thread, 79.0 s on 2. Threads that wait for each
# other on a busy machine lose more than they win on the population's small steps (so does the runner: 1 thread).
DEFAULT_THREADS = 1


def knowledge_keys(state: torch.Tensor) -> list[str]:
    """(B, P) rules state codes -> B knowledge keys, the letters train.summary.knowledge_key gives."""
    return ["".join(KNOWLEDGE_LETTERS[c] for c in row) for row in state.tolist()]


def agreement(keys: list[str]) -> tuple[str, float, dict]:
    """Final knowledge keys of every order -> (the most common key, the fraction of orders that hold it, the count of
    every key, most common first). Ties go to the key seen first."""
    if not keys:
        raise ValueError("agreement needs at least one knowledge key")
    counts = Counter(keys).most_common()
    return counts[0][0], counts[0][1] / len(keys), dict(counts)


def median_rel_errors(predicted: torch.Tensor, truth: torch.Tensor) -> list[float | None]:
    """Row-wise `train.experiment.median_rel_error`, vectorised: (B, n_probes) predictions -> B medians (None where
    no probe can be predicted). Same arithmetic: float32 errors, a NaN prediction counts as 1, the median of an even
    count is the float64 mean of the middle two, as `statistics.median` gives."""
    B, n = predicted.shape
    if n == 0:
        return [None] * B
    err = torch.nan_to_num((predicted - truth).abs() / truth, nan=1.0).sort(dim=1).values.double()
    med = err[:, n // 2] if n % 2 else (err[:, n // 2 - 1] + err[:, n // 2]) / 2
    none = torch.isnan(predicted).all(1)
    return [None if nothing else m for m, nothing in zip(med.tolist(), none.tolist())]


def _row_keys(*parts: torch.Tensor) -> list[bytes]:
    """The exact bytes of each row of the (B, ...) parts, bool parts packed 8 to a byte: equal keys, equal rows."""
    cols = []
    for p in parts:
        a = p.detach().cpu().contiguous().reshape(p.shape[0], -1).numpy()
        cols.append(np.packbits(a, axis=1) if a.dtype == np.bool_ else a.view(np.uint8).reshape(a.shape[0], -1))
    rows = np.ascontiguousarray(np.concatenate(cols, axis=1))
    return rows.view(np.dtype((np.void, rows.shape[1]))).ravel().tolist()


class RecallCache:
    """Recall results by the exact bytes of (stored episodes, episode count, cue), shared by every memory of one
    population run (one memory config, default max_recalls), so a recall another batch already made is not made
    again.

    Grows with the distinct recalls of the run (all orders of the 8 default objects: ~45,000, ~1.2 kB each)."""

    def __init__(self):
        self.index: dict[bytes, int] = {}
        self.size = 0
        self.episodes = self.strength = self.valid = None   # (capacity, ...) stores; episodes bit-packed
        self.shape = None                                   # (K, rows, cols) of the stored episodes

    def missing(self, keys: list[bytes]) -> list[int]:
        """Rows whose key is new, the first of each."""
        seen, out = set(), []
        for i, k in enumerate(keys):
            if k not in self.index and k not in seen:
                seen.add(k)
                out.append(i)
        return out

    def add(self, keys: list[bytes], r: Recall) -> None:
        eps = r.episodes.cpu()
        if self.shape is None:
            self.shape = tuple(eps.shape[1:])
            self.episodes = np.zeros((0, (int(np.prod(self.shape)) + 7) // 8), dtype=np.uint8)
            self.strength, self.valid = torch.zeros(0, self.shape[0]), torch.zeros(0, self.shape[0], dtype=torch.bool)
        if tuple(eps.shape[1:]) != self.shape:
            raise ValueError(f"recalls of shape {tuple(eps.shape[1:])} in a cache of {self.shape}: one cache per "
                             "memory config")
        n, lo = len(keys), self.size
        if lo + n > len(self.strength):   # grow by doubling: amortised O(1) per entry
            more = max(2 * len(self.strength), lo + n, 64) - len(self.strength)
            self.episodes = np.concatenate([self.episodes, np.zeros((more, self.episodes.shape[1]), np.uint8)])
            self.strength = torch.cat([self.strength, self.strength.new_zeros(more, self.shape[0])])
            self.valid = torch.cat([self.valid, self.valid.new_zeros(more, self.shape[0])])
        self.episodes[lo:lo + n] = np.packbits(eps.reshape(n, -1).numpy(), axis=1)
        self.strength[lo:lo + n], self.valid[lo:lo + n] = r.strength.cpu(), r.valid.cpu()
        self.index.update(zip(keys, range(lo, lo + n)))
        self.size += n

    def recall(self, keys: list[bytes], device) -> Recall:
        ids = [self.index[k] for k in keys]
        bits = np.unpackbits(self.episodes[ids], axis=1, count=int(np.prod(self.shape)))
        episodes = torch.from_numpy(bits).view(torch.bool).reshape(len(ids), *self.shape)
        ids = torch.tensor(ids)
        valid = self.valid[ids]
        return Recall(episodes.to(device), self.strength[ids].to(device), valid.to(device), valid.any(1).to(device))


class SharedRecallMemory(EpisodicMemory):
    """An episodic memory that recalls once for agents with the same memory and the same cue.

    A recall depends only on the stored episodes and the cue. Orders that differ only in when an uninformative
    object came (one that was not encoded and changed nothing) end with the same memory and cue it alike: for all
    orders of the 8 default objects, 45,000 of the 311,000 recalls (109,600 episodes, 5 probes x 40,320) are
    distinct. The new ones of a batch are recalled together (in batch order), the rest copied: from the same batch,
    or from earlier batches through `cache` (a RecallCache; None: within the batch only). Agent.select keeps the
    memory's type (not the cache: set it on each new agent's memory)."""

    cache: RecallCache | None = None

    @torch.no_grad()
    def recall(self, cue: torch.Tensor, max_recalls: int | None = None) -> Recall:
        if cue.ndim != 2 or cue.shape[0] != self.batch:   # a shared memory serving many cues, or bad input
            return super().recall(cue, max_recalls)
        keys = _row_keys(self.patterns, self.count, cue.to(torch.float32))
        default_k = max_recalls is None or int(max_recalls) == self.config.max_recalls
        cache = self.cache if self.cache is not None and default_k else RecallCache()
        new = cache.missing(keys)
        if new:
            rows = torch.tensor(new, device=self.patterns.device)
            distinct = EpisodicMemory(self.config, batch=len(new)).to(self.patterns.device)
            distinct.patterns, distinct.count = self.patterns[rows], self.count[rows]
            cache.add([keys[i] for i in new], distinct.recall(cue[rows], max_recalls))
        return cache.recall(keys, cue.device)


class _Trie:
    """The orders sorted lexicographically; node[t][i] is the level-t node (prefix of length t + 1) of sorted row i."""

    def __init__(self, orders: torch.Tensor):
        N, n = orders.shape
        perm = torch.arange(N)
        for c in reversed(range(n)):   # least significant column first, stable sorts: lexicographic order
            perm = perm[torch.sort(orders[perm, c], stable=True).indices]
        self.perm, self.rows = perm, orders[perm]
        differs = torch.zeros(N, dtype=torch.bool)
        self.start, self.node = [], []
        for t in range(n):
            differs = differs.clone()
            differs[1:] |= self.rows[1:, t] != self.rows[:-1, t]
            start = differs.clone()
            start[0] = True
            self.start.append(start)               # row i begins a new level-t node
            self.node.append(start.cumsum(0) - 1)  # level-t node id of row i
        self.nodes_per_level = [int(s.sum()) for s in self.start]


def run_population(train_names: list[str], probe_names: list[str], orders: list[list[int]], outcomes: dict,
                   probes: dict, config: AgentConfig, chunk: int = DEFAULT_CHUNK, progress=None,
                   threads: int | None = None) -> dict:
    """Run every order to its end; return the final knowledge and probe error of each, in the order given.

    orders: lists of indices into train_names, all of length len(train_names) (as train.experiment.draw_orders
    gives). outcomes / probes: `Experiment.outcomes` / `Experiment.probes` (every train and probe name present).
    config: the agents' config (not modified; the experiment's buffer caps are applied to a copy, as Experiment
    does). progress: optional callable(orders_done, orders_total). threads: torch threads while running (default
    DEFAULT_THREADS), restored afterwards.

    Returns {"orders", "final_knowledge" (key per order), "final_probe_rel_error" (per order, rounded to 4 places as
    in the episode records; None while nothing can be predicted), "final_probe_cm3" ((orders, probes) float tensor:
    the predictions themselves, NaN where nothing was recalled), "most_common_knowledge", "agree_fraction",
    "knowledge_counts", "agent_steps", "distinct_recalls", "nodes_per_level", "timing_s"}.
    """
    n, N = len(train_names), len(orders)
    if n == 0 or N == 0:
        raise ValueError(f"need at least one train object and one order, got {n} objects and {N} orders")
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    if any(len(o) != n for o in orders):
        raise ValueError(f"every order must list {n} train objects (one per episode)")
    order_t = torch.tensor(orders, dtype=torch.long)
    if int(order_t.min()) < 0 or int(order_t.max()) >= n:
        raise ValueError(f"orders must index the {n} train objects (0..{n - 1})")
    missing = [m for m in train_names if m not in outcomes] + [m for m in probe_names if m not in probes]
    if missing:
        raise ValueError(f"no outcome or probe record for {', '.join(missing)}")

    t0 = time.perf_counter()
    old_threads = torch.get_num_threads()
    torch.set_num_threads(threads or DEFAULT_THREADS)
    try:
        config = copy.deepcopy(config)
        # as Experiment: an agent encodes at most one episode and one object per episode
        config.memory.max_episodes = min(config.memory.max_episodes, n)
        config.hub.max_assemblies = min(config.hub.max_assemblies, n)
        root = Agent(config, batch=1)
        root.memory = SharedRecallMemory(config.memory, batch=1)   # its children (Agent.select) inherit it
        t_setup = time.perf_counter()
        walk = _Walk(train_names, probe_names, outcomes, probes, order_t, chunk, progress)
        walk.grow(root, 0, N, 0)
    finally:
        torch.set_num_threads(old_threads)
    t_end = time.perf_counter()

    common, fraction, counts = agreement(walk.keys)
    return {
        "orders": N,
        "final_knowledge": walk.keys,
        "final_probe_rel_error": walk.errors,
        "final_probe_cm3": walk.predictions,
        "most_common_knowledge": common,
        "agree_fraction": fraction,
        "knowledge_counts": counts,
        "agent_steps": walk.agent_steps,
        "distinct_recalls": walk.cache.size,
        "nodes_per_level": walk.trie.nodes_per_level,
        "timing_s": {"setup": round(t_setup - t0, 3), "steps": round(walk.step_s, 3),
                     "probes": round(walk.probe_s, 3), "total": round(t_end - t0, 3)},
    }


class _Walk:
    """The depth-first walk over the trie, writing each order's results as its leaf is reached."""

    def __init__(self, train_names, probe_names, outcomes, probes, orders, chunk, progress):
        self.trie, self.chunk, self.progress = _Trie(orders), chunk, progress
        self.n, self.N = orders.shape[1], orders.shape[0]
        recs = [outcomes[name] for name in train_names]
        self.meas = stack_measurements([r["measurement"] for r in recs])          # (n_objects, ...) per key
        self.observed = torch.tensor([r["observed_cm3"] for r in recs])
        self.before = torch.tensor([r["goal_before"] for r in recs])
        self.after = torch.tensor([r["goal_after"] for r in recs])
        self.sank = torch.tensor([r["sank"] for r in recs]) if all("sank" in r for r in recs) else None
        self.probe_meas = [stack_measurements([probes[name]["measurement"]]) for name in probe_names]
        self.truth = torch.tensor([probes[name]["archimedes_cm3"] for name in probe_names])
        self.keys: list = [None] * self.N
        self.predictions = torch.full((self.N, len(probe_names)), float("nan"))
        self.errors: list = [None] * self.N
        self.agent_steps, self.done, self.step_s, self.probe_s = 0, 0, 0.0, 0.0
        self.cache = RecallCache()

    def grow(self, parents: Agent, lo: int, hi: int, t: int) -> None:
        """Step the level-t children of `parents` (the level t-1 nodes of sorted rows lo..hi, one agent each; the
        root for t = 0) in pieces of at most `chunk` nodes, then recurse into each piece."""
        trie = self.trie
        starts = trie.start[t][lo:hi].nonzero().flatten() + lo                   # first row of each child
        bounds = torch.cat([starts, torch.tensor([hi])])
        for g in range(0, len(starts), self.chunk):
            first = starts[g:g + self.chunk]
            plo, phi = int(bounds[g]), int(bounds[min(g + self.chunk, len(starts))])
            parent = (trie.node[t - 1][first] - trie.node[t - 1][lo]) if t else torch.zeros_like(first)
            # an only child continues its parent's agent in place (nothing else needs the parent): no copy
            child = parents if len(starts) == parents.batch else parents.select(parent)
            child.memory.cache = self.cache
            obj = trie.rows[first, t]
            tic = time.perf_counter()
            child.step({k: v[obj] for k, v in self.meas.items()}, self.observed[obj], self.before[obj],
                       self.after[obj], sank=None if self.sank is None else self.sank[obj])
            self.step_s += time.perf_counter() - tic
            self.agent_steps += len(first)
            if t + 1 < self.n:
                self.grow(child, plo, phi, t + 1)
            else:
                self._finish(child, plo, phi)
            del child

    def _finish(self, leaves: Agent, lo: int, hi: int) -> None:
        """Final knowledge and probe error of the leaves (full orders) of sorted rows lo..hi."""
        tic = time.perf_counter()
        pred = self._probe_predictions(leaves)
        errors = median_rel_errors(pred, self.truth)
        keys = knowledge_keys(leaves.rules.state)
        self.probe_s += time.perf_counter() - tic
        leaf = self.trie.node[self.n - 1][lo:hi] - self.trie.node[self.n - 1][lo]
        self.predictions[self.trie.perm[lo:hi]] = pred[leaf]
        leaf = leaf.tolist()
        for row, i in zip(self.trie.perm[lo:hi].tolist(), leaf):
            self.keys[row] = keys[i]
            self.errors[row] = None if errors[i] is None else round(errors[i], 4)
        self.done += hi - lo
        if self.progress is not None:
            self.progress(self.done, self.N)

    def _probe_predictions(self, agents: Agent) -> torch.Tensor:
        """(B, n_probes) what each agent expects every probe to displace, learning frozen (as Experiment's)."""
        B = agents.batch
        cols = [agents.predict({k: v.expand(B, *v.shape[1:]).contiguous() for k, v in m.items()})
                for m in self.probe_meas]
        return torch.stack(cols, dim=1) if cols else torch.zeros(B, 0)
