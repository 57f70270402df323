"""Which part of each model carries which result: the paper and extended models beside their ablations and two peers.

    python benches/ablation.py [--sets 30] [--long-sets 10] [--lives 8] [--orders 24] [--first-seed 0]
                               [--conditions NAME,...] [--workers N] [--record]

Generated sets (`sim.make_objects --pairs`, seeds first-seed..), measurements and outcomes with the simulated robot's
noise (`sim.sensor_model.SensorModel`): sets of 8 and of 24 train objects learned in `--orders` random orders each
(8 probes), and lives of 230 train objects in one order each (16 probes). Conditions:

- paper, paper -rules (no rule fires: the strengths stay at 1), paper -gating (the cue ignores the strengths);
- contextual and its ablations (-rules, -gating, -context, -fit, -boundary: the expected fate by the recalled fates'
  vote instead of a fitted boundary, -replay: today's sequential rules instead of the knowledge re-derived from every
  pair lived, -signed: no signed consistency, -tally: replay's Elimination on any clean pair whose outcome held
  instead of on a share of the property's clean pairs, -lived: the fate's boundary fitted over the episodes the
  fate's recall brings back instead of every episode lived, -causes: that boundary over every property live for the
  fate instead of only those dominant in some context), and contextual +active: the robot chooses its next object
  (`explore = "active"`, aesop_torch/exploration.py) from the teacher's first;
- extended, extended -rules, extended -prior (its readout without the physics priors);
- on request (`--conditions`), paper +knowledge: the paper model with the right knowledge set by hand and its
  rules off, what its readout can do when the knowledge is right;
- kNN and MLP (benches/generalization.py's peers) on the perceived features the agent has (rgb, log extents, fill,
  log mass), and kNN+ and MLP+ with the extended model's derived features besides (log volume = fill x extents, and
  log mass over volume, which decides the fate).

Printed per condition: the median novel-object error |predicted - Archimedes| / Archimedes (median over probes, then
over (set, order); nothing recalled counts as 100 %) after 8 (sets of 8), 24 (sets of 24) and 8 / 24 / 64 / 230
objects (lives); the share of sets whose final knowledge is the same in every order; how often colour ends
irrelevant and how often it ends dominant (of (set, order)); and for the paper model how often weight or size ends
irrelevant (a physically wrong elimination). Last line:
`paper_err_24= paper_err_64= paper_err_230= paper_rules_off_ratio_230= paper_order_agreement_8= extended_err_8=
extended_rules_off_ratio_24=` (err_24 from the sets of 24, err_64 and err_230 from the lives; a ratio is the ablated
model's error over the model's), then the contextual model's (issue 45): `contextual_err_24= contextual_err_64=
contextual_err_230= contextual_order_agreement_24= contextual_right_functional_24= contextual_right_functional_230=
contextual_right_strict_230= contextual_rules_off_ratio_24= contextual_rules_off_ratio_64=
contextual_rules_off_ratio_230= contextual_gating_off_ratio_230= contextual_active_err_24=
contextual_life_time_ratio=`: order agreement the share of sets of 24 with the same per-context knowledge in every
order; functionally right the share of (set, order) whose final knowledge has in each context exactly what decides it
dominant (floaters: weight; sinkers: fill and size; fate: fill, size and weight), strict and every other property
irrelevant; active err `n/a` without the `contextual +active` condition; the time ratio a life's contextual over paper
wall time (medians over lives, side by side). `--record` writes the output into BENCHMARKS.md.

The agent conditions (the six above) run as the sweep benches/ablation.toml runs them: each (condition, set) is
train/sweep.py's cell (`train.sweeps.cell.run_cell`, one code path) and their figures are train/report.py's medians, so
`python train/sweep.py benches/ablation.toml` then `python -m train.report` gives these figures digit for digit (and
at scale, on a Ray cluster). The peers and paper +knowledge (its knowledge set by hand) are no sweep conditions: they
run here, their medians taken the same way.

Numbers of the models were chosen on seeds 1000 and up; the default seeds (0..) are for reporting.
"""

