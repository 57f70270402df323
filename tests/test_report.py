"""train/report.py: its 95 % intervals resample object sets (not runs), the same rows give the same report, every
count is named, a condition that learned nothing is marked, and it runs from any directory."""

import shutil
import subprocess
import sys
from pathlib import Path

import pyarrow as pa
import pytest

from train import report as report_mod
from train.sweeps import cell as sweep_cell
from train.sweeps import report as sweeps_report
from train.sweeps import store

ROOT = Path(__file__).resolve().parents[1]


def test_the_interval_resamples_object_sets_not_runs():
    """One set of a single run at 10 %, one of nine runs at 50 %: drawing the first set twice (a quarter of the
    resamples) gives a median of 10 %, so the interval reaches down to it. Resampling the ten runs instead would
    need five or more draws of the one 10 % run (0.16 % of the time): its interval would be 50-50 %."""
    assert sweeps_report.bootstrap_median([[0.1], [0.5] * 9]) == (0.1, 0.5)
    assert sweeps_report.bootstrap_median([[0.1, 0.2], [0.3, 0.4]]) == pytest.approx((0.15, 0.35))
    assert sweeps_report.bootstrap_median([[0.1, 0.2, 0.3]]) is None   # one set: nothing to resample
    # sets of unequal size take the general path; the fixed seed gives the same interval every time
    uneven = [[0.1, 0.3], [0.2], [0.6, 0.7, 0.9], [0.4]]
    lo, hi = sweeps_report.bootstrap_median(uneven)
    assert 0.1 <= lo < hi <= 0.9 and sweeps_report.bootstrap_median(uneven) == (lo, hi)


def _rows(cond: str, n_sets: int, finals: str, errs):
    """A condition's rows: n_sets cells of one seed, 2 orders x 2 episodes, probe errors at episode 2."""
    rows = []
    for c in range(n_sets):
        for o in range(2):
            for ep in (1, 2):
                k = finals if ep == 2 else "UUUU"
                rows.append({"cell": f"{cond}{c}".ljust(16, "0"), "condition": cond, "model": "paper", "ablate": "",
                             "overrides": "{}", "config": "0" * 16, "commit": "abc1234", "world": "closed_form", "set_group": "g",
                             "set": str(c), "generator_seed": c, "seed": c, "n_train": 2, "n_probe": 3, "n_orders": 2,
                             "order": o, "episode": ep, "object": f"t{ep}", "predicted_cm3": None,
                             "observed_cm3": 1.0, "archimedes_cm3": 1.0, "sank": False, "goal_reached": False,
                             "rules": "SSSS", "knowledge": k, "color": k[0], "shape": k[1], "size": k[2],
                             "weight": k[3], "stored": ep, "probe_rel_error": errs[2 * c + o] if ep == 2 else None})
    return rows


@pytest.fixture
def swept(tmp_path):
    """A DIR of hand-made cells: 'learns' (2 sets) and 'idle' (3 sets, every property unknown in every run)."""
    rows = _rows("learns", 2, "IUUD", [0.1, 0.2, 0.3, 0.4]) + _rows("idle", 3, "UUUU", [1.0] * 6)
    table = pa.Table.from_pylist(rows, schema=sweep_cell.schema())
    (tmp_path / "cells").mkdir()
    for cell in sorted({r["cell"] for r in rows}):
        store.write_cell(tmp_path, cell, table.filter(pa.compute.equal(table.column("cell"), cell)))
    return tmp_path


def test_the_same_rows_give_the_same_report_with_every_count_named(swept):
    assert report_mod.main([str(swept)]) == 0
    first = {f: (swept / f).read_bytes() for f in ("report.csv", "report.md")}
    assert report_mod.main([str(swept)]) == 0
    assert {f: (swept / f).read_bytes() for f in first} == first
    lines = first["report.csv"].decode().splitlines()
    # the rows' provenance first: one commit; these hand-made cells carry no versions or dates, DIR no sweep.json
    assert lines[:4] == ["# commit: abc1234",
                         "# versions: not recorded (the cell files hold no provenance, DIR no sweep.json)",
                         "# date: not recorded", "# command: not recorded (DIR/sweep.json holds none)"]
    csv = lines[4:]
    header = csv[0].split(",")
    assert "n" not in header and header[3:5] == ["sets", "runs"]
    assert all(h in ("condition", "set_group", "episode", "sets", "runs", "probes_over_2pts", "stored", "recalled",
                     "runs_fell", "runs_rose", "cells", "cell_sets", "cell_runs", "nothing_learned", "error_ci95_note")
               or h.endswith("_pct") for h in header)
    by = {line.split(",")[0]: dict(zip(header, line.split(","))) for line in csv[1:]}   # no spec: in file order
    assert list(by) == ["idle", "learns"]
    row = by["learns"]
    assert [row[k] for k in ("condition", "sets", "runs", "cells", "cell_runs")] == ["learns", "2", "4", "2", "4"]
    idle = by["idle"]
    assert (idle["sets"], idle["runs"], idle["order_agreement_pct"], idle["nothing_learned"]) == ("3", "6", "100.00",
                                                                                                 "yes")
    # 3 sets: no 95 % interval, and the row says why
    assert idle["error_ci95_lo_pct"] == idle["error_ci95_hi_pct"] == ""
    assert idle["error_ci95_note"] == "n too small: 3 sets (a 95 % interval needs 10)"
    md = first["report.md"].decode()
    assert "n =" not in md and "| condition | sets | runs | after 2 episodes |" in md
    assert md.startswith("# Sweep report: " + str(swept) + "\n\n- commit: abc1234\n- versions: not recorded")
    assert "| idle | 3 | 6 | 100.0 % (n too small: 3 sets) |" in md
    assert "| idle | g | 3 | 3 | 6 | 100.0 % (nothing learned) |" in md
    assert "| learns | g | 2 | 2 | 4 | 100.0 % | 100.0 % |" in md    # learned, and agreed: not marked


