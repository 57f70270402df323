"""A sweep's summary: novel-object errors, order agreement and colour's fate per condition, as tables and plots.

    python -m train.report DIR        (or: python train/report.py DIR)

Reads the finished cells of a sweep (DIR/cells/*.parquet, train/sweep.py; a sweep still running or interrupted is
summarised as far as it got) and writes (docs/sweeps.md):

- DIR/report.csv: one row per (condition, set group, episode count at which probe errors were recorded): n (the
  (set, seed, order) runs behind the figures), error_median, error_q25, error_q75 (of probe_rel_error: each run's
  median over its probes; percentiles with linear interpolation), and per (condition, set group), repeated on each
  of its rows: cells, order_agreement (the share of cells, i.e. (set, seed), whose final knowledge is the same in
  every order; empty when the cells have one order each) and colour_irrelevant (the share of (set, seed, order)
  whose final colour state is I);
- DIR/report.md: the same as tables (at most 12 episode counts per set group; all of them are in the CSV);
- DIR/errors.png: the median error against experience per condition, the 25-75 % band shaded, one panel per set
  group; DIR/agreement.png: order agreement and colour irrelevant per condition (bars, one per set group).

A DIR without finished cells is refused in one line, exit code 2.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import sys
from collections import Counter
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the project importable without installing it
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

PROG = "train.report"
MD_CHECKS = 12   # episode counts shown per set group in report.md


class ReportError(Exception):
    """One line on stderr, exit code 2."""


def _order(values, preferred: list) -> list:
    """The distinct values, those of `preferred` first in its order, the rest in order of appearance."""
    seen = list(dict.fromkeys(values))
    return [v for v in preferred if v in seen] + [v for v in seen if v not in preferred]


def summarise(table, spec: dict | None = None) -> dict:
    """The report's figures from a sweep's rows (a pyarrow Table of train.sweep.schema()). spec: the sweep's
    resolved spec (DIR/sweep.json), for the order of conditions and set groups. Returns {"conditions", "groups",
    "errors": {(condition, group): {episode: (n, median, q25, q75)}}, "knowledge": {(condition, group): {"cells",
    "order_agreement", "colour_irrelevant"}}}."""
    import numpy as np
    import pyarrow.compute as pc

    spec = spec or {}
    cond = pc.unique(table.column("condition")).to_pylist()    # in order of first appearance
    group = pc.unique(table.column("set_group")).to_pylist()
    conditions = _order(cond, [c["name"] for c in spec.get("conditions", [])])
    groups = _order(group, [s["name"] for s in spec.get("sets", [])])

    errors: dict = {}
    checked = table.filter(pc.is_valid(table.column("probe_rel_error")))
    if checked.num_rows:
        agg = checked.group_by(["condition", "set_group", "episode"]).aggregate([("probe_rel_error", "list")])
        for c, g, ep, vals in zip(*(agg.column(k).to_pylist() for k in ("condition", "set_group", "episode",
                                                                         "probe_rel_error_list"))):
            v = np.asarray(vals, dtype=np.float64)
            q25, med, q75 = np.percentile(v, [25, 50, 75])
            errors.setdefault((c, g), {})[ep] = (len(v), float(med), float(q25), float(q75))
    for k in errors:
        errors[k] = dict(sorted(errors[k].items()))
    checks = _checks(checked)

    final = table.filter(pc.equal(table.column("episode"), table.column("n_train")))
    knowledge: dict = {}
    if final.num_rows:
        per_cell = final.group_by(["condition", "set_group", "cell"]).aggregate(
            [("knowledge", "count_distinct"), ("order", "count")])
        for c, g, distinct, orders in zip(*(per_cell.column(k).to_pylist() for k in (
                "condition", "set_group", "knowledge_count_distinct", "order_count"))):
            k = knowledge.setdefault((c, g), {"cells": 0, "_multi": 0, "_same": 0, "_runs": 0, "_colour_i": 0,
                                              "_weight_d": 0, "_batched": 0, "_equal": 0})
            k["cells"] += 1
            if orders > 1:
                k["_multi"] += 1
                k["_same"] += distinct == 1
        cols = ("condition", "set_group", "cell", "order", "knowledge", "batch_knowledge", "color", "weight")
        answers: dict = {}   # (condition, group) -> {cell: its batch answer}
        for c, g, cell, _, key, batch, colour, weight in zip(*(final.column(k).to_pylist() for k in cols)):
            k = knowledge[c, g]
            k["_runs"] += 1
            k["_colour_i"] += colour == "I"
            k["_weight_d"] += weight == "D"
            if batch is not None:
                k["_batched"] += 1
                k["_equal"] += key == batch
                answers.setdefault((c, g), {})[cell] = batch
        for (c, g), k in knowledge.items():
            k["order_agreement"] = k["_same"] / k["_multi"] if k["_multi"] else None
            k["colour_irrelevant"] = k["_colour_i"] / k["_runs"]
            k["weight_dominant"] = k["_weight_d"] / k["_runs"]
            k["equals_batch"] = k["_equal"] / k["_batched"] if k["_batched"] else None
            # the batch answers of the cells, most common first (ties: in order of first appearance)
            k["batch_answers"] = dict(Counter(answers.get((c, g), {}).values()).most_common())
            for x in [x for x in k if x.startswith("_")]:
                del k[x]
    return {"conditions": conditions, "groups": groups, "errors": errors, "knowledge": knowledge, "checks": checks}


def _median(values: list) -> float:
    import numpy as np
    return float(np.median(np.asarray(values, dtype=np.float64)))


def _checks(checked) -> dict:
    """Per (condition, set group) and episode count with probe errors: {"floor": the median over runs of each run's
    median senses' floor, "over_floor": the median over runs of the run's mean over probes of error less floor,
    "over_2pts": the probes more than 2 points above their floor, summed over runs, "stored": the median over runs of
    the episodes stored, "recalled": the median over runs of the episodes recalled per probe cue, and after the first
    count "fell", "rose" (the runs whose error fell / rose since the previous count) and "change" (their median
    change)}. Rows without the per-probe columns (no probes) give none."""
    import numpy as np
    out: dict = {}
    if not checked.num_rows:
        return out
    cols = ("condition", "set_group", "cell", "order", "episode", "probe_rel_error", "probe_errors", "probe_floors",
            "stored", "recalled")
    runs: dict = {}   # (condition, group) -> {episode: {(cell, order): (error, over_floor, over_2pts, ...)}}
    for c, g, cell, order, ep, err, errs, floors, stored, recalled in zip(*(checked.column(k).to_pylist()
                                                                           for k in cols)):
        if errs is None or floors is None:
            continue
        excess = np.asarray(errs, dtype=np.float64) - np.asarray(floors, dtype=np.float64)
        f = np.sort(np.asarray(floors, dtype=np.float64))
        floor = f[len(f) // 2] if len(f) % 2 else (f[len(f) // 2 - 1] + f[len(f) // 2]) / 2
        runs.setdefault((c, g), {}).setdefault(ep, {})[cell, order] = (
            err, float(excess.mean()), int((excess > 0.02).sum()), float(floor), stored, recalled)
    for key, by_ep in runs.items():
        prev = None
        for ep in sorted(by_ep):
            r = by_ep[ep]
            fig = {"floor": _median([v[3] for v in r.values()]), "over_floor": _median([v[1] for v in r.values()]),
                   "over_2pts": sum(v[2] for v in r.values()), "stored": _median([v[4] for v in r.values()]),
                   "recalled": _median([v[5] for v in r.values()])}
            if prev is not None:
                change = [r[k][0] - prev[k][0] for k in r if k in prev]
                if change:
                    fig.update(fell=sum(d < 0 for d in change), rose=sum(d > 0 for d in change),
                               change=_median(change))
            out.setdefault(key, {})[ep] = fig
            prev = r
    return out


def _fmt(x, digits: int = 4) -> str:
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def write_csv(s: dict, path: Path) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["condition", "set_group", "episode", "n", "error_median", "error_q25", "error_q75", "floor",
                "over_floor", "probes_over_2pts", "stored", "recalled", "runs_fell", "runs_rose", "change_median",
                "cells", "order_agreement", "colour_irrelevant", "weight_dominant", "equals_batch"])
    for g in s["groups"]:
        for c in s["conditions"]:
            k = s["knowledge"].get((c, g))
            if k is None:
                continue
            tail = [k["cells"], _fmt(k["order_agreement"]), _fmt(k["colour_irrelevant"]), _fmt(k["weight_dominant"]),
                    _fmt(k["equals_batch"])]
            errs = s["errors"].get((c, g)) or {}
            if not errs:   # no probes, or no checks: the knowledge figures still have a row
                w.writerow([c, g, "", 0, "", "", ""] + [""] * 8 + tail)
            for ep, (n, med, q25, q75) in errs.items():
                f = (s.get("checks") or {}).get((c, g), {}).get(ep, {})
                mid = [_fmt(f.get("floor"), 6), _fmt(f.get("over_floor"), 6), f.get("over_2pts", ""),
                       _fmt(f.get("stored"), 1), _fmt(f.get("recalled"), 3), f.get("fell", ""), f.get("rose", ""),
                       _fmt(f.get("change"), 6)]
                w.writerow([c, g, ep, n, _fmt(med, 6), _fmt(q25, 6), _fmt(q75, 6)] + mid + tail)
    _write(path, buf.getvalue())


def _shown(episodes: list[int]) -> list[int]:
    """At most MD_CHECKS episode counts: all of them, or 1, 2, 4, 8, ... and the last."""
    if len(episodes) <= MD_CHECKS:
        return episodes
    pick = {episodes[-1]}
    p = 1
    while len(pick) < MD_CHECKS and p <= episodes[-1]:
        near = min(episodes, key=lambda e: abs(e - p))
        pick.add(near)
        p *= 2
    return sorted(pick)


def write_md(s: dict, path: Path, out: Path, n_cells: int, spec: dict | None) -> None:
    lines = [f"# Sweep report: {out}", ""]
    total = None
    if spec:
        total = len(spec["conditions"]) * sum(len(o["seeds"]) for st in spec["sets"] for o in st["objects"])
    lines.append(f"{n_cells} cell(s)" + (f" of {total}" if total is not None else "") + " finished"
                 + (f"; world {spec['world']}" if spec else "") + ". Written by `python -m train.report`; every "
                 "figure is also in report.csv.")
    lines += ["", "## Novel-object error", "",
              "probe_rel_error: |predicted - Archimedes| / Archimedes, the median over a run's probes (nothing "
              "recalled counts as 1); here the median over the (set, seed, order) runs and, in brackets, their "
              "25-75 % range, after n episodes.", ""]
    any_err = False
    for g in s["groups"]:
        eps = sorted({e for c in s["conditions"] for e in (s["errors"].get((c, g)) or {})})
        if not eps:
            continue
        any_err = True
        shown = _shown(eps)
        lines += [f"### {g}", "", "| condition | " + " | ".join(f"n = {e}" for e in shown) + " |",
                  "| --- |" + " --- |" * len(shown)]
        for c in s["conditions"]:
            errs = s["errors"].get((c, g))
            if not errs:
                continue
            cells = [f"{errs[e][1]:.4f} ({errs[e][2]:.3f}-{errs[e][3]:.3f})" if e in errs else "" for e in shown]
            lines.append(f"| {c} | " + " | ".join(cells) + " |")
        if len(shown) < len(eps):
            lines += ["", f"{len(shown)} of {len(eps)} episode counts shown; all in report.csv."]
        lines.append("")
    if not any_err:
        lines += ["No probe errors were recorded (no probes, or no checks).", ""]
    floors = [(g, c) for g in s["groups"] for c in s["conditions"] if (s.get("checks") or {}).get((c, g))]
    if floors:
        lines += ["## Memory and the senses' floor", "",
                  "per episode count with probe errors, medians over the (set, seed, order) runs: episodes stored, "
                  "episodes recalled per probe cue, the senses' floor (Archimedes on the probes as measured), the mean "
                  "over probes of the error less each probe's floor; probes more than 2 points above their floor "
                  "(summed over runs); runs whose error fell / rose since the previous count, and the median change.",
                  "", "| condition | set group | n | stored | recalled | floor | over floor | probes > 2 pts | "
                  "fell/rose | median change |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for g, c in floors:
            for ep in _shown(list(s["checks"][c, g])):
                f = s["checks"][c, g][ep]
                moved = f"{f['fell']}/{f['rose']}" if "fell" in f else ""
                lines.append(f"| {c} | {g} | {ep} | {f['stored']:.0f} | {f['recalled']:.1f} | {f['floor']:.4f} | "
                             f"{f['over_floor']:+.4f} | {f['over_2pts']} | {moved} | {_fmt(f.get('change'))} |")
        lines.append("")
    lines += ["## Knowledge after the last episode", "",
              "same in every order: the share of cells (set, seed) whose final knowledge key is the same in all its "
              "orders (empty: one order per cell); colour irrelevant, weight dominant: the share of (set, seed, order) "
              "whose final colour state is I, whose weight state is D; equals the batch answer: the share of (set, "
              "seed, order) whose final knowledge is the set's batch answer (every pair of its episodes compared at "
              "once); batch answers: per cell, most common first.", "",
              "| condition | set group | cells | same in every order | colour irrelevant | weight dominant | "
              "equals the batch answer | batch answers |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for g in s["groups"]:
        for c in s["conditions"]:
            k = s["knowledge"].get((c, g))
            if k:
                answers = ", ".join(f"{a} {n}" for a, n in list(k["batch_answers"].items())[:6])
                lines.append(f"| {c} | {g} | {k['cells']} | {_fmt(k['order_agreement'], 3)} | "
                             f"{_fmt(k['colour_irrelevant'], 3)} | {_fmt(k['weight_dominant'], 3)} | "
                             f"{_fmt(k['equals_batch'], 3)} | {answers} |")
    lines += ["", "![error against experience](errors.png)", "", "![order agreement](agreement.png)", ""]
    _write(path, "\n".join(lines))


def plot_errors(s: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, MaxNLocator, NullFormatter
    groups = [g for g in s["groups"] if any(s["errors"].get((c, g)) for c in s["conditions"])] or s["groups"]
    fig, axes = plt.subplots(1, len(groups), figsize=(5.2 * len(groups), 4.2), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, g in zip(axes[0], groups):
        drawn = False
        for i, c in enumerate(s["conditions"]):
            errs = s["errors"].get((c, g))
            if not errs:
                continue
            ep = list(errs)
            med, q25, q75 = ([100 * errs[e][j] for e in ep] for j in (1, 2, 3))
            col = colours[i % len(colours)]
            ax.plot(ep, med, "-o", color=col, markersize=3, label=c)
            ax.fill_between(ep, q25, q75, color=col, alpha=0.18, linewidth=0)
            drawn = True
        ax.set_title(g, fontsize=10)
        ax.set_xlabel("episodes (objects explored)")
        ax.set_ylabel("novel-object error, % (median, 25-75 %)")
        if drawn:
            ax.set_yscale("log")
            ax.legend(fontsize=8)
            plain = FuncFormatter(lambda v, _: f"{v:g}")
            lo, hi = ax.get_ylim()
            ax.yaxis.set_major_formatter(plain)      # 30, not 3 x 10^1
            two_five = FuncFormatter(lambda v, _: f"{v:g}" if f"{v:e}"[0] in "25" else "")
            ax.yaxis.set_minor_formatter(two_five if hi / lo < 1000 else NullFormatter())   # 2, 5, 20, 50, ...
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        else:
            ax.text(0.5, 0.5, "no probe errors", ha="center", va="center", transform=ax.transAxes)
        ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_agreement(s: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    conds, groups = s["conditions"], s["groups"]
    fig, axes = plt.subplots(1, 2, figsize=(max(8.0, 1.1 * len(conds) * 2 + 2), 4.2))
    width = 0.8 / max(1, len(groups))
    x = np.arange(len(conds))
    for ax, key, title in ((axes[0], "order_agreement", "same knowledge in every order (share of cells)"),
                           (axes[1], "colour_irrelevant", "colour ends irrelevant (share of runs)")):
        for j, g in enumerate(groups):
            vals = [(s["knowledge"].get((c, g)) or {}).get(key) for c in conds]
            bars = ax.bar(x + (j - (len(groups) - 1) / 2) * width, [np.nan if v is None else v for v in vals],
                          width, label=g)
            ax.bar_label(bars, labels=["n/a" if v is None else f"{v:.2f}" for v in vals], fontsize=7)
        ax.set_xticks(x, conds, rotation=30, ha="right", fontsize=8)
        ax.set_ylim(0, 1.1)
        ax.set_title(title, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
        if len(groups) > 1:
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _write(path: Path, text: str) -> None:
    from train.sweep import write_atomic
    write_atomic(path, text.encode())


def report(out: Path) -> dict:
    """Write DIR's report.md, report.csv, errors.png and agreement.png; returns the figures (summarise)."""
    from train.sweep import read_cells
    out = Path(out)
    if not out.is_dir():
        raise ReportError(f"{out} is not a directory")
    files = sorted((out / "cells").glob("*.parquet"))
    if not files:
        raise ReportError(f"{out} holds no finished cells ({out / 'cells'}/*.parquet)")
    spec = None
    try:
        spec = json.loads((out / "sweep.json").read_text())["spec"]
    except (OSError, ValueError, KeyError, TypeError):
        pass   # the order of conditions then follows the rows
    try:
        table = read_cells(out)
    except Exception as e:   # noqa: BLE001  a damaged or foreign file: one line
        why = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise ReportError(f"cannot read the cells in {out / 'cells'}: {why}") from None
    s = summarise(table, spec)
    write_csv(s, out / "report.csv")
    write_md(s, out / "report.md", out, len(files), spec)
    plot_errors(s, out / "errors.png")
    plot_agreement(s, out / "agreement.png")
    return s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog=f"python -m {PROG}", description=__doc__.split("\n")[0])
    ap.add_argument("dir", type=Path, help="the sweep's directory (train/sweep.py --out)")
    a = ap.parse_args(argv)
    try:
        report(a.dir)
    except ReportError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"{PROG}: error: cannot write {e.filename or a.dir}: {e.strerror or e}", file=sys.stderr)
        return 1
    print(f"wrote {a.dir}/report.md, report.csv, errors.png, agreement.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
