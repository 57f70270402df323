"""The benches are sweeps: benches/ablation.py's agent conditions run as train/sweep.py's cells (one code path), so
its figures are the sweep's report's, and its defaults are benches/ablation.toml."""

import importlib.util
import sys
from pathlib import Path

import pyarrow.compute as pc
import pytest

from train import sweep
from train.report import summarise

ROOT = Path(__file__).resolve().parents[1]
BENCHES = ROOT / "benches"


@pytest.fixture(scope="module")
def ablation():
    sys.path.insert(0, str(BENCHES))   # the bench imports its neighbours (generalization, cli_args, record)
    try:
        spec = importlib.util.spec_from_file_location("ablation_bench", BENCHES / "ablation.py")
        mod = sys.modules["ablation_bench"] = importlib.util.module_from_spec(spec)   # its pool pickles _task
        spec.loader.exec_module(mod)
        yield mod
    finally:
        sys.path.remove(str(BENCHES))
        sys.modules.pop("ablation_bench", None)


def _sorted(table):
    return table.sort_by([("cell", "ascending"), ("order", "ascending"), ("episode", "ascending")])


def _toml(doc: dict) -> str:
    """sweep_doc's dict as a sweep file (its few value types: strings, integers, booleans, lists, flat tables)."""
    def v(x):
        if isinstance(x, bool):
            return "true" if x else "false"
        if isinstance(x, str):
            return '"' + x + '"'
        if isinstance(x, list):
            return "[" + ", ".join(v(y) for y in x) + "]"
        if isinstance(x, dict):
            return "{ " + ", ".join(f"{k} = {v(y)}" for k, y in x.items()) + " }"
        return str(x)
    lines = [f'world = {v(doc["world"])}']
    for key in ("conditions", "sets"):
        for entry in doc[key]:
            lines += [f"[[{key}]]", *(f"{k} = {v(x)}" for k, x in entry.items())]
    return "\n".join(lines) + "\n"


def test_the_benchs_defaults_are_its_sweep_file(ablation):
    """benches/ablation.toml is the bench at its defaults: the same resolved spec, so the same cells."""
    plan = [("8", 30, 8, 8, 24, (8,)), ("24", 10, 24, 8, 24, (8, 24)), ("life", 8, 230, 16, 1, (8, 24, 64, 230))]
    mine, cells = sweep.resolve(ablation.sweep_doc(list(ablation.MODELS), plan, 0), ROOT)
    shipped, shipped_cells = sweep.load_sweep(BENCHES / "ablation.toml")
    assert mine["conditions"] == shipped["conditions"] and mine["sets"] == shipped["sets"]
    assert sorted(c["id"] for c in cells) == sorted(c["id"] for c in shipped_cells) and len(cells) == 6 * 48


def test_the_benchs_rows_and_figures_are_the_sweeps(tmp_path, ablation, local_ray, capsys):
    """A few cells through the bench's path (its process pool) and through train/sweep.py on Ray: equal rows, so
    the bench's medians (train.report.summarise of its rows) are the report's."""
    conditions = ["paper", "extended -prior"]
    plan = [("8", 2, 6, 3, 2, (2, 6)), ("life", 1, 9, 2, 1, (4, 9))]
    bench = _sorted(ablation.agent_rows(conditions, plan, 5, workers=1))
    path = tmp_path / "bench.toml"
    path.write_text(_toml(ablation.sweep_doc(conditions, plan, 5)))
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    swept = _sorted(sweep.read_cells(tmp_path / "out"))
    assert bench.num_rows == 2 * (2 * 2 * 6 + 9) and bench.equals(swept)
    s = summarise(swept)
    # the figures by hand from the rows: the median over (set, order) of the per-run probe error at a check
    rows = swept.filter(pc.and_(pc.equal(swept.column("condition"), "paper"), pc.equal(swept.column("episode"), 6)))
    errs = sorted(rows.filter(pc.equal(rows.column("set_group"), "sets of 8")).column("probe_rel_error").to_pylist())
    assert len(errs) == 4 and s["errors"]["paper", "sets of 8"][6][1] == pytest.approx((errs[1] + errs[2]) / 2,
                                                                                          rel=0, abs=0)
    final = [r for r in swept.to_pylist() if r["episode"] == r["n_train"] and r["condition"] == "paper"
             and r["set_group"] == "sets of 8"]
    assert ablation.final_share(swept, "paper", "sets of 8", "color", "I") == \
        sum(r["color"] == "I" for r in final) / len(final) and len(final) == 4
