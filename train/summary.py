"""summary.json (CONTRACTS.md contract) and the short table the runner prints at the end.

For large populations (more than FULL_RUNS orders) `runs` keeps the full episode records of the first FULL_RUNS
orders only (the runner runs those in detail), and a compact `population` block covers every order: its final
knowledge (one letter per property: U unknown, L likely irrelevant, D dominant, I irrelevant) and final probe error,
and the fraction of orders that agree with the most common final knowledge. `order_independent` is always computed
over every order (null for a single order, where it is undefined).
"""

from __future__ import annotations

from aesop_torch.rules import PROPERTIES, STATES

FULL_RUNS = 64  # 64 orders x 8 episodes of full records is ~0.5 MB of JSON; 40,320 would be ~300 MB


KNOWLEDGE_LETTERS = "ULDI"   # one letter per rules.STATES code, in its order
assert len(KNOWLEDGE_LETTERS) == len(STATES)


def knowledge_key(k: dict) -> str:
    return "".join(KNOWLEDGE_LETTERS[STATES.index(k[p]["state"])] for p in PROPERTIES)


def build_summary(exp, population: dict | None = None) -> dict:
    """exp: the Experiment run in detail (at most FULL_RUNS orders); population: train.population's result for
    every order when there are more."""
    names = exp.train_names
    finals = exp.final_knowledge()
    runs = [{"order": [names[i] for i in exp.orders[b]], "episodes": exp.records[b], "final_knowledge": finals[b]}
            for b in range(len(exp.orders))]
    for b, trials in enumerate(getattr(exp, "trials", None) or []):   # only when the objects file has trials
        runs[b]["trials"] = trials
    keys = population["final_knowledge"] if population else [knowledge_key(k) for k in finals]
    # one order cannot show independence of the order: undefined there (null), never a vacuous true
    independent = len(set(keys)) == 1 if len(keys) > 1 else None
    summary = {"seed": exp.seed, "physics": exp.physics, "model": exp.config.model, "ablate": list(exp.config.ablate),
               "runs": runs, "order_independent": independent}
    if population:
        summary["population"] = {
            "orders": len(keys),
            "key": "one letter per property (" + ", ".join(PROPERTIES)
                   + "): U unknown, L likely irrelevant, D dominant, I irrelevant",
            "most_common_knowledge": population["most_common_knowledge"],
            "agree_fraction": population["agree_fraction"],
            "final_knowledge": keys,
            "final_probe_rel_error": population["final_probe_rel_error"],
        }
    return summary


def knowledge_table(summary: dict) -> str:
    runs = summary["runs"]
    lines = [f"{'order':<7}" + "".join(f"{p:<26}" for p in PROPERTIES) + "probe error first -> last"]
    for i, run in enumerate(runs[:12]):
        errs = [e["probe_rel_error"] for e in run["episodes"] if e["probe_rel_error"] is not None]
        err = f"{100 * errs[0]:.1f}% -> {100 * errs[-1]:.1f}%" if errs else "n/a"
        cells = "".join(f"{k['state']} ({k['certainty']:.2f})".ljust(26)
                        for k in (run["final_knowledge"][p] for p in PROPERTIES))
        lines.append(f"{i + 1:<7}{cells}{err}")
    if len(runs) > 12:
        lines.append(f"... {len(runs) - 12} more orders in summary.json")
    trials = [t for run in runs for t in run.get("trials", [])]
    if trials:
        n = len(trials)
        lines.append(f"goal trials: {sum(t['goal_reached'] for t in trials)} of {n} reached the ball; drops "
                     f"{sum(t['drops'] for t in trials)} (planner's fewest {sum(t['fewest_drops'] for t in trials)}, "
                     f"random {sum(t['random_drops_mean'] for t in trials):.1f}); first choice optimal in "
                     f"{sum(t['first_choice_optimal'] for t in trials)} of {n} (all orders)")
    pop = summary.get("population")
    if pop:
        lines.append(f"population: {pop['orders']} orders, {100 * pop['agree_fraction']:.2f}% agree on "
                     f"{pop['most_common_knowledge']} ({pop['key']})")
    independent = summary["order_independent"]
    lines.append("order_independent: " + ("undefined (one order)" if independent is None else str(independent).lower()))
    return "\n".join(lines)
