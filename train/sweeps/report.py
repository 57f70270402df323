"""A sweep's summary: novel-object errors with their intervals, order agreement and colour's fate per condition,
as tables and plots, under the code, libraries, dates and command lines that made the rows.

Reads the finished cells of a sweep (DIR/cells/*.parquet, train/sweep.py; a sweep still running or interrupted is
summarised as far as it got; a file that is no cell of the sweep recorded in DIR/sweep.json is named and left out)
and writes DIR/report.csv, DIR/report.md, DIR/errors.png and DIR/agreement.png (docs/sweeps.md "The report"). Every
count says what it counts: object sets (the independent unit: the intervals resample them), runs ((set, seed,
order)), cells ((set, seed)); every share and error is in %. A 95 % interval needs MIN_SETS object sets: over fewer,
a bootstrap has too few distinct resamples to be one, and the report says "n too small" instead. A DIR without
finished cells, or with a damaged cell file (unreadable, renamed, or a value out of range), is refused in one line.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections import Counter
from pathlib import Path

from train.sweeps.report_plots import plot_agreement, plot_errors

MD_CHECKS = 12   # episode counts shown per set group in report.md
BOOTSTRAP = 2000          # resamples of the object sets behind each 95 % interval
BOOTSTRAP_SEED = 0        # a fixed seed, the generator made anew per figure: the same rows give the same report
BOOTSTRAP_BLOCK = 4_000_000   # values drawn at once (resamples x runs): memory stays bounded on a large sweep
MIN_SETS = 10   # object sets behind a printed 95 % interval: 3 sets have 10 distinct resamples, and their 2.5 and
                # 97.5 percentiles are close to the min and max; 10 sets have 92,378


class ReportError(Exception):
    """One line on stderr, exit code 2."""


def _order(values, preferred: list) -> list:
    """The distinct values, those of `preferred` first in its order, the rest in order of appearance."""
    seen = list(dict.fromkeys(values))
    return [v for v in preferred if v in seen] + [v for v in seen if v not in preferred]


def summarise(table, spec: dict | None = None) -> dict:
    """The report's figures from a sweep's rows (a pyarrow Table of train.sweeps.cell.schema()). spec: the sweep's
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
            # a 95 % interval over MIN_SETS sets or more; None (n too small) over fewer
            ci.setdefault((c, g), {})[ep] = bootstrap_median(list(per_set.values())) if len(per_set) >= MIN_SETS \
                else None
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
               "error_ci95_hi_pct", "error_ci95_note", "error_q25_pct", "error_q75_pct", "floor_pct", "over_floor_pct",
               "probes_over_2pts", "stored", "recalled", "runs_fell", "runs_rose", "change_median_pct", "cells",
               "cell_sets", "cell_runs", "order_agreement_pct", "nothing_learned", "colour_irrelevant_pct",
               "weight_dominant_pct", "equals_batch_pct")


def too_few(sets: int) -> str:
    """What stands in a 95 % interval's place over fewer than MIN_SETS object sets."""
    return f"n too small: {sets} set{'s' if sets != 1 else ''} (a 95 % interval needs {MIN_SETS})"