def test_the_report_runs_from_any_directory_and_refuses_in_one_line(swept, tmp_path_factory):
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    r = subprocess.run([sys.executable, str(ROOT / "train" / "report.py"), str(swept)], cwd=elsewhere,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert r.stdout == f"wrote {swept}/report.md, report.csv, errors.png, agreement.png\n"
    for args, words in (([], "the following arguments are required: dir"), ([str(swept), "extra"],
                                                                           "unrecognized arguments: extra")):
        r = subprocess.run([sys.executable, str(ROOT / "train" / "report.py"), *args], cwd=elsewhere,
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and r.stderr.splitlines() == [f"train.report: error: {words}"], r.stderr


def test_a_swapped_cell_file_is_refused_and_a_foreign_one_left_out(swept, capsys):
    (swept / "sweep.json").write_text('{"spec": {"conditions": [], "sets": [], "world": "closed_form"}, "cells": '
                                      + str([p.stem for p in (swept / "cells").glob("*.parquet")]).replace("'", '"')
                                      + "}")
    shutil.copyfile(swept / "cells" / "idle000000000000.parquet", swept / "cells" / "0123456789abcdef.parquet")
    assert report_mod.main([str(swept)]) == 0
    assert capsys.readouterr().err.splitlines() == [
        f"train.report: {swept / 'cells' / '0123456789abcdef.parquet'} is no cell of the sweep in "
        f"{swept / 'sweep.json'}: left out"]
    assert "5 cell(s) of 0 finished" in (swept / "report.md").read_text()   # the 5 of its record, not 6
    shutil.copyfile(swept / "cells" / "idle000000000000.parquet", swept / "cells" / "idle100000000000.parquet")
    assert report_mod.main([str(swept)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == (f"train.report: error: {swept / 'cells' / 'idle100000000000.parquet'}: holds the rows of "
                       f"cell idle000000000000, not idle100000000000 (renamed?); `python train/sweep.py SWEEP.toml "
                       f"--out {swept} --resume` runs its cell again")


@pytest.mark.timeout(60)
def test_a_sweep_record_that_is_a_fifo_is_refused_at_once(swept, capsys):
    import os
    os.mkfifo(swept / "sweep.json")
    assert report_mod.main([str(swept)]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"train.report: error: {swept / 'sweep.json'}: is a FIFO (named pipe), not a sweep record (a regular file)"]


@pytest.mark.parametrize("n_sets, shown", [(9, "20.0 % (n too small: 9 sets)"), (10, "20.0 % [20.0-20.0]")])
def test_a_95_percent_interval_is_printed_over_ten_object_sets_or_more(tmp_path, n_sets, shown):
    """Every run at 20 %: any resample's median is 20 %, so the interval over 10 sets is [20.0-20.0]; over 9 it is
    not printed, and the CSV says why in its place."""
    rows = _rows("c", n_sets, "IUUD", [0.2] * (2 * n_sets))
    for r in rows:   # one cell per set ("c1" and "c10" padded alike would collide)
        r["cell"] = f"c{int(r['set']):015d}"
    table = pa.Table.from_pylist(rows, schema=sweep_cell.schema())
    (tmp_path / "cells").mkdir()
    for cid in sorted({r["cell"] for r in rows}):
        store.write_cell(tmp_path, cid, table.filter(pa.compute.equal(table.column("cell"), cid)))
    assert report_mod.main([str(tmp_path)]) == 0
    assert f"| c | {n_sets} | {2 * n_sets} | {shown} |" in (tmp_path / "report.md").read_text()
    lines = (tmp_path / "report.csv").read_text().splitlines()
    row = dict(zip(lines[4].split(","), lines[5].split(",")))
    assert (row["error_ci95_lo_pct"], row["error_ci95_hi_pct"], row["error_ci95_note"]) == (
        ("", "", "n too small: 9 sets (a 95 % interval needs 10)") if n_sets == 9 else ("20.0000", "20.0000", ""))


def test_the_help_is_whole_and_names_the_command_typed(capsys):
    from aesop_torch import cli
    with pytest.raises(SystemExit) as e:
        cli.report(["--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith("usage: aesop-report [-h] dir\n")
    flat = " ".join(text.split())
    assert ("A sweep's summary: novel-object errors with their 95 % intervals (or \"n too small\" over fewer than 10 "
            "object sets), order agreement and colour's fate per condition, as tables and plots, headed by the "
            "commit, versions, dates and command lines that made the rows.") in flat
    with pytest.raises(SystemExit):
        report_mod.main(["--help"])
    assert capsys.readouterr().out.startswith("usage: python -m train.report [-h] dir\n")