from __future__ import annotations

import argparse
import multiprocessing
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from aesop_torch.malloc import keep_freed_memory  # noqa: E402

import torch  # noqa: E402

from aesop_torch.agent import Agent, AgentConfig  # noqa: E402
from aesop_torch.rules import DOMINANT, IRRELEVANT, KNOWLEDGE_LETTERS  # noqa: E402
from generalization import knn, mlp, raw_features, rel_errors  # noqa: E402
from sim.make_objects import generate  # noqa: E402
from sim.objects import parse_objects  # noqa: E402
from sim.sensor_model import SensorModel  # noqa: E402
from train.learning.experiment import closed_form_outcomes, draw_orders, stack_measurements  # noqa: E402
from train.learning.population import knowledge_keys  # noqa: E402
from train.learning.sim_pool import cores  # noqa: E402
from train.common.progress import Step  # noqa: E402
from train.sweeps import cell as sweep_cell  # noqa: E402
from train.sweeps import spec as sweep_spec  # noqa: E402
from train.sweeps.report import summarise  # noqa: E402
from cli_args import count, record_flag, seed  # noqa: E402
from record import run_main  # noqa: E402

MODELS = {"paper": ("paper", ()), "paper -rules": ("paper", ("rules",)), "paper -gating": ("paper", ("gating",)),
          "contextual": ("contextual", ()), "contextual -rules": ("contextual", ("rules",)),
          "contextual -gating": ("contextual", ("gating",)), "contextual -context": ("contextual", ("context",)),
          "contextual -fit": ("contextual", ("fit",)),
          "contextual -boundary": ("contextual", ("boundary",)), "contextual -replay": ("contextual", ("replay",)),
          "contextual -signed": ("contextual", ("signed",)), "contextual -tally": ("contextual", ("tally",)),
          "contextual -lived": ("contextual", ("lived",)), "contextual -causes": ("contextual", ("causes",)),
          "contextual +active": ("contextual", ()), "contextual size=largest": ("contextual", ()),
          "extended": ("extended", ()), "extended -rules": ("extended", ("rules",)),
          "extended -prior": ("extended", ("prior",))}
# conditions that differ from their model by a config key, not an ablation: the robot chooses its next object
# (AgentConfig.explore, aesop_torch/exploration.py) instead of the teacher's order
OVERRIDES = {"contextual +active": {"explore": "active"},
             # size read as the largest extent, not the cube root of the bounding box's volume (docs/model.md)
             "contextual size=largest": {"encoder.size_from": "largest"}}
# run only when --conditions names them
ON_REQUEST = ("contextual size=largest",)
DEFAULT_AGENTS = [c for c in MODELS if c not in ON_REQUEST]   # the agent conditions run by default (ablation.toml)
PEERS = ("kNN", "MLP", "kNN+", "MLP+")
# not run by default: the paper model with the physically right knowledge set by hand and its rules off (colour
# eliminated, size and weight dominant, shape untouched): what its readout does when the knowledge is right
# the physically right knowledge per context (contextual_rules.CONTEXTS; properties SPLIT_PROPERTIES): a floater
# displaces its weight, a sinker its volume (fill and size), and whether it floats depends on all three. Given by
# hand as strengths (3 dominant, 0.05 eliminated), and checked on a life's final knowledge (RIGHT: the letters each
# context must show, "." where either is right)
RIGHT = {"floating": "IIIID", "sinking": "IDIDI", "fate": ".D.DD"}
RIGHT_STRENGTH = [[0.05 if c == "I" else 3.0 if c == "D" else 1.0 for c in RIGHT[k]]
                  for k in ("floating", "sinking", "fate")]
# the hub's strengths per property (paper), or the rules' per context and property (contextual)
GIVEN = {"paper +knowledge": ("paper", ("rules",), (0.05, 1.0, 3.0, 3.0)),
         "contextual +knowledge": ("contextual", ("rules",), RIGHT_STRENGTH)}
