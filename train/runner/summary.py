"""summary.json (CONTRACTS.md contract) and the short table the runner prints at the end.

For large populations (more than FULL_RUNS orders) `runs` keeps the full episode records of the first FULL_RUNS
orders only (the runner runs those in detail), and a compact `population` block covers every order: its final
knowledge (one letter per property: U unknown, L likely irrelevant, D dominant, I irrelevant) and final probe error,
and the fraction of orders that agree with the most common final knowledge. `order_independent` is always computed
over every order (null for a single order, where it is undefined).

`config` is the run's whole config in the layout `--config` reads (train/common/config.py): the agents' as the experiment
ran it and the world's; `commit` names the code (`git describe --always --dirty` in the repository, or "unknown"),
`versions` the libraries that computed it.
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import os
import subprocess
import sys
from pathlib import Path

from aesop_torch.encoders import object_properties
from aesop_torch.rules import KNOWLEDGE_LETTERS, STATES

ROOT = Path(__file__).resolve().parents[2]
GIT_TIMEOUT_S = 5.0
# a git environment that points elsewhere would describe another repository
GIT_REDIRECTS = ("GIT_DIR", "GIT_WORK_TREE", "GIT_INDEX_FILE", "GIT_COMMON_DIR", "GIT_OBJECT_DIRECTORY")
VERSIONED = ("torch", "pybullet", "numpy")


def knowledge_key(k: dict) -> str:
    return "".join(KNOWLEDGE_LETTERS[STATES.index(k[p]["state"])] for p in object_properties(k))


def git_commit(root=ROOT, timeout: float = GIT_TIMEOUT_S) -> str:
    """`git describe --always --dirty` run in `root` (the repository's root), or "unknown": outside a repository,
    without git, past the timeout, on any error. Takes no lock (GIT_OPTIONAL_LOCKS=0: a describe --dirty would
    otherwise refresh the index beside whoever else is using the repository)."""
    env = {k: v for k, v in os.environ.items() if k not in GIT_REDIRECTS}
    env["GIT_OPTIONAL_LOCKS"] = "0"
    try:
        r = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=root, env=env, capture_output=True,
                           text=True, timeout=timeout, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.SubprocessError, ValueError):
        return "unknown"
    out = r.stdout.strip()
    return out if r.returncode == 0 and out and "\n" not in out else "unknown"


def versions() -> dict:
    """{"torch", "pybullet", "numpy": version}: the module's __version__ (pybullet has none: its distribution's),
    "unknown" when neither is found."""
    out = {}
    for name in VERSIONED:
        v = getattr(sys.modules.get(name), "__version__", None)
        if v is None:
            try:
                v = importlib.metadata.version(name)
            except importlib.metadata.PackageNotFoundError:
                v = "unknown"
        out[name] = str(v)
    return out


def build_summary(exp, population: dict | None = None, config: dict | None = None) -> dict:
    """exp: the Experiment run in detail (at most FULL_RUNS orders); population: train.learning.population's result for
    every order when there are more; config: the run's config as train.common.config.config_dict gives it (None: the
    experiment's agents with the default world)."""
    if config is None:
        from sim.world import WorldConfig
        from train.common.config import RunConfig, config_dict
        config = config_dict(RunConfig(exp.config, WorldConfig()))
    names = exp.train_names
    finals = exp.final_knowledge()
    resting = exp.knowledge_as_it_is()
    runs = [{"order": [names[i] for i in exp.orders[b]], "episodes": exp.records[b], "final_knowledge": finals[b],
             "knowledge_by_context": resting[b]["by_context"], "confounded": resting[b]["confounded"]}
            for b in range(len(exp.orders))]
    for b, trials in enumerate(getattr(exp, "trials", None) or []):   # only when the objects file has trials
        runs[b]["trials"] = trials
    keys = population["final_knowledge"] if population else [knowledge_key(k) for k in finals]
    # one order cannot show independence of the order: undefined there (null), never a vacuous true
    independent = len(set(keys)) == 1 if len(keys) > 1 else None
    summary = {"seed": exp.seed, "physics": exp.physics, "model": exp.config.model, "ablate": list(exp.config.ablate),
               "commit": git_commit(), "versions": versions(), "config": config,
               "runs": runs, "order_independent": independent}
    if population:
        summary["population"] = {
            "orders": len(keys),
            "key": "one letter per property (" + ", ".join(exp.config.encoder.properties)
                   + "): U unknown, L likely irrelevant, D dominant, I irrelevant",
            "most_common_knowledge": population["most_common_knowledge"],
            "agree_fraction": population["agree_fraction"],
            "final_knowledge": keys,
            "final_probe_rel_error": population["final_probe_rel_error"],
        }
    return json_safe(summary)


