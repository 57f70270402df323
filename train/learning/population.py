"""Every presentation order at once: the final knowledge and probe error of a large population of orders.

`train.learning.experiment.Experiment` runs one agent per order and records every episode; for all 8! = 40,320 orders that
is too slow and too big. Here only the end of each order is kept, and work that orders share is done once:

- Prefix sharing. With the jar reset between episodes an agent's state after t episodes depends only on the first t
  objects of its order, so the orders form a trie (level t: the distinct prefixes of length t + 1). A node's
  children start as copies of it (`Agent.select`), then each steps with its own next object. All orders of 8
  objects: 109,600 trie nodes instead of 322,560 agent-steps.
- Merged states. Two prefixes that used the same objects and left their agents in the same state have the same
  future: the same remaining objects, stepped from the same state. Orders that differ in when an object that
  changed nothing came, or in the order of objects whose comparisons are symmetric, end up so. The agent's state
  records the order in only one more way: which slots (memory episodes, hub assemblies and the hub neurons they
  use) the objects were stored in, a labelling the network does not depend on; `canonicalise` relabels it by the
  objects. Each node's state is digested after its step; a node whose state was met before at its level (with the
  same orders below it) is not stepped further and its orders take the first one's results. All orders of 8
  objects: 2,782 agent-steps instead of 109,600, with the plain trie's knowledge and rounded probe errors
  (its predictions within 3e-6 relative; benches/population.py runs both).
- Shared recall (`SharedRecallMemory`, `RecallCache`). Orders that differ only in when an object that changed
  nothing came end up with the same memory and cue it alike; each distinct (memory, cue) pair is recalled once per
  run, the rest copied from the first.
- Bounded memory. The trie is walked depth first in pieces of at most `chunk` sibling nodes, so at most chunk agents
  per level are alive, whatever the number of orders; the merging keeps a 16-byte digest per distinct state.

Results agree with `Experiment` on the same orders (tests/test_population.py): the same final knowledge, and the same
probe predictions up to float rounding. Not bit for bit: the agent's float results depend in their last bits on the
batch an agent is computed in (permuting Experiment's own agents changes a few probe predictions by ~1e-6
relative), and the batches (and the relabelling) here differ from Experiment's. Same inputs, same outputs, bit for
bit.
"""

from __future__ import annotations

import copy
import hashlib
import os
import pickle
import queue
import signal
import threading
import time
from collections import Counter

import numpy as np
import torch

from aesop_torch.agent import OBJECT_ROWS, Agent, AgentConfig
from aesop_torch.memory import EpisodicMemory, Recall
from aesop_torch.rules import KNOWLEDGE_LETTERS
from train.learning.experiment import stack_measurements

# Sibling trie nodes stepped together. All 40,320 orders of the default set with the plain trie (before states were
# merged), 2 threads, shared recall cache: 32.8 s / 0.7 GB peak at 512, 31.2 s / 0.9 GB at 1024, ~31.5 s / 1.4 GB
# at 2048, 31.5 s / 2.1 GB at 4096 (each level of the depth-first walk holds one piece alive, ~110 kB per agent,
# mostly the hub's W then): 1024 is as fast as any and lean. A piece is also where states merge first, but equal
# states merge across pieces too (each object is perceived once: a state's bits do not depend on its piece).
DEFAULT_CHUNK = 1024
# torch threads of a population run. 2,000 orders of the default set (closed-form outcomes, as benches/population.py)
# on the shared 2-core machine while other jobs ran: 19.7 s on 1 thread, 79.0 s on 2. Threads that wait for each
# other on a busy machine lose more than they win on the population's small steps (so does the runner: 1 thread).
DEFAULT_THREADS = 1


def knowledge_keys(state: torch.Tensor) -> list[str]:
    """(B, P) rules state codes -> B knowledge keys, the letters train.runner.summary.knowledge_key gives."""
    return ["".join(KNOWLEDGE_LETTERS[c] for c in row) for row in state.tolist()]


def agreement(keys: list[str]) -> tuple[str, float, dict]:
    """Final knowledge keys of every order -> (the most common key, the fraction of orders that hold it, the count of
    every key, most common first). Ties go to the key seen first."""
    if not keys:
        raise ValueError("agreement needs at least one knowledge key")
    counts = Counter(keys).most_common()
    return counts[0][0], counts[0][1] / len(keys), dict(counts)