LIFE_CHECKS = (8, 24, 64, 230)


def derived_features(meas: dict) -> torch.Tensor:
    """The peers' inputs with the extended model's derived features besides: log volume, log mass over volume."""
    vol = (meas["fill"] * meas["extent_cm"].prod(-1)).log()
    return torch.cat([raw_features(meas), vol[:, None], (meas["mass_g"].log() - vol)[:, None]], 1)


def peer_errors(meas, observed, pmeas, truth, orders, n: int, seed_: int) -> dict:
    """Each peer's (B,) error after the first n objects of each order."""
    seen, y = orders[:, :n], observed.log()
    out = {}
    for plus, feats in ((False, raw_features), (True, derived_features)):
        x, xq = feats(meas), feats(pmeas)
        if plus:   # scale the two derived columns like the log extents in knn's distance
            x, xq = torch.cat([x[:, :8], x[:, 8:] * 2], 1), torch.cat([xq[:, :8], xq[:, 8:] * 2], 1)
        tag = "+" if plus else ""
        out["kNN" + tag] = rel_errors(_knn(x[seen], y[seen], xq).exp(), truth)
        out["MLP" + tag] = rel_errors(mlp(x[seen], y[seen], xq, seed_ * 1000 + n).exp(), truth)
    return out


def _knn(tx, ty, xq):
    """generalization.knn on any number of features (its scale covers the 8 raw ones; the rest count at 1)."""
    if tx.shape[-1] == 8:
        return knn(tx, ty, xq)
    d = torch.cdist(xq[None].expand(tx.shape[0], -1, -1), tx)
    k = min(3, tx.shape[1])
    dist, idx = d.topk(k, dim=-1, largest=False)
    w = 1.0 / (dist + 1e-6)
    return (w * ty.gather(1, idx.flatten(1)).view_as(idx)).sum(-1) / w.sum(-1)


def world(seed_: int, n_train: int, n_probe: int):
    objs = parse_objects(generate(seed_, n_train, n_probe, pairs=True))
    outcomes, probes = closed_form_outcomes(objs, sensor=SensorModel(), seed=seed_)
    names, pnames = [o.name for o in objs.train], [o.name for o in objs.probe]
    ep = {k: torch.tensor([outcomes[n][k] for n in names]) for k in ("observed_cm3", "goal_before", "goal_after",
                                                                      "sank")}
    return (stack_measurements([outcomes[n]["measurement"] for n in names]), ep,
            stack_measurements([probes[n]["measurement"] for n in pnames]),
            torch.tensor([probes[n]["archimedes_cm3"] for n in pnames]))


def run(condition: str, seed_: int, n_train: int, n_probe: int, n_orders: int, checks) -> dict:
    """One condition on one set in n_orders orders: errors (B,) at each check, final knowledge keys and states."""
    meas, ep, pmeas, truth = world(seed_, n_train, n_probe)
    orders = torch.tensor(draw_orders(n_train, str(n_orders), seed_))
    B = len(orders)
    if condition in PEERS:
        errs = {}
        for n in checks:
            errs[n] = peer_errors(meas, ep["observed_cm3"], pmeas, truth, orders, n, seed_)[condition]
        return {"errors": errs}
    model, ablate, given = GIVEN[condition] if condition in GIVEN else (*MODELS[condition], None)
    cfg = AgentConfig.named(model, ablate=ablate, seed=seed_)
    if condition in OVERRIDES:
        from train.common.config import apply_overrides
        cfg = apply_overrides(cfg, OVERRIDES[condition])
    cfg.memory.max_episodes = cfg.hub.max_assemblies = n_train
    agent = Agent(cfg, batch=B)
    if given is not None and torch.tensor(given).ndim == 2:   # per context: the contextual rules' strengths
        agent.rules.strength[:] = torch.tensor(given)
        agent._set_judged_strength(agent.rules.strength_from_knowledge())
    elif given is not None:
        agent.hub.strength[:, :len(given)] = torch.tensor(given)
    errs = {}
    active = cfg.explore == "active"
    if active:   # the robot chooses its next object (as train.sweeps.cell.run_cell)
        from aesop_torch.exploration import choose_in_order
        seen = agent.activities(meas)
    for t in range(n_train):
        obj = choose_in_order(agent, *seen, orders, t) if active else orders[:, t]
        agent.step({k: v[obj] for k, v in meas.items()}, ep["observed_cm3"][obj], ep["goal_before"][obj],
                   ep["goal_after"][obj], sank=ep["sank"][obj])
        if t + 1 in checks:
            Q = len(truth)
            probe = agent.select(torch.arange(B).repeat_interleave(Q))
            p = probe.anticipate({k: v.repeat(B, *([1] * (v.ndim - 1))) for k, v in pmeas.items()})
            errs[t + 1] = rel_errors(p.expected.view(B, Q), truth)
    return {"errors": errs, "keys": knowledge_keys(agent.rules.state), "state": agent.rules.state.clone(),
            "properties": agent.properties}