def summary_text(summary: dict) -> str:
    """json.dumps(summary, indent=1), the same text, faster: with an indent json.dumps encodes in Python, item by
    item; without one, in C. The population's two lists of every order (362,880 keys and errors for 9 objects) are
    encoded so, one item a line one space deeper than their key as the indent would put them (the item separator a
    comma, a newline and that indent), in place of a placeholder the indented dump wrote."""
    pop = summary.get("population")
    lists = {k: pop[k] for k in ("final_knowledge", "final_probe_rel_error")
             if isinstance(pop, dict) and isinstance(pop.get(k), list)}
    if not lists or not all({type(v) for v in items} <= _SCALARS for items in lists.values()):
        return json.dumps(summary, indent=1)
    marks = {k: f"@@summary_text:{k}@@" for k in lists}
    text = json.dumps({**summary, "population": {**pop, **marks}}, indent=1)
    for key, mark in marks.items():
        quoted = json.dumps(mark)
        at = text.find(quoted)
        if at < 0 or text.find(quoted, at + 1) >= 0:   # a mark that is also someone's value: the plain way
            return json.dumps(summary, indent=1)
        depth = at - text.rfind("\n", 0, at) - 1 - len(json.dumps(key) + ": ")
        items = lists[key]
        inner = json.dumps(items, separators=(",\n" + " " * (depth + 1), ": "))[1:-1]   # scalars: no nesting
        body = f"[\n{' ' * (depth + 1)}{inner}\n{' ' * depth}]" if items else "[]"
        text = text[:at] + body + text[at + len(quoted):]
    return text


_SCALARS = {str, int, float, bool, type(None)}   # what json writes alike with and without an indent


def json_safe(x):
    """x with every non-finite float as None (JSON's null): json.dumps would write a bare NaN or Infinity, which no
    JSON reader takes. Tuples become lists; strings stay (json.dumps escapes their control characters)."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        kinds = set(map(type, x))
        if kinds <= _PLAIN:   # a population's 362,880 keys: nothing to change, no call per item
            return list(x)
        if kinds <= _PLAIN | {float}:   # and its errors: only a float may change
            return [v if type(v) is not float or math.isfinite(v) else None for v in x]
        return [json_safe(v) for v in x]
    return x


_PLAIN = {str, int, bool, type(None)}   # exactly these types (not a subclass): json_safe leaves them as they are


def knowledge_table(summary: dict) -> str:
    runs = summary["runs"]
    props = object_properties(runs[0]["final_knowledge"]) if runs else ()
    lines = [f"{'order':<7}" + "".join(f"{p:<26}" for p in props) + "probe error first -> last"]
    for i, run in enumerate(runs[:12]):
        errs = [e["probe_rel_error"] for e in run["episodes"] if e["probe_rel_error"] is not None]
        err = f"{100 * errs[0]:.1f}% -> {100 * errs[-1]:.1f}%" if errs else "n/a"
        confounded = run.get("confounded", [])
        cells = "".join((f"{k['state']} ({k['certainty']:.2f})" + (" conf." if p in confounded else "")).ljust(26)
                        for p, k in ((p, run["final_knowledge"][p]) for p in props))
        lines.append(f"{i + 1:<7}{cells}{err}")
        if i == 0 and summary.get("model") != "paper":   # a model with contexts
            by = run.get("knowledge_by_context", {})
            lines.append("       by context: " + "; ".join(
                f"{c}: dominant {', '.join(v['dominant']) or '-'}, irrelevant {', '.join(v['irrelevant']) or '-'}"
                for c, v in by.items()))
    if len(runs) > 12:
        lines.append(f"... {len(runs) - 12} more orders in summary.json")
    if any(run.get("confounded") for run in runs):
        lines.append("conf.: dominant only through comparisons where it changed together with other properties, "
                     "never shown alone")
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