def median_rel_errors(predicted: torch.Tensor, truth: torch.Tensor) -> list[float | None]:
    """Row-wise `train.learning.experiment.median_rel_error`, vectorised: (B, n_probes) predictions -> B medians (None where
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


def _sorted_rows(rows: torch.Tensor) -> bool:
    """Whether the (N, n) rows are in lexicographic order (equal rows side by side allowed)."""
    if rows.shape[0] < 2 or rows.shape[1] == 0:
        return True
    step = rows[1:] - rows[:-1]
    first = (step != 0).to(torch.uint8).argmax(1)        # the first column where a row differs from the one before
    return bool((step.gather(1, first[:, None]) >= 0).all())   # rising there (0: the same row)


class _Trie:
    """The orders sorted lexicographically; node[t][i] is the level-t node (prefix of length t + 1) of sorted row i,
    and level-t node k spans the sorted rows lo[t][k]..hi[t][k]."""

    def __init__(self, orders: torch.Tensor):
        N, n = orders.shape
        self.orders = orders   # what it was built from (a trie prepared ahead is used only for these orders)
        perm = torch.arange(N)
        if not _sorted_rows(orders):   # (all orders come sorted: the stable sorts would leave them as they are)
            for c in reversed(range(n)):   # least significant column first, stable sorts: lexicographic order
                perm = perm[torch.sort(orders[perm, c], stable=True).indices]
        self.perm, self.rows = perm, orders[perm]
        differs = torch.zeros(N, dtype=torch.bool)
        self.start, self.node, self.lo, self.hi = [], [], [], []
        for t in range(n):
            differs = differs.clone()
            differs[1:] |= self.rows[1:, t] != self.rows[:-1, t]
            start = differs.clone()
            start[0] = True
            self.start.append(start)               # row i begins a new level-t node
            self.node.append(start.cumsum(0) - 1)  # level-t node id of row i
            lo = start.nonzero().flatten()
            self.lo.append(lo)
            self.hi.append(torch.cat([lo[1:], torch.tensor([N])]))
        self.nodes_per_level = [int(s.sum()) for s in self.start]


def run_population(train_names: list[str], probe_names: list[str], orders: list[list[int]], outcomes: dict,
                   probes: dict, config: AgentConfig, chunk: int = DEFAULT_CHUNK, progress=None,
                   threads: int | None = None, merge: bool = True, curves: bool = False,
                   probe_process: bool = False, maps: dict | None = None, trie: _Trie | None = None) -> dict:
    """Run every order to its end; return the final knowledge and probe error of each, in the order given.

    orders: lists of indices into train_names, all of length len(train_names) (as train.learning.experiment.draw_orders
    gives), or the same as an (N, n) long tensor (order_tensor). outcomes / probes: `Experiment.outcomes` /
    `Experiment.probes` (every train and probe name present). config: the agents' config (not modified; the
    experiment's buffer caps are applied to a copy, as Experiment does). progress: optional callable(orders_done,
    orders_total). threads: torch threads while running (default DEFAULT_THREADS), restored afterwards.
    merge=False: the plain trie, every node stepped (a check on the merging, and its peer in
    benches/population.py). curves=True: also the probe error after every episode of every order
    (one probe reading per stepped state: Figure 2's bands over all orders; off, the run is as fast as before).
    probe_process=True (with curves, Linux): those probe readings are made on a process of its own, forked here
    (`_ProbeProcess`), beside the walk: they were half of the population's time on one core. maps: the property
    maps' state (`Agent.maps.state_dict()`, tensors or arrays) of an agent of this config, developed already (the
    runner's experiment's): loaded instead of developed again (0.3-0.8 s), as a resumed run loads them. trie: the
    orders' trie built already (prepare_orders), else built here.

    Returns {"orders", "final_knowledge" (key per order), "final_probe_rel_error" (per order, rounded to 4 places as
    in the episode records; None while nothing can be predicted), "final_probe_cm3" ((orders, probes) float tensor:
    the predictions themselves, NaN where nothing was recalled), "most_common_knowledge", "agree_fraction",
    "knowledge_counts", "agent_steps", "distinct_recalls" (with probe_process, on either process), "nodes_per_level"
    (trie nodes), "steps_per_level"
    (agent-steps taken, fewer where states merged), "distinct_final_states", "timing_s"}; with curves=True also
    "curves": {"probe_rel_error": per episode, {"values": the distinct errors (rounded as the records), "counts":
    how many orders have each, "none": how many orders cannot predict yet}} (counts, not N numbers per episode:
    9! orders share a few thousand values; `train.common.quantiles.weighted_quantiles` reads them).
    """
    n, N = len(train_names), len(orders)
    if n == 0 or N == 0:
        raise ValueError(f"need at least one train object and one order, got {n} objects and {N} orders")
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    if isinstance(orders, torch.Tensor):   # as train.learning.experiment.order_tensor gives (no lists for 9! rows)
        if orders.dim() != 2 or orders.shape[1] != n or orders.dtype != torch.long:
            raise ValueError(f"every order must list {n} train objects (one per episode): an (N, {n}) long tensor, "
                             f"not {orders.dtype} {tuple(orders.shape)}")
        order_t = orders
    else:
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
    walk = None
    try:
        config = copy.deepcopy(config)
        # as Experiment: an agent encodes at most one episode and one object per episode
        config.memory.max_episodes = min(config.memory.max_episodes, n)
        config.hub.max_assemblies = min(config.hub.max_assemblies, n)
        if config.explore == "active":   # the agents choose their own objects: no prefixes to share
            return _run_active(train_names, probe_names, order_t, outcomes, probes, config, chunk, progress, curves,
                               t0)
        root = Agent(config, batch=1, develop=maps is None)
        if maps is not None:
            root.maps.load_state_dict({k: torch.as_tensor(v) for k, v in maps.items()})
        root.memory = SharedRecallMemory(config.memory, batch=1)   # its children (Agent.select) inherit it
        t_setup = time.perf_counter()
        walk = _Walk(train_names, probe_names, outcomes, probes, order_t, chunk, progress, merge, curves, trie)
        walk.perceive(root)
        if curves and probe_process and hasattr(os, "fork"):
            walk.helper = _ProbeProcess(walk, root)
        A, M = config.hub.max_assemblies, config.memory.max_episodes
        walk.grow(root, (torch.full((1, A), n), torch.full((1, M), n)), None, 0)
        walk.collect_errors()
        keys, errors, predictions = walk.results()
    finally:
        torch.set_num_threads(old_threads)
        if walk is not None and walk.helper is not None:
            walk.helper.close()
    t_end = time.perf_counter()

    common, fraction, counts = agreement(keys)
    out = {
        "orders": N,
        "final_knowledge": keys,
        "final_probe_rel_error": errors,
        "final_probe_cm3": predictions,
        "most_common_knowledge": common,
        "agree_fraction": fraction,
        "knowledge_counts": counts,
        "agent_steps": walk.agent_steps,
        "distinct_recalls": walk.cache.size if walk.helper is None else
        len(_digests(walk.cache.index) | walk.helper.recalls),
        "nodes_per_level": walk.trie.nodes_per_level,
        "steps_per_level": walk.steps_per_level,
        "distinct_final_states": len(walk.leaf_keys),
        "timing_s": {"setup": round(t_setup - t0, 3), "steps": round(walk.step_s, 3),
                     "probes": round(walk.probe_s, 3), "total": round(t_end - t0, 3)},
    }
    if curves:
        out["curves"] = {"probe_rel_error": walk.curves(errors)}
    return out


_PREPARED: dict = {}   # (n_objects, orders, seed) -> (the order tensor, its trie), made ahead by prepare_orders
LAST: dict = {}   # run_orders' last answer in this process: the figure process draws Figure 2 from it (figure_process)


def prepare_orders(n_objects: int, orders: str, seed: int) -> None:
    """Draw the orders and build their trie now, for the run_orders call of the same (n_objects, orders, seed) to
    take: the runner's figure process does this at its start, on the core its torch import leaves idle, rather than
    when the simulations are in and the population is the run's longest part (9! orders: ~0.2 s)."""
    from train.learning.experiment import order_tensor
    order_t = order_tensor(n_objects, orders, seed)
    _PREPARED[(n_objects, orders, seed)] = (order_t, _Trie(order_t))