# the sweep file's set groups (benches/ablation.toml) of the bench's three kinds of set
GROUPS = {"8": "sets of 8", "24": "sets of 24", "life": "lives"}


def sweep_doc(conditions, plan, first_seed: int) -> dict:
    """The agent conditions and sets of this run as a sweep file (benches/ablation.toml at the defaults)."""
    return {"world": "closed_form",
            "conditions": [{"name": c, "model": MODELS[c][0], "ablate": list(MODELS[c][1]),
                            **({"overrides": OVERRIDES[c]} if c in OVERRIDES else {})} for c in conditions],
            "sets": [{"name": GROUPS[kind], "generate": {"seeds": [first_seed, first_seed + n_sets], "train": n_train,
                                                         "probe": n_probe, "pairs": True},
                      "orders": n_orders, "checks": list(checks)}
                     for kind, n_sets, n_train, n_probe, n_orders, checks in plan if n_sets]}


def _task(t):
    torch.set_num_threads(1)
    if t[0] == "cell":   # an agent condition: the sweep's cell, and its wall time
        t0 = time.perf_counter()
        table = sweep_cell.run_cell(t[1]["spec"], t[1]["objects"])
        return table, time.perf_counter() - t0
    return run(*t[1:])


def agent_rows(conditions, plan, first_seed: int, workers: int, bar=None, times: dict | None = None):
    """The rows (a pyarrow Table of train.sweeps.cell.schema()) of the agent conditions on the plan's sets: the sweep's
    cells, run on `workers` processes. Equal, row for row, to train/sweep.py on sweep_doc's file. times: filled with
    {(condition, set group): [each cell's wall time, s]}."""
    import pyarrow as pa
    _, cells = sweep_spec.resolve(sweep_doc(conditions, plan, first_seed), ROOT)
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        tables = []
        for c, (t, seconds) in zip(cells, pool.imap(_task, [("cell", c) for c in cells])):
            tables.append(t)
            if times is not None:
                spec = c["spec"]
                times.setdefault((spec["condition"]["name"], spec["set_group"]), []).append(seconds)
            if bar is not None:
                bar.update(1)
    return pa.concat_tables(tables)


def final(table, condition: str, group: str):
    """The rows (a pyarrow Table) of the condition's runs on a set group at their last episode."""
    import pyarrow.compute as pc
    m = pc.and_(pc.and_(pc.equal(table.column("condition"), condition), pc.equal(table.column("set_group"), group)),
                pc.equal(table.column("episode"), table.column("n_train")))
    return table.filter(m)


def final_rows(table, condition: str, group: str) -> list[dict]:
    """`final`'s rows as dicts."""
    return final(table, condition, group).to_pylist()


def right_per_context(key: str | None) -> bool:
    """A context_knowledge string ("floating:...;sinking:...;fate:...") physically right in every context (RIGHT)."""
    if not key:
        return False
    got = dict(part.split(":") for part in key.split(";"))
    return all(len(got[c]) == len(w) and all(x == "." or x == y for x, y in zip(w, got[c])) for c, w in RIGHT.items())


