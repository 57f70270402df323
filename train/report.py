"""A sweep's summary: novel-object errors with 95 % intervals, order agreement and colour's fate per condition, as
tables and plots.

    python -m train.report DIR        (from the repository's root; from anywhere: python /path/to/train/report.py DIR)

Reads the finished cells of a sweep (DIR/cells/*.parquet, train/sweep.py; a sweep still running or interrupted is
summarised as far as it got; a file that is no cell of the sweep recorded in DIR/sweep.json is named and left out)
and writes DIR/report.csv, DIR/report.md, DIR/errors.png and DIR/agreement.png (docs/sweeps.md "The report"). Every
count says what it counts: object sets (the independent unit: the 95 % intervals resample them), runs ((set, seed,
order)), cells ((set, seed)); every share and error is in %. A DIR without finished cells, or with a damaged cell
file, is refused in one line, exit code 2.
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
BOOTSTRAP = 2000          # resamples of the object sets behind each 95 % interval
BOOTSTRAP_SEED = 0        # a fixed seed, the generator made anew per figure: the same rows give the same report
BOOTSTRAP_BLOCK = 4_000_000   # values drawn at once (resamples x runs): memory stays bounded on a large sweep


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
    ci: dict = {}
    sets: dict = {}
    checked = table.filter(pc.is_valid(table.column("probe_rel_error")))
    if checked.num_rows:
        by: dict = {}   # (condition, group, episode) -> {set: [its runs' errors]}
        for c, g, ep, st, err in zip(*(checked.column(k).to_pylist() for k in ("condition", "set_group", "episode",
                                                                                "set", "probe_rel_error"))):
            by.setdefault((c, g, ep), {}).setdefault(st, []).append(err)
        for (c, g, ep), per_set in by.items():
            v = np.asarray([e for errs in per_set.values() for e in errs], dtype=np.float64)
            q25, med, q75 = np.percentile(v, [25, 50, 75])
            errors.setdefault((c, g), {})[ep] = (len(v), float(med), float(q25), float(q75))
            ci.setdefault((c, g), {})[ep] = bootstrap_median(list(per_set.values()))
            sets.setdefault((c, g), {})[ep] = len(per_set)
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
            k = knowledge.setdefault((c, g), {"cells": 0, "runs": 0, "_sets": set(), "_multi": 0, "_same": 0,
                                              "_runs": 0, "_colour_i": 0, "_weight_d": 0, "_batched": 0, "_equal": 0,
                                              "_unknown": 0})
            k["cells"] += 1
            if orders > 1:
                k["_multi"] += 1
                k["_same"] += distinct == 1
        cols = ("condition", "set_group", "cell", "set", "knowledge", "batch_knowledge", "color", "weight")
        answers: dict = {}   # (condition, group) -> {cell: its batch answer}
        for c, g, cell, st, key, batch, colour, weight in zip(*(final.column(k).to_pylist() for k in cols)):
            k = knowledge[c, g]
            k["_runs"] += 1
            k["_sets"].add(st)
            k["_unknown"] += key == "U" * len(key)
            k["_colour_i"] += colour == "I"
            k["_weight_d"] += weight == "D"
            if batch is not None:
                k["_batched"] += 1
                k["_equal"] += key == batch
                answers.setdefault((c, g), {})[cell] = batch
        for (c, g), k in knowledge.items():
            k["runs"], k["sets"] = k["_runs"], len(k["_sets"])
            # every property unknown after every run: the orders agree because nothing was learned in any of them
            k["nothing_learned"] = k["_unknown"] == k["_runs"]
            k["order_agreement"] = k["_same"] / k["_multi"] if k["_multi"] else None
            k["colour_irrelevant"] = k["_colour_i"] / k["_runs"]
            k["weight_dominant"] = k["_weight_d"] / k["_runs"]
            k["equals_batch"] = k["_equal"] / k["_batched"] if k["_batched"] else None
            # the batch answers of the cells, most common first (ties: in order of first appearance)
            k["batch_answers"] = dict(Counter(answers.get((c, g), {}).values()).most_common())
            for x in [x for x in k if x.startswith("_")]:
                del k[x]
    return {"conditions": conditions, "groups": groups, "errors": errors, "ci": ci, "sets": sets,
            "knowledge": knowledge, "checks": checks}


def bootstrap_median(per_set: list, level: float = 0.95) -> tuple[float, float] | None:
    """The `level` percentile interval of the median over runs, resampling the object sets (each set's runs
    together: a set's orders and seeds are not independent of each other), BOOTSTRAP resamples from a generator
    seeded with BOOTSTRAP_SEED. per_set: one list of run errors per set. None for fewer than 2 sets (nothing to
    resample)."""
    import numpy as np
    if len(per_set) < 2:
        return None
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    S = len(per_set)
    draws = rng.integers(0, S, size=(BOOTSTRAP, S))
    sizes = {len(v) for v in per_set}
    if len(sizes) == 1:   # every set has as many runs: one array, resampled by rows in blocks
        m = np.asarray(per_set, dtype=np.float64)                        # (S, runs)
        block = max(1, BOOTSTRAP_BLOCK // m.size)
        meds = np.concatenate([np.median(m[draws[i:i + block]].reshape(len(draws[i:i + block]), -1), axis=1)
                               for i in range(0, BOOTSTRAP, block)])
    else:
        arrays = [np.asarray(v, dtype=np.float64) for v in per_set]
        meds = np.array([np.median(np.concatenate([arrays[j] for j in row])) for row in draws])
    lo, hi = np.percentile(meds, [100 * (1 - level) / 2, 100 * (1 + level) / 2])
    return float(lo), float(hi)


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


def _pct(x, digits: int = 2) -> str:
    """A share or relative error in %, for the CSV ("" when there is none)."""
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.{digits}f}"


def _shown_pct(x, digits: int = 1) -> str:
    """The same in report.md, with its sign: '25.0 %'."""
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.{digits}f} %"


def _agreement(k: dict, digits: int = 1) -> str:
    """Order agreement in report.md: marked when the orders agree only because none learned anything."""
    text = _shown_pct(k["order_agreement"], digits)
    return f"{text} (nothing learned)" if text and k.get("nothing_learned") else text


CSV_COLUMNS = ("condition", "set_group", "episode", "sets", "runs", "error_median_pct", "error_ci95_lo_pct",
               "error_ci95_hi_pct", "error_q25_pct", "error_q75_pct", "floor_pct", "over_floor_pct",
               "probes_over_2pts", "stored", "recalled", "runs_fell", "runs_rose", "change_median_pct", "cells",
               "cell_sets", "cell_runs", "order_agreement_pct", "nothing_learned", "colour_irrelevant_pct",
               "weight_dominant_pct", "equals_batch_pct")


def write_csv(s: dict, path: Path) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for g in s["groups"]:
        for c in s["conditions"]:
            k = s["knowledge"].get((c, g))
            if k is None:
                continue
            tail = [k["cells"], k["sets"], k["runs"], _pct(k["order_agreement"]),
                    "yes" if k["nothing_learned"] else "no", _pct(k["colour_irrelevant"]), _pct(k["weight_dominant"]),
                    _pct(k["equals_batch"])]
            errs = s["errors"].get((c, g)) or {}
            if not errs:   # no probes, or no checks: the knowledge figures still have a row
                w.writerow([c, g, "", 0, 0] + [""] * 13 + tail)
            for ep, (n, med, q25, q75) in errs.items():
                f = (s.get("checks") or {}).get((c, g), {}).get(ep, {})
                ci = (s.get("ci") or {}).get((c, g), {}).get(ep) or (None, None)
                mid = [_pct(f.get("floor"), 4), _pct(f.get("over_floor"), 4), f.get("over_2pts", ""),
                       _fmt(f.get("stored"), 1), _fmt(f.get("recalled"), 3), f.get("fell", ""), f.get("rose", ""),
                       _pct(f.get("change"), 4)]
                w.writerow([c, g, ep, s["sets"][c, g][ep], n, _pct(med, 4), _pct(ci[0], 4), _pct(ci[1], 4),
                            _pct(q25, 4), _pct(q75, 4)] + mid + tail)
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
                 "figure is also in report.csv. Counts: sets = object sets (the independent unit), runs = (set, seed, "
                 "order), cells = (set, seed).")
    lines += ["", "## Novel-object error", "",
              "probe_rel_error: |predicted - Archimedes| / Archimedes, the median over a run's probes (nothing "
              f"recalled counts as 100 %); here the median over the runs after each number of episodes and, in "
              f"brackets, its 95 % interval: {BOOTSTRAP:,} resamples of the object sets (each set with all its runs; "
              "none for a single set). The 25-75 % range over the runs is in report.csv.", ""]
    any_err = False
    for g in s["groups"]:
        eps = sorted({e for c in s["conditions"] for e in (s["errors"].get((c, g)) or {})})
        if not eps:
            continue
        any_err = True
        shown = _shown(eps)
        lines += [f"### {g}", "", "| condition | sets | runs | " + " | ".join(
            f"after {e} episode{'s' if e != 1 else ''}" for e in shown) + " |", "| --- | --- | --- |" +
            " --- |" * len(shown)]
        for c in s["conditions"]:
            errs = s["errors"].get((c, g))
            if not errs:
                continue
            last = max(errs)
            cis = s["ci"].get((c, g), {})
            cells = [(f"{_shown_pct(errs[e][1])} [{100 * cis[e][0]:.1f}-{100 * cis[e][1]:.1f}]" if cis.get(e) else
                      _shown_pct(errs[e][1])) if e in errs else "" for e in shown]
            lines.append(f"| {c} | {s['sets'][c, g][last]} | {errs[last][0]} | " + " | ".join(cells) + " |")
        if len(shown) < len(eps):
            lines += ["", f"{len(shown)} of {len(eps)} episode counts shown; all in report.csv."]
        lines.append("")
    if not any_err:
        lines += ["No probe errors were recorded (no probes, or no checks).", ""]
    floors = [(g, c) for g in s["groups"] for c in s["conditions"] if (s.get("checks") or {}).get((c, g))]
    if floors:
        lines += ["## Memory and the senses' floor", "",
                  "per number of episodes with probe errors, medians over the runs: episodes stored, episodes recalled "
                  "per probe cue, the senses' floor (Archimedes on the probes as measured), the mean over probes of "
                  "the error less each probe's floor (percentage points); probes more than 2 points above their floor "
                  "(summed over runs); runs whose error fell / rose since the previous count, and the median change "
                  "(points).", "", "| condition | set group | episodes | runs | stored | recalled | floor | over floor "
                  "| probes > 2 pts | runs fell/rose | median change |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for g, c in floors:
            for ep in _shown(list(s["checks"][c, g])):
                f = s["checks"][c, g][ep]
                moved = f"{f['fell']}/{f['rose']}" if "fell" in f else ""
                change = f"{100 * f['change']:+.2f}" if f.get("change") is not None else ""
                lines.append(f"| {c} | {g} | {ep} | {s['errors'][c, g][ep][0]} | {f['stored']:.0f} | "
                             f"{f['recalled']:.1f} | {_shown_pct(f['floor'], 2)} | {100 * f['over_floor']:+.2f} | "
                             f"{f['over_2pts']} | {moved} | {change} |")
        lines.append("")
    lines += ["## Knowledge after the last episode", "",
              "same in every order: the share of cells whose final knowledge key is the same in all its orders "
              "(empty: one order per cell; \"nothing learned\": every property is still unknown after every run, so "
              "the orders agree on nothing); colour irrelevant, weight dominant: the share of runs whose final colour "
              "state is I, whose weight state is D; equals the batch answer: the share of runs whose final knowledge "
              "is the set's batch answer (every pair of its episodes compared at once); batch answers: per cell, most "
              "common first.", "",
              "| condition | set group | sets | cells | runs | same in every order | colour irrelevant | "
              "weight dominant | equals the batch answer | batch answers |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for g in s["groups"]:
        for c in s["conditions"]:
            k = s["knowledge"].get((c, g))
            if k:
                answers = ", ".join(f"{a} {n}" for a, n in list(k["batch_answers"].items())[:6])
                lines.append(f"| {c} | {g} | {k['sets']} | {k['cells']} | {k['runs']} | {_agreement(k)} | "
                             f"{_shown_pct(k['colour_irrelevant'])} | {_shown_pct(k['weight_dominant'])} | "
                             f"{_shown_pct(k['equals_batch'])} | {answers} |")
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
            med = [100 * errs[e][1] for e in ep]
            col = colours[i % len(colours)]
            ax.plot(ep, med, "-o", color=col, markersize=3, label=c)
            cis = s["ci"].get((c, g), {})
            band = [e for e in ep if cis.get(e)]
            if band:
                ax.fill_between(band, [100 * cis[e][0] for e in band], [100 * cis[e][1] for e in band], color=col,
                                alpha=0.18, linewidth=0)
            drawn = True
        ax.set_title(g, fontsize=10)
        ax.set_xlabel("episodes (objects explored)")
        ax.set_ylabel("novel-object error, % (median, 95 % interval)")
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
    for ax, key, title in ((axes[0], "order_agreement", "same knowledge in every order (% of cells)"),
                           (axes[1], "colour_irrelevant", "colour ends irrelevant (% of runs)")):
        for j, g in enumerate(groups):
            ks = [s["knowledge"].get((c, g)) or {} for c in conds]
            vals = [k.get(key) for k in ks]
            bars = ax.bar(x + (j - (len(groups) - 1) / 2) * width, [np.nan if v is None else 100 * v for v in vals],
                          width, label=g)
            labels = ["n/a" if v is None else f"{100 * v:.0f} %" + (
                "\n(nothing\nlearned)" if key == "order_agreement" and k.get("nothing_learned") else "")
                for v, k in zip(vals, ks)]
            ax.bar_label(bars, labels=labels, fontsize=7)
        ax.set_xticks(x, conds, rotation=30, ha="right", fontsize=8)
        ax.set_ylim(0, 125)
        ax.set_ylabel("%")
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


def report(out: Path, warn=None) -> dict:
    """Write DIR's report.md, report.csv, errors.png and agreement.png; returns the figures (summarise). warn(line):
    told of each file in DIR/cells that is no cell of the sweep (left out)."""
    from train.sweep import check_cell_file, read_cells
    out = Path(out)
    if not out.is_dir():
        raise ReportError(f"{out} is not a directory")
    spec, ids = None, None
    recorded = out / "sweep.json"
    if recorded.exists() or recorded.is_symlink():   # a regular file of bounded size: not /dev/zero, not a FIFO
        from train.sweep import MAX_RECORD_BYTES, SweepError, read_bounded
        try:
            raw = read_bounded(recorded, MAX_RECORD_BYTES, "a sweep record")
        except SweepError as e:
            raise ReportError(str(e)) from None
        try:
            record = json.loads(raw)
            spec = record["spec"]
            ids = set(record["cells"]) if isinstance(record.get("cells"), list) else None
        except (ValueError, KeyError, TypeError, RecursionError):
            pass   # the order of conditions then follows the rows, and every file counts
    files = sorted((out / "cells").glob("*.parquet"))
    if ids is not None:
        for f in files:
            if f.stem not in ids and warn is not None:
                warn(f"{f} is no cell of the sweep in {out / 'sweep.json'}: left out")
        files = [f for f in files if f.stem in ids]
    if not files:
        raise ReportError(f"{out} holds no finished cells ({out / 'cells'}/*.parquet)")
    for f in files:   # a damaged or renamed file would count a cell twice, or another's rows as its own
        if why := check_cell_file(f):
            raise ReportError(f"{f}: {why}; `python train/sweep.py SWEEP.toml --out {out} --resume` runs its cell "
                              f"again")
    try:
        table = read_cells(out, [f.stem for f in files])
    except Exception as e:   # noqa: BLE001  a file changed under the report: one line
        why = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise ReportError(f"cannot read the cells in {out / 'cells'}: {why}") from None
    s = summarise(table, spec)
    write_csv(s, out / "report.csv")
    write_md(s, out / "report.md", out, len(files), spec)
    plot_errors(s, out / "errors.png")
    plot_agreement(s, out / "agreement.png")
    return s


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints usage + message; one line is enough
        raise ReportError(message)


def main(argv=None) -> int:
    """The command line (and the aesop-report console script): 0 written, 2 bad input, 1 a write that failed."""
    ap = _Parser(prog=f"python -m {PROG}", description=__doc__.split("\n")[0])
    ap.add_argument("dir", type=Path, help="the sweep's directory (train/sweep.py --out)")
    try:
        a = ap.parse_args(sys.argv[1:] if argv is None else argv)
        report(a.dir, warn=lambda line: print(f"{PROG}: {line}", file=sys.stderr))
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