def run_orders(train_names: list[str], probe_names: list[str], orders: str, seed: int, outcomes: dict, probes: dict,
               config: AgentConfig, maps: dict | None = None) -> dict:
    """run_population over draw_orders(len(train_names), orders, seed), drawn here, with curves, without
    "final_probe_cm3": what the runner asks of its figure process (train/runner/loop.py), which runs it beside the
    detailed orders. Drawn and run in that process, the 9! orders are not sent to it, nor their predictions back."""
    from aesop_torch.malloc import keep_freed_memory
    from train.learning.experiment import order_tensor

    from train.learning.sim_pool import cores

    keep_freed_memory()   # as in the runner (aesop_torch/malloc.py)
    LAST.clear()
    prepared = _PREPARED.pop((len(train_names), orders, seed), None)
    order_t, trie = prepared or (order_tensor(len(train_names), orders, seed), None)
    out = run_population(train_names, probe_names, order_t, outcomes, probes, config, curves=True,
                         probe_process=cores() > 1, maps=maps, trie=trie)
    del out["final_probe_cm3"]
    LAST.update(out)
    return out


def _run_active(train_names, probe_names, orders: torch.Tensor, outcomes: dict, probes: dict, config: AgentConfig,
                chunk: int, progress, curves: bool, t0: float) -> dict:
    """run_population's answer when the robot chooses its next object (AgentConfig.explore "active",
    aesop_torch/exploration.py): what comes next depends on what the agent learned, not on the order's prefix, so
    the orders (the teacher's first object, and the tie-breaks) run side by side in pieces of `chunk`, each agent
    stepping the object it chose, as Experiment does. Same keys as run_population's answer; "chosen_orders" holds
    the orders as the agents made them."""
    from aesop_torch.exploration import choose_in_order
    N, n = orders.shape
    walk = _Walk(train_names, probe_names, outcomes, probes, orders[:1], chunk, None, merge=False, curves=False)
    keys, errors, preds, chosen, curve = [], [], [], [], []
    step_s = probe_s = 0.0
    for lo in range(0, N, chunk):
        part = orders[lo:lo + chunk].clone()
        agent = Agent(config, batch=len(part))
        if lo == 0:
            walk.perceive(agent)
        errs_t = []
        for t in range(n):
            tic = time.perf_counter()
            obj = choose_in_order(agent, walk.acts, walk.present, part, t)
            agent.step({k: v[obj] for k, v in walk.meas.items()}, walk.observed[obj], walk.before[obj],
                       walk.after[obj], sank=None if walk.sank is None else walk.sank[obj],
                       perceived=(walk.acts[obj], walk.present[obj]))
            step_s += time.perf_counter() - tic
            if curves and t + 1 < n:
                tic = time.perf_counter()
                errs_t.append(median_rel_errors(walk._probe_predictions(agent), walk.truth))
                probe_s += time.perf_counter() - tic
        tic = time.perf_counter()
        pred = walk._probe_predictions(agent)
        probe_s += time.perf_counter() - tic
        preds.append(pred)
        keys += knowledge_keys(agent.rules.state)
        errors += [None if e is None else round(e, 4) for e in median_rel_errors(pred, walk.truth)]
        chosen += part.tolist()
        curve.append(errs_t)
        if progress is not None:
            progress(min(lo + chunk, N), N)
    common, fraction, counts = agreement(keys)
    out = {"orders": N, "final_knowledge": keys, "final_probe_rel_error": errors,
           "final_probe_cm3": torch.cat(preds), "most_common_knowledge": common, "agree_fraction": fraction,
           "knowledge_counts": counts, "agent_steps": N * n, "distinct_recalls": 0, "nodes_per_level": [N] * n,
           "steps_per_level": [N] * n, "distinct_final_states": len(counts), "chosen_orders": chosen,
           "timing_s": {"setup": 0.0, "steps": round(step_s, 3), "probes": round(probe_s, 3),
                        "total": round(time.perf_counter() - t0, 3)}}
    if curves:
        per_t = []
        for t in range(n - 1):
            err = torch.tensor([float("nan") if e is None else round(e, 4) for c in curve for e in c[t]],
                               dtype=torch.float64)
            ok = err[~torch.isnan(err)]
            values, counts_t = torch.unique(ok, return_counts=True)
            per_t.append({"values": values.tolist(), "counts": counts_t.tolist(), "none": int(len(err) - len(ok))})
        final = torch.tensor([float("nan") if e is None else e for e in errors], dtype=torch.float64)
        ok = final[~torch.isnan(final)]
        values, counts_t = torch.unique(ok, return_counts=True)
        per_t.append({"values": values.tolist(), "counts": counts_t.tolist(), "none": int(len(final) - len(ok))})
        out["curves"] = {"probe_rel_error": per_t}
    return out