# what decides the outcome in each context (the "functionally right"): floaters displace their weight,
# sinkers their volume (fill and size), and the fate depends on all three; letters per SPLIT_PROPERTIES
DECIDES = {"floating": "....D", "sinking": ".D.D.", "fate": ".D.DD"}


def functionally_right(key: str | None, strict: bool = False) -> bool:
    """A context_knowledge string with, in every context, exactly the properties that decide it dominant (DECIDES);
    strict: and every other property irrelevant."""
    if not key:
        return False
    got = dict(part.split(":") for part in key.split(";"))
    return all(len(got[c]) == len(w) and all((y == "D") == (x == "D") and (not strict or x == "D" or y == "I")
                                             for x, y in zip(w, got[c])) for c, w in DECIDES.items())


def right_share(table, condition: str, group: str, strict: bool = False) -> float:
    """The share of the group's (set, order) whose final knowledge is functionally (or strictly) right."""
    rows = final_rows(table, condition, group)
    return sum(functionally_right(r["context_knowledge"], strict) for r in rows) / max(len(rows), 1)


def context_agreement(table, condition: str, group: str) -> float:
    """The share of the group's sets whose final knowledge per context is the same in every order."""
    sets: dict = {}
    for r in final_rows(table, condition, group):
        sets.setdefault(r["cell"], set()).add(r["context_knowledge"])
    return sum(len(v) == 1 for v in sets.values()) / max(len(sets), 1)


def final_share(table, condition: str, group: str, prop: str, letter: str) -> float:
    """The share of (set, order) whose final knowledge of prop (a rows column: color, weight, size, shape) is letter."""
    v = final(table, condition, group).column(prop).to_pylist()
    return sum(x == letter for x in v) / max(len(v), 1)