def write_csv(s: dict, path: Path, about: list[str]) -> None:
    """report.csv: `about` (provenance_lines) as '# ' lines, then the header and the rows."""
    buf = io.StringIO()
    buf.writelines(f"# {line}\n" for line in about)
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
                w.writerow([c, g, "", 0, 0] + [""] * 14 + tail)
            for ep, (n, med, q25, q75) in errs.items():
                f = (s.get("checks") or {}).get((c, g), {}).get(ep, {})
                ci = (s.get("ci") or {}).get((c, g), {}).get(ep) or (None, None)
                mid = [_pct(f.get("floor"), 4), _pct(f.get("over_floor"), 4), f.get("over_2pts", ""),
                       _fmt(f.get("stored"), 1), _fmt(f.get("recalled"), 3), f.get("fell", ""), f.get("rose", ""),
                       _pct(f.get("change"), 4)]
                sets = s["sets"][c, g][ep]
                note = too_few(sets) if sets < MIN_SETS else ""
                w.writerow([c, g, ep, sets, n, _pct(med, 4), _pct(ci[0], 4), _pct(ci[1], 4), note,
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


def write_md(s: dict, path: Path, out: Path, n_cells: int, spec: dict | None, about: list[str]) -> None:
    """report.md: `about` (provenance_lines) first, then the tables."""
    lines = [f"# Sweep report: {out}", "", *(f"- {line}" for line in about), ""]
    total = None
    if spec:
        total = len(spec["conditions"]) * sum(len(o["seeds"]) for st in spec["sets"] for o in st["objects"])
    lines.append(f"{n_cells} cell(s)" + (f" of {total}" if total is not None else "") + " finished"
                 + (f"; world {spec['world']}" if spec else "") + ". Written by `aesop-report` (python -m train.report); "
                 "every "
                 "figure is also in report.csv. Counts: sets = object sets (the independent unit), runs = (set, seed, "
                 "order), cells = (set, seed).")
    lines += ["", "## Novel-object error", "",
              "probe_rel_error: |predicted - Archimedes| / Archimedes, the median over a run's probes (nothing "
              f"recalled counts as 100 %); here the median over the runs after each number of episodes and, in "
              f"brackets, its 95 % interval: {BOOTSTRAP:,} resamples of the object sets (each set with all its runs), "
              f"printed over {MIN_SETS} sets or more; over fewer, \"n too small\" stands in its place (a bootstrap of "
              "3 sets has 10 distinct resamples: its percentiles would be near the min and max, not an interval). The "
              "25-75 % range over the runs is in report.csv.", ""]
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
            sets = s["sets"][c, g]
            cells = [(f"{_shown_pct(errs[e][1])} [{100 * cis[e][0]:.1f}-{100 * cis[e][1]:.1f}]" if cis.get(e) else
                      f"{_shown_pct(errs[e][1])} ({too_few(sets[e]).split(' (')[0]})") if e in errs else ""
                     for e in shown]
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


def _write(path: Path, text: str) -> None:
    from sim.output_files import write_atomic
    write_atomic(path, text.encode())


def provenance_lines(table, files: list[Path], record: dict | None) -> list[str]:
    """What made the rows, for the top of report.md and report.csv: the commit (every commit, with its cells, and a
    warning when there is more than one or one is a dirty tree's), the libraries' versions (the workers', from each
    cell file; else the driver's, from DIR/sweep.json), the dates (the first cell's start to the last one's end)
    and each run's command line (DIR/sweep.json). From the rows and DIR alone: the same DIR, the same lines."""
    from train.sweeps.provenance import LIBRARIES, names_its_code
    from train.sweeps.store import cell_info
    per_cell = dict(zip(*(table.column(k).to_pylist() for k in ("cell", "commit"))))
    commits = Counter(per_cell.values()).most_common()
    shown = ", ".join(f"{c} ({n} cell{'s' if n != 1 else ''})" for c, n in commits)
    lines = [f"commit: {commits[0][0]}" if len(commits) == 1 else
             f"commits: MIXED CODE, {len(commits)} commits: {shown}"]
    if len(commits) > 1:
        lines.append("the cells were not all computed by the same code (--resume --allow-mixed-commits): compare "
                     "conditions only within one commit's cells (the rows' commit column)")
    elif not names_its_code(commits[0][0]):
        lines.append("the commit does not name the code: the cells were written from a tree with uncommitted "
                     "changes (-dirty) or outside git")
    infos = [cell_info(f) for f in files]
    runs = [r for r in (record or {}).get("runs", []) if isinstance(r, dict)]
    found = [i["versions"] for i in infos if isinstance(i.get("versions"), dict)] or \
        [r["versions"] for r in runs if isinstance(r.get("versions"), dict)]
    distinct = list(dict.fromkeys(json.dumps(v, sort_keys=True) for v in found))
    order = ("python", *LIBRARIES)   # Python first, then the libraries as provenance lists them
    shown_v = ["; ".join(", ".join(f"{k} {v[k]}" for k in sorted(v, key=lambda k: (k not in order, order.index(k)
                                                                                   if k in order else 0, k)))
                         for v in map(json.loads, distinct))]
    lines.append(("versions: " if len(distinct) == 1 else f"versions ({len(distinct)} sets): ") + shown_v[0]
                 if distinct else "versions: not recorded (the cell files hold no provenance, DIR no sweep.json)")
    starts = [i["started"] for i in infos if isinstance(i.get("started"), str)]
    ends = [i["ended"] for i in infos if isinstance(i.get("ended"), str)]
    if not starts:
        starts = [r["started"] for r in runs if isinstance(r.get("started"), str)]
        ends = [r["ended"] for r in runs if isinstance(r.get("ended"), str)]
    lines.append(f"date: {min(starts)} to {max(ends or starts)} (UTC, the cells' first start to last end)" if starts
                 else "date: not recorded")
    commands = list(dict.fromkeys(r["command"] for r in runs if isinstance(r.get("command"), str)))
    lines.append(("command: " + " ; then ".join(f"`{c}`" for c in commands)) if commands else
                 "command: not recorded (DIR/sweep.json holds none)")
    return [_printable(line) for line in lines]


def _printable(text: str) -> str:
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def report(out: Path, warn=None) -> dict:
    """Write DIR's report.md, report.csv, errors.png and agreement.png; returns the figures (summarise). warn(line):
    told of each file in DIR/cells that is no cell of the sweep (left out). ReportError (one line) for a DIR it
    cannot summarise."""
    from train.sweeps.spec import SweepError, read_bounded
    from train.sweeps.store import (
        MAX_RECORD_BYTES,
        check_cell_file,
        needs_pyarrow,
        read_cells,
    )
    out = Path(out)
    if not out.is_dir():
        raise ReportError(f"{out} is not a directory")
    try:
        needs_pyarrow()
    except SweepError as e:
        raise ReportError(str(e)) from None
    spec, ids, record = None, None, None
    recorded = out / "sweep.json"
    if recorded.exists() or recorded.is_symlink():   # a regular file of bounded size: not /dev/zero, not a FIFO
        try:
            raw = read_bounded(recorded, MAX_RECORD_BYTES, "a sweep record")
        except SweepError as e:
            raise ReportError(str(e)) from None
        try:
            record = json.loads(raw)
            spec = record["spec"]
            ids = set(record["cells"]) if isinstance(record.get("cells"), list) else None
        except (ValueError, KeyError, TypeError, RecursionError):
            record = None   # the order of conditions then follows the rows, and every file counts
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
        about = provenance_lines(table, files, record if isinstance(record, dict) else None)
    except Exception as e:   # noqa: BLE001  a file changed under the report: one line
        why = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise ReportError(f"cannot read the cells in {out / 'cells'}: {why}") from None
    s = summarise(table, spec)
    write_csv(s, out / "report.csv", about)
    write_md(s, out / "report.md", out, len(files), spec, about)
    plot_errors(s, out / "errors.png")
    plot_agreement(s, out / "agreement.png")
    return s