def _owned(owner: torch.Tensor, before: torch.Tensor, after: torch.Tensor, obj: torch.Tensor) -> torch.Tensor:
    """owner (B, S) with the slots before[b]..after[b] - 1 (filled by this step) set to obj[b]."""
    slot = torch.arange(owner.shape[1])
    return torch.where((slot >= before[:, None]) & (slot < after[:, None]), obj[:, None], owner)


def canonicalise(agent: Agent, hub_owner: torch.Tensor, mem_owner: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Relabel each agent's stored objects in place into the order of the objects that stored them, so that agents
    that learned the same things in another order hold the same bytes. Returns the owners in their new order.

    hub_owner (B, A): the train object that allocated each hub slot; mem_owner (B, M): the object of each stored
    episode (n, the object count, for an empty slot). The memory's episodes are sorted by their objects. The hub's
    assemblies are sorted too where they lie as the hub lays them out while no two overlap (`ObjectHub._pick`: slot
    s on neurons a s .. a s + a - 1 of every row, a = assembly_size): slot j then takes the stored patterns of the
    object that is j-th in order, and its neurons stand for that object in the memory's episodes (the object rows
    are the hub's neurons, `agent.OBJECT_ROWS`). Nothing else is touched (usage, assemblies, strengths and the rules
    are the same for both labellings), so the relabelled agent is the same network with its neurons and slots
    renamed: it computes the same things, up to the order of float additions and ties broken by index."""
    hub, mem = agent.hub, agent.memory
    B, M = mem.patterns.shape[:2]
    big = torch.iinfo(torch.long).max
    order = torch.sort(torch.where(torch.arange(M) < mem.count[:, None], mem_owner, big), dim=1, stable=True).indices
    mem.patterns = mem.patterns[torch.arange(B)[:, None], order]
    mem_owner = mem_owner.gather(1, order)
    A, N = hub.assemblies.shape[1:]
    cfg = agent.config.hub
    a, cols = cfg.assembly_size, cfg.n_neurons
    if A == 0 or A * a > cols or cols != mem.patterns.shape[3] or cfg.rows != len(OBJECT_ROWS):
        return hub_owner, mem_owner
    filled = torch.arange(A) < hub.n_assemblies[:, None]                                     # (B, A)
    code = torch.zeros(A, cfg.rows, cols, dtype=torch.bool)
    for s in range(A):
        code[s, :, a * s:a * (s + 1)] = True
    laid_out = (hub.assemblies == (code.flatten(1) & filled[..., None])).flatten(1).all(1)  # (B,)
    perm = torch.sort(torch.where(filled, hub_owner, big), dim=1, stable=True).indices
    perm = torch.where(laid_out[:, None], perm, torch.arange(A))
    hub.branches = hub.branches[torch.arange(B)[:, None], perm]
    hub.branch_norm = hub.branch_norm[torch.arange(B)[:, None], perm]
    hub.graded = hub.graded[torch.arange(B)[:, None], perm]
    colmap = torch.arange(cols).repeat(B, 1)
    colmap[:, :A * a] = (a * perm[:, :, None] + torch.arange(a)).flatten(1)                  # new column <- old
    rows = list(OBJECT_ROWS)
    obj = mem.patterns[:, :, rows]
    mem.patterns[:, :, rows] = obj.gather(3, colmap[:, None, None, :].expand(obj.shape))
    return hub_owner.gather(1, perm), mem_owner


def _state_digests(agent: Agent, *extra: torch.Tensor) -> list[bytes]:
    """A 16-byte digest (blake2b) of each agent's learned state (every persistent buffer of the hub, the memory and
    the rules) and the extra (B, ...) parts: equal digests, equal bytes (a collision is a 2^-64 event at 2^32
    states)."""
    parts = [getattr(part, key) for part in (agent.hub, agent.memory, agent.rules) for key in part.state_dict()]
    return [hashlib.blake2b(k, digest_size=16).digest() for k in _row_keys(*extra, *parts)]


class _Walk:
    """The depth-first walk over the trie, merging the subtrees of nodes whose agents are in the same state.

    Two prefixes that used the same objects and left their agents in the same state (after `canonicalise`) have
    the same future: the same remaining objects, stepped from the same state. A node whose state was met before at
    its level, with the same suffixes below it, is not stepped further: its orders take the results of the first.
    Each order ends at a leaf result (knowledge and probe predictions), computed once per distinct final state."""

    def __init__(self, train_names, probe_names, outcomes, probes, orders, chunk, progress, merge=True,
                 curves=False, trie: _Trie | None = None):
        self.trie = trie if trie is not None and trie.orders is orders else _Trie(orders)
        self.chunk, self.progress, self.merge = chunk, progress, merge
        self.n, self.N = orders.shape[1], orders.shape[0]
        recs = [outcomes[name] for name in train_names]
        self.meas = stack_measurements([r["measurement"] for r in recs])          # (n_objects, ...) per key
        self.observed = torch.tensor([r["observed_cm3"] for r in recs])
        self.before = torch.tensor([r["goal_before"] for r in recs])
        self.after = torch.tensor([r["goal_after"] for r in recs])
        self.sank = torch.tensor([r["sank"] for r in recs]) if all("sank" in r for r in recs) else None
        self.probe_meas = [stack_measurements([probes[name]["measurement"]]) for name in probe_names]
        self.truth = torch.tensor([probes[name]["archimedes_cm3"] for name in probe_names])
        self.memo: list[dict] = [{} for _ in range(self.n)]    # level t: state digest -> the level-t node stepped
        self.leaf_of = torch.full((self.N,), -1, dtype=torch.long)   # sorted row -> its leaf result
        self.leaf_keys: list[str] = []
        self.leaf_errors: list = []
        self.leaf_pred: list[torch.Tensor] = []
        self.agent_steps, self.done, self.step_s, self.probe_s = 0, 0, 0.0, 0.0
        self.steps_per_level = [0] * self.n
        self.cache = RecallCache()
        # curves: level t (before the last), sorted row -> the probe error of its order after episode t + 1
        self.row_err = torch.full((self.n - 1, self.N), float("nan"), dtype=torch.float64) if curves else None
        self.err_memo: list[dict] = [{} for _ in range(self.n)]   # level t: state digest -> its probe error
        # a _ProbeProcess reading the probes' errors elsewhere: the rows' errors (row_err) are written once its
        # answers are in (collect_errors), from what _record_errors and _copy would have written meanwhile
        self.helper = None
        self.pending_errors: list[tuple] = []   # (t, ids, digests) of _record_errors
        self.pending_copies: list[tuple] = []   # (t, lo, hi, src) of _copy

    def perceive(self, agent: Agent) -> None:
        """What the agents perceive of each object and probe (Agent.activities), computed once here: in the last bits
        it depends on the batch it is computed in, and the merging needs a state to come out the same bits
        whichever batch stepped it."""
        self.acts, self.present = agent.activities(self.meas)
        self.probe_acts = [agent.activities(m) for m in self.probe_meas]

    def results(self) -> tuple[list, list, torch.Tensor]:
        """Per order, in the order given: (knowledge keys, probe errors, (N, n_probes) probe predictions)."""
        leaf = torch.empty_like(self.leaf_of)
        leaf[self.trie.perm] = self.leaf_of
        pred = torch.cat(self.leaf_pred) if self.leaf_pred else torch.zeros(0, len(self.truth))
        ids = leaf.tolist()
        return [self.leaf_keys[i] for i in ids], [self.leaf_errors[i] for i in ids], pred[leaf]

    def curves(self, final_errors: list) -> list[dict]:
        """Per episode, the distinct probe errors of the orders with their counts, and the count of orders that
        cannot predict yet (None); the last episode's from final_errors. Counts do not depend on the rows' order."""
        final = torch.tensor([float("nan") if e is None else e for e in final_errors], dtype=torch.float64)
        out = []
        for err in [*self.row_err, final]:
            ok = err[~torch.isnan(err)]
            values, counts = torch.unique(ok, return_counts=True)
            out.append({"values": values.tolist(), "counts": counts.tolist(), "none": int(len(err) - len(ok))})
        return out

    def _record_errors(self, agents: Agent, ids: torch.Tensor, t: int, digests: list) -> None:
        """The probe error of each level-t node just stepped (learning frozen, as Experiment's records), written to
        every order below it, rounded as the records are. Read once per distinct state (digest) of the level: the
        probes' recall and readout were half the time of all orders of 8 objects read node by node."""
        tic = time.perf_counter()
        memo, new = self.err_memo[t], {}
        for i, d in enumerate(digests):
            if d not in memo and d not in new:
                new[d] = i
        if new:
            sub = agents if len(new) == agents.batch else agents.select(torch.tensor(list(new.values())))
            if self.helper is not None:   # read there; its answer written into memo by collect_errors
                self.helper.send(t, list(new), sub, cached=sub is agents)
                memo.update(dict.fromkeys(new))
            else:
                for d, e in zip(new, median_rel_errors(self._probe_predictions(sub), self.truth)):
                    memo[d] = float("nan") if e is None else round(e, 4)
        if self.helper is not None:
            self.pending_errors.append((t, ids, digests))
        else:
            self._write_errors(t, ids, digests)
        self.probe_s += time.perf_counter() - tic

    def _write_errors(self, t: int, ids: torch.Tensor, digests: list) -> None:
        """row_err of the orders below the level-t nodes ids, from err_memo[t]."""
        memo = self.err_memo[t]
        errs = torch.tensor([memo[d] for d in digests], dtype=torch.float64)
        lo, hi = self.trie.lo[t][ids], self.trie.hi[t][ids]
        count = hi - lo
        rows = lo.repeat_interleave(count) + torch.arange(int(count.sum())) - \
            (count.cumsum(0) - count).repeat_interleave(count)
        self.row_err[t, rows] = errs.repeat_interleave(count)

    def collect_errors(self) -> None:
        """With a _ProbeProcess: its errors into err_memo, then row_err written as _record_errors and _copy would
        have written it (each copy's source written before it, as in the walk: the copies in their order, after
        every node's own errors, whose rows no copy touches)."""
        if self.helper is None:
            return
        tic = time.perf_counter()
        memo, leaves = self.helper.results()
        for (t, d), e in memo.items():
            self.err_memo[t][d] = e
        # the leaves' predictions and errors, in the order _finish sent them (every leaf batch was sent)
        self.leaf_pred = [torch.from_numpy(pred) for pred, _ in leaves]
        self.leaf_errors = [e for _, errors in leaves for e in errors]
        for t, ids, digests in self.pending_errors:
            self._write_errors(t, ids, digests)
        for t, lo, hi, src in self.pending_copies:
            self.row_err[t + 1:, lo:hi] = self.row_err[t + 1:, src:src + hi - lo]
        self.pending_errors, self.pending_copies = [], []
        self.probe_s += time.perf_counter() - tic

    def grow(self, parents: Agent, owners: tuple, pnodes: torch.Tensor | None, t: int) -> None:
        """Step the level-t children of `parents` (agent i: the level t-1 node pnodes[i]; the root for t = 0, pnodes
        None) in pieces of at most `chunk` nodes, then recurse into the children whose state is new."""
        trie = self.trie
        if t == 0:
            cids = torch.arange(trie.nodes_per_level[0])
            pidx = torch.zeros_like(cids)
        else:
            first = trie.node[t][trie.lo[t - 1][pnodes]]
            count = trie.node[t][trie.hi[t - 1][pnodes] - 1] - first + 1
            pidx = torch.arange(len(pnodes)).repeat_interleave(count)
            cids = first.repeat_interleave(count) + torch.arange(int(count.sum())) - \
                (count.cumsum(0) - count).repeat_interleave(count)
        for g in range(0, len(cids), self.chunk):
            ids, par = cids[g:g + self.chunk], pidx[g:g + self.chunk]
            # an only child continues its parent's agent in place (nothing else needs the parent): no copy
            child = parents if len(cids) == parents.batch else parents.select(par)
            hub_owner, mem_owner = owners[0][par], owners[1][par]
            child.memory.cache = self.cache
            rows = trie.lo[t][ids]
            obj = trie.rows[rows, t]
            n_hub, n_mem = child.hub.n_assemblies.clone(), child.memory.count.clone()
            tic = time.perf_counter()
            child.step({k: v[obj] for k, v in self.meas.items()}, self.observed[obj], self.before[obj],
                       self.after[obj], sank=None if self.sank is None else self.sank[obj],
                       perceived=(self.acts[obj], self.present[obj]))   # seen once, see perceive
            hub_owner = _owned(hub_owner, n_hub, child.hub.n_assemblies, obj)
            mem_owner = _owned(mem_owner, n_mem, child.memory.count, obj)
            if self.merge:
                hub_owner, mem_owner = canonicalise(child, hub_owner, mem_owner)
                used = torch.zeros(len(ids), self.n, dtype=torch.bool)
                used[torch.arange(len(ids))[:, None], trie.rows[rows, :t + 1]] = True
                digests = _state_digests(child, used, hub_owner, mem_owner)
            else:   # every node its own state
                digests = [(t, c) for c in ids.tolist()]
            self.step_s += time.perf_counter() - tic
            self.agent_steps += len(ids)
            self.steps_per_level[t] += len(ids)
            if t + 1 == self.n:
                self._finish(child, ids, digests)
                continue
            if self.row_err is not None:
                self._record_errors(child, ids, t, digests)
            memo, new, copies, seen = self.memo[t], [], [], {}
            for i, (d, c) in enumerate(zip(digests, ids.tolist())):
                m = memo.get(d, seen.get(d))
                if m is not None and self._same_below(m, c, t):
                    copies.append((c, m))       # its subtree is (or, from this piece, will be) the first's
                    continue
                if m is None:
                    seen[d] = c
                new.append(i)
            if new:
                keep = torch.tensor(new)
                sub = child if len(new) == child.batch else child.select(keep)
                del child
                self.grow(sub, (hub_owner[keep], mem_owner[keep]), ids[keep], t + 1)
                del sub
            memo.update(seen)
            for c, m in copies:
                self._copy(c, m, t)

    def _same_below(self, a: int, b: int, t: int) -> bool:
        """Do level-t nodes a and b have the same suffixes below them (always so for all orders)?"""
        tr = self.trie
        la, ha, lb, hb = int(tr.lo[t][a]), int(tr.hi[t][a]), int(tr.lo[t][b]), int(tr.hi[t][b])
        return ha - la == hb - lb and torch.equal(tr.rows[la:ha, t + 1:], tr.rows[lb:hb, t + 1:])

    def _copy(self, node: int, like: int, t: int) -> None:
        """The orders below level-t node `node` end as the corresponding ones below `like` (same suffixes)."""
        tr = self.trie
        lo, hi, src = int(tr.lo[t][node]), int(tr.hi[t][node]), int(tr.lo[t][like])
        self.leaf_of[lo:hi] = self.leaf_of[src:src + hi - lo]
        if self.helper is not None:    # once the errors are in (collect_errors)
            self.pending_copies.append((t, lo, hi, src))
        elif self.row_err is not None:   # the levels below; level t was recorded when `node` was stepped
            self.row_err[t + 1:, lo:hi] = self.row_err[t + 1:, src:src + hi - lo]
        self._done(hi - lo)

    def _done(self, k: int) -> None:
        self.done += k
        if self.progress is not None:
            self.progress(self.done, self.N)

    def _finish(self, leaves: Agent, ids: torch.Tensor, digests: list[bytes]) -> None:
        """Final knowledge and probe error of the leaves (full orders), once per distinct final state."""
        tic = time.perf_counter()
        memo, new, result = self.memo[-1], [], []
        for i, d in enumerate(digests):
            r = memo.get(d)
            if r is None:
                r = memo[d] = len(self.leaf_keys) + len(new)
                new.append(i)
            result.append(r)
        if new:
            sub = leaves if len(new) == leaves.batch else leaves.select(torch.tensor(new))
            if self.helper is not None:   # predicted there; collect_errors puts them in these places
                self.helper.send(-1, None, sub, cached=sub is leaves)
                self.leaf_pred.append(None)
                self.leaf_errors += [None] * len(new)
            else:
                pred = self._probe_predictions(sub)
                self.leaf_pred.append(pred)
                self.leaf_errors += [None if e is None else round(e, 4)
                                     for e in median_rel_errors(pred, self.truth)]
            self.leaf_keys += knowledge_keys(sub.rules.state)
        tr = self.trie
        lo, hi = tr.lo[-1][ids], tr.hi[-1][ids]
        self.leaf_of[lo] = torch.tensor(result)
        for i in (hi - lo > 1).nonzero().flatten().tolist():   # an order given more than once
            self.leaf_of[int(lo[i]):int(hi[i])] = result[i]
        self.probe_s += time.perf_counter() - tic
        self._done(int((hi - lo).sum()))

    def _probe_predictions(self, agents: Agent) -> torch.Tensor:
        """(B, n_probes) what each agent expects every probe to displace, learning frozen (as Experiment's)."""
        B = agents.batch
        cols = [agents.anticipate_acts(acts.expand(B, *acts.shape[1:]), present.expand(B, -1), decoded=False
                                       ).expected for acts, present in self.probe_acts]
        return torch.stack(cols, dim=1) if cols else torch.zeros(B, 0)


class _ProbeProcess:
    """The probe readings of a population's curves (`_Walk._record_errors`) and of its leaves (`_Walk._finish`) on a
    child process forked from this one (it has the walk's probes and the agents' maps already), fed each batch of
    new states through a pipe as plain arrays: the walk steps its agents meanwhile. The child reads each batch as
    the walk reads it (the same agents, the same batch, `_probe_predictions`, a RecallCache where the walk's would
    be used: its own, so the walk's steps no longer find the probes' recalls there and make them again; a recall
    is the same whatever batch makes it) and answers, at the end, the rounded error of every (level, digest) and
    the leaves' predictions. All 9! orders of nine objects, the curves' readings alone moved: 10.3 s of CPU on the
    walk's process and 6.5 s on the child, against 15.9 s on one (a busy machine).

    The child ignores Ctrl-C, ends at SIGTERM or SIGHUP and dies with this process (sim_pool._die_with); it never
    returns into the caller's code (os._exit). A child that died is an error here, not a silent gap."""

    def __init__(self, walk: _Walk, template: Agent):
        from multiprocessing.connection import Connection
        to_r, to_w = os.pipe()
        back_r, back_w = os.pipe()
        parent, threads = os.getpid(), torch.get_num_threads()
        pid = os.fork()
        if pid == 0:   # the child
            code = 1
            try:
                os.close(to_w)
                os.close(back_r)
                from train.learning.sim_pool import _die_with
                signal.signal(signal.SIGINT, signal.SIG_IGN)
                _die_with(parent)
                torch.set_num_threads(threads)   # the walk's (run_population's `threads`)
                _serve(walk, template, Connection(to_r, writable=False), Connection(back_w, readable=False))
                code = 0
            finally:
                os._exit(code)
        os.close(to_r)
        os.close(back_w)
        self.pid, self._to, self._back = pid, Connection(to_w, readable=False), Connection(back_r, writable=False)
        self.recalls = set()   # digests of the recalls the child made (its own RecallCache's keys)
        # a thread writes the batches, so the walk never waits for the child to take one (a pipe holds 64 kB)
        self._queue, self._failed = queue.SimpleQueue(), None
        self._writer = threading.Thread(target=self._write, daemon=True)
        self._writer.start()

    def _write(self) -> None:
        while (data := self._queue.get()) is not None:
            try:
                self._to.send_bytes(data)
            except OSError as e:   # the child died: said by results()
                self._failed = e
                return

    def send(self, t: int, digests: list, agents: Agent, cached: bool) -> None:
        """The agents whose states have these digests at level t (-1: leaves, digests None); cached: their memory recalls through the run's
        RecallCache (as a stepped batch's does, not one selected from it: Agent.select leaves the cache out)."""
        state = {name: {key: getattr(part, key).numpy() for key in part.state_dict()}
                 for name, part in (("hub", agents.hub), ("memory", agents.memory), ("rules", agents.rules))}
        self._queue.put(pickle.dumps((t, digests, cached, state), protocol=pickle.HIGHEST_PROTOCOL))

    def results(self) -> tuple[dict, list]:
        """({(level, digest): rounded error (NaN: nothing predicted)} of every state sent at a level, [(predictions
        (B, n_probes), their rounded errors (None: nothing predicted))] of every batch of leaves sent (level -1), in
        the order sent)."""
        self._queue.put(pickle.dumps(None))
        self._queue.put(None)
        self._writer.join()
        try:
            if self._failed is not None:
                raise EOFError
            memo, leaves, self.recalls = pickle.loads(self._back.recv_bytes())
            return memo, leaves
        except EOFError:
            raise RuntimeError(f"the population's probe process (pid {self.pid}) died") from None

    def close(self) -> None:
        """End the child (its answer is in, or the walk ended early) and the writer, then the pipes."""
        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGKILL)
                os.waitpid(self.pid, 0)
            except (ProcessLookupError, ChildProcessError):
                pass
            self.pid = None
        self._queue.put(None)          # a writer still writing stops at its broken pipe, else here
        self._writer.join()
        for conn in (self._to, self._back):
            conn.close()