def main():
    keep_freed_memory()
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sets", type=count, default=30, help="sets of 8 train objects")
    ap.add_argument("--long-sets", type=count, default=10, help="sets of 24 train objects")
    ap.add_argument("--lives", type=count, default=8, help="lives of 230 train objects, one order each")
    ap.add_argument("--life-objects", type=count, default=230, help="objects in a life")
    ap.add_argument("--orders", type=count, default=24)
    ap.add_argument("--first-seed", type=seed, default=0)
    ap.add_argument("--conditions", default=",".join([*DEFAULT_AGENTS, *PEERS]),
                    help="comma-separated subset of: " + ", ".join([*MODELS, *PEERS, *GIVEN]))
    ap.add_argument("--workers", type=count, default=cores(), help="processes (default: the machine's cores)")
    record_flag(ap)
    a = ap.parse_args()
    conditions = [c.strip() for c in a.conditions.split(",") if c.strip()]
    if bad := [c for c in conditions if c not in MODELS and c not in PEERS and c not in GIVEN]:
        ap.error(f"--conditions: unknown {', '.join(map(repr, bad))}")
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    life_checks = tuple(n for n in LIFE_CHECKS if n < a.life_objects) + (a.life_objects,)
    plan = [("8", a.sets, 8, 8, a.orders, (8,)), ("24", a.long_sets, 24, 8, a.orders, (8, 24)),
            ("life", a.lives, a.life_objects, 16, 1, life_checks)]
    agents = [c for c in conditions if c in MODELS]
    others = [c for c in conditions if c not in MODELS]
    # every (condition, set) is a task of its own, run on --workers processes (each a deterministic function of its
    # arguments: the result does not depend on the worker count); the longest (lives) first
    tasks = [(kind, c, a.first_seed + i, n_train, n_probe, n_orders, checks)
             for kind, n_sets, n_train, n_probe, n_orders, checks in reversed(plan) for c in others
             for i in range(n_sets)]
    res = {(kind, c): [None] * n for kind, n, *_ in plan for c in others}
    n_cells = len(agents) * sum(n for _, n, *_ in plan)
    times: dict = {}
    with Step("(condition, set) runs", len(tasks) + n_cells, unit="run", stream=sys.stderr) as bar:
        rows = agent_rows(agents, plan, a.first_seed, a.workers, bar, times) if agents else None
        with multiprocessing.get_context("fork").Pool(a.workers) as pool:
            for (kind, c, s, *_), r in zip(tasks, pool.imap(_task, tasks)):
                res[kind, c][s - a.first_seed] = r
                bar.update(1)
    summary = summarise(rows) if agents else {"errors": {}, "knowledge": {}}
    print(f"{len(tasks) + n_cells} runs on {a.workers} process(es): {time.perf_counter() - t0:.0f} s", flush=True)

    def err(kind, c, n):
        """The median over (set, order) of the median over probes: train/report.py's for an agent condition."""
        if c in MODELS:
            return summary["errors"][c, GROUPS[kind]][n][1]
        return statistics.median(torch.cat([r["errors"][n] for r in res[kind, c]]).tolist())

    def same(kind, c):
        if c in MODELS:
            return summary["knowledge"][c, GROUPS[kind]]["order_agreement"]
        return sum(len(set(r["keys"])) == 1 for r in res[kind, c]) / len(res[kind, c])

    cols = [("8", 8, "8 (sets of 8)"), ("24", 24, "24 (sets of 24)")] + [("life", n, f"{n} (lives)")
                                                                           for n in life_checks]
    print(f"\nmedian novel-object error after n objects; seeds {a.first_seed}..; {a.sets} sets of 8 and "
          f"{a.long_sets} of 24 in {a.orders} orders, {a.lives} lives of {a.life_objects}")
    print(f"{'condition':<17}" + "".join(f"{h:>17}" for _, _, h in cols))
    for c in conditions:
        print(f"{c:<17}" + "".join(f"{err(k, c, n):>17.4f}" for k, n, _ in cols))
    print("\nknowledge (of (set, order)): same in every order = share of sets; C/W/S = colour / weight / size")
    print(f"{'condition':<17}{'same (8)':>10}{'same (24)':>10}{'C irrel.':>10}{'C dom.':>10}{'W irrel.':>10}"
          f"{'S irrel.':>10}   (C, W and S over the sets of 8 / of 24 / lives)")
    for c in conditions:
        if c in PEERS:
            continue

        def share(prop, code):
            if c in MODELS:
                return "/".join(f"{final_share(rows, c, GROUPS[k], prop, KNOWLEDGE_LETTERS[code]):.2f}"
                                for k in ("8", "24", "life"))
            parts = [torch.cat([r["state"][:, r["properties"].index(prop)] for r in res[k, c]])
                     for k in ("8", "24", "life")]
            return "/".join(f"{float((x == code).float().mean()):.2f}" for x in parts)
        print(f"{c:<17}{_fmt(same('8', c), 3):>10}{_fmt(same('24', c), 3):>10}  {share('color', IRRELEVANT)}  "
              f"{share('color', DOMINANT)}  {share('weight', IRRELEVANT)}  {share('size', IRRELEVANT)}")
    print(f"{time.perf_counter() - t0:.0f} s")

    def ratio(c, base, kind, n):
        return err(kind, c, n) / max(err(kind, base, n), 1e-12)
    line, ctx = {}, {}
    if "paper" in conditions:
        line["paper_err_24"] = err("24", "paper", 24)
        line["paper_err_64"] = err("life", "paper", 64) if 64 in life_checks else float("nan")
        line["paper_err_230"] = err("life", "paper", life_checks[-1])
        if "paper -rules" in conditions:
            line["paper_rules_off_ratio_230"] = ratio("paper -rules", "paper", "life", life_checks[-1])
        line["paper_order_agreement_8"] = same("8", "paper")
    if "contextual" in conditions:
        last = life_checks[-1]
        print("\ncontextual model, knowledge per context (floating / sinking / fate; letters color fill elongation "
              "size weight):")
        right = [right_per_context(r["context_knowledge"]) for r in final_rows(rows, "contextual", GROUPS["life"])]
        for r in final_rows(rows, "contextual", GROUPS["life"])[:8]:
            print(f"  life {r['set']}: {r['context_knowledge']}")
        ratio_t = float("nan")
        if "paper" in conditions and times.get(("paper", GROUPS["life"])):
            ratio_t = (statistics.median(times["contextual", GROUPS["life"]])
                       / statistics.median(times["paper", GROUPS["life"]]))
            print(f"a life of {a.life_objects} objects: contextual {statistics.median(times['contextual', GROUPS['life']]):.0f} s, "
                  f"paper {statistics.median(times['paper', GROUPS['life']]):.0f} s (medians over lives, one process "
                  f"each, side by side): {ratio_t:.2f}x")
        nan = float("nan")
        ctx["contextual_err_24"] = err("24", "contextual", 24) if a.long_sets else nan
        ctx["contextual_err_64"] = err("life", "contextual", 64) if 64 in life_checks else nan
        ctx["contextual_err_230"] = err("life", "contextual", last)
        ctx["contextual_order_agreement_24"] = context_agreement(rows, "contextual", GROUPS["24"]) if a.long_sets else nan
        ctx["contextual_right_functional_24"] = right_share(rows, "contextual", GROUPS["24"]) if a.long_sets else nan
        ctx["contextual_right_functional_230"] = right_share(rows, "contextual", GROUPS["life"])
        ctx["contextual_right_strict_230"] = right_share(rows, "contextual", GROUPS["life"], strict=True)
        off = "contextual -rules" in conditions
        ctx["contextual_rules_off_ratio_24"] = (ratio("contextual -rules", "contextual", "24", 24)
                                                if off and a.long_sets else nan)
        ctx["contextual_rules_off_ratio_64"] = (ratio("contextual -rules", "contextual", "life", 64)
                                                if off and 64 in life_checks else nan)
        ctx["contextual_rules_off_ratio_230"] = ratio("contextual -rules", "contextual", "life", last) if off else nan
        ctx["contextual_gating_off_ratio_230"] = (ratio("contextual -gating", "contextual", "life", last)
                                                  if "contextual -gating" in conditions else nan)
        # the robot choosing its next object (--explore active), when the condition exists
        ctx["contextual_active_err_24"] = (err("24", "contextual +active", 24)
                                           if "contextual +active" in conditions and a.long_sets else "n/a")
        ctx["contextual_life_time_ratio"] = ratio_t
        for c in ("contextual -context", "contextual -replay", "contextual -signed", "contextual -tally",
                  "contextual -lived", "contextual -causes"):
            if c in conditions:
                line[c.replace(" -", "_") + "_off_ratio_230"] = ratio(
                    c, "contextual", "life", last)
        for c in ("contextual -lived", "contextual -causes"):   # the fate's boundary: what it does after 24
            if c in conditions and a.long_sets:
                line[c.replace(" -", "_") + "_off_ratio_24"] = ratio(c, "contextual", "24", 24)
        line["contextual_right_knowledge_230"] = sum(right) / max(len(right), 1)
    if "extended" in conditions:
        line["extended_err_8"] = err("8", "extended", 8)
        if "extended -rules" in conditions:
            line["extended_rules_off_ratio_24"] = ratio("extended -rules", "extended", "24", 24)
    print(" ".join(f"{k}={_fmt(v)}" for k, v in line.items()))
    if ctx:   # the contextual model's figures (issue 45), last
        print(" ".join(f"{k}={_fmt(v)}" for k, v in ctx.items()))


def _fmt(v, digits: int = 4) -> str:
    """A figure to print: n/a where there is none (order agreement over one order is None)."""
    return "n/a" if v is None else f"{v:.{digits}f}" if isinstance(v, (int, float)) else str(v)


if __name__ == "__main__":
    run_main("ablation", main)