def _serve(walk: _Walk, template: Agent, inbox, outbox) -> None:
    """_ProbeProcess's child: read the batches of agents' states until None, then answer their errors."""
    cache, memo, leaves = RecallCache(), {}, []
    while (msg := pickle.loads(inbox.recv_bytes())) is not None:
        t, digests, cached, state = msg
        agents = template.select(torch.zeros(len(state["memory"]["count"]), dtype=torch.long))
        for name, buffers in state.items():
            part = getattr(agents, name)
            for key, value in buffers.items():
                setattr(part, key, torch.from_numpy(value))
        if cached:
            agents.memory.cache = cache
        pred = walk._probe_predictions(agents)
        errors = median_rel_errors(pred, walk.truth)
        if t < 0:   # leaves, as _Walk._finish reads them
            leaves.append((pred.numpy(), [None if e is None else round(e, 4) for e in errors]))
            continue
        for d, e in zip(digests, errors):
            memo[(t, d)] = float("nan") if e is None else round(e, 4)
    outbox.send_bytes(pickle.dumps((memo, leaves, _digests(cache.index)), protocol=pickle.HIGHEST_PROTOCOL))


def _digests(keys) -> set:
    """16-byte digests (blake2b) of a RecallCache's keys: the recalls two processes made, counted once."""
    return {hashlib.blake2b(k, digest_size=16).digest() for k in keys}
