"""The benches are sweeps: benches/ablation.py's agent conditions run as train/sweep.py's cells (one code path), so
its figures are the sweep's report's, and its defaults are benches/ablation.toml."""

import importlib.util
import sys
from pathlib import Path

import pyarrow.compute as pc
import pytest

from train import sweep
from train.sweeps import spec as sweep_spec
from train.sweeps import store
from train.sweeps.report import summarise

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
    mine, cells = sweep_spec.resolve(ablation.sweep_doc(ablation.DEFAULT_AGENTS, plan, 0), ROOT)
    shipped, shipped_cells = sweep_spec.load_sweep(BENCHES / "ablation.toml")
    assert mine["conditions"] == shipped["conditions"] and mine["sets"] == shipped["sets"]
    assert sorted(c["id"] for c in cells) == sorted(c["id"] for c in shipped_cells) and len(cells) == len(ablation.DEFAULT_AGENTS) * 48


def test_the_benchs_rows_and_figures_are_the_sweeps(tmp_path, ablation, local_ray, capsys):
    """A few cells through the bench's path (its process pool) and through train/sweep.py on Ray: equal rows, so
    the bench's medians (train.sweeps.report.summarise of its rows) are the report's."""
    conditions = ["paper", "extended -prior"]
    plan = [("8", 2, 6, 3, 2, (2, 6)), ("life", 1, 9, 2, 1, (4, 9))]
    bench = _sorted(ablation.agent_rows(conditions, plan, 5, workers=1))
    path = tmp_path / "bench.toml"
    path.write_text(_toml(ablation.sweep_doc(conditions, plan, 5)))
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    swept = _sorted(store.read_cells(tmp_path / "out"))
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


def _bench(name: str):
    sys.path.insert(0, str(BENCHES))
    try:
        spec = importlib.util.spec_from_file_location(f"{name}_bench", BENCHES / f"{name}.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    finally:
        sys.path.remove(str(BENCHES))


def _run_bench(name: str, *flags: str) -> list[str]:
    """The bench as a script (tiny flags), under a timeout: its stdout's lines."""
    import subprocess
    r = subprocess.run([sys.executable, f"benches/{name}.py", *flags], cwd=ROOT, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout.splitlines()


def _last_line(lines: list[str]) -> dict:
    return {k: float(v) for k, v in (x.split("=") for x in lines[-1].split())}


def test_the_generalization_and_learning_curve_defaults_are_their_sweep_files():
    gen, lc = _bench("generalization"), _bench("learning_curve")
    _, shipped = sweep_spec.load_sweep(BENCHES / "generalization.toml")
    for model in ("extended", "paper"):
        _, mine = sweep_spec.resolve(gen.sweep_doc(model, 100, 30, 24, 0), ROOT)
        assert sorted(c["id"] for c in mine) == sorted(c["id"] for c in shipped
                                                       if c["spec"]["condition"]["name"] == model)
        assert len(mine) == 130
    _, shipped = sweep_spec.load_sweep(BENCHES / "learning_curve.toml")
    _, mine = sweep_spec.resolve(lc.sweep_doc("extended", 20, 230, 0, (8, 16, 32, 64, 128, 230)), ROOT)
    assert [c["id"] for c in mine] == [c["id"] for c in shipped] and len(mine) == 20


def test_a_tiny_generalization_run_prints_the_sweeps_figures(tmp_path, local_ray, capsys):
    """benches/generalization.py (1 set of 8 and 1 of 24, 2 orders, the paper model) against its cells through
    train/sweep.py on Ray: its last line is the figures worked out by hand from the sweep's rows."""
    gen = _bench("generalization")
    lines = _run_bench("generalization", "--sets", "1", "--long-sets", "1", "--orders", "2", "--first-seed", "3",
                       "--model", "paper")
    path = tmp_path / "gen.toml"
    path.write_text(_toml(gen.sweep_doc("paper", 1, 1, 2, 3)))
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    rows = store.read_cells(tmp_path / "out").to_pylist()
    assert len(rows) == 2 * 8 + 2 * 24
    got = _last_line(lines)
    for n_train, key, equal_key in ((8, "median_error_8", "sequential_equals_batch"),
                                    (24, "median_error_24", "sequential_equals_batch_24")):
        last = [r for r in rows if r["n_train"] == n_train and r["episode"] == n_train]
        assert len(last) == 2 and all(r["batch_knowledge"] for r in last)
        # two runs: the median is their mean; the share of the two orders whose final knowledge is the batch answer
        assert got[key] == float(f'{(last[0]["probe_rel_error"] + last[1]["probe_rel_error"]) / 2:.3f}')
        assert got[equal_key] == sum(r["knowledge"] == r["batch_knowledge"] for r in last) / 2
        same = float(last[0]["knowledge"] == last[1]["knowledge"])
        assert got["sets_order_independent" + ("_24" if n_train == 24 else "")] == same
    answer = next(r["batch_knowledge"] for r in rows if r["n_train"] == 8)
    assert any(f"batch answers: {answer} 1" in x for x in lines)
    # and train/report.py's CSV says the same
    from train.sweeps.report import report
    s = report(tmp_path / "out")
    assert s["errors"]["paper", "sets of 8"][8][1] == pytest.approx(got["median_error_8"], abs=5e-4)


def test_a_tiny_learning_curve_run_prints_the_sweeps_figures(tmp_path, local_ray, capsys):
    """benches/learning_curve.py (2 lives of 10 objects) against its cells through train/sweep.py on Ray: its
    figures are the ones worked out by hand from the sweep's rows."""
    lc = _bench("learning_curve")
    lines = _run_bench("learning_curve", "--sets", "2", "--objects", "10", "--first-seed", "3")
    path = tmp_path / "lc.toml"
    path.write_text(_toml(lc.sweep_doc("extended", 2, 10, 3, (8, 10))))
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    rows = store.read_cells(tmp_path / "out").to_pylist()
    assert len(rows) == 2 * 10
    got = _last_line(lines)
    for n in (8, 10):
        at = [r for r in rows if r["episode"] == n]
        assert len(at) == 2 and all(len(r["probe_errors"]) == len(r["probe_floors"]) == 16 for r in at)
        assert got[f"median_error_{n}"] == float(f'{(at[0]["probe_rel_error"] + at[1]["probe_rel_error"]) / 2:.4f}')
        row = next(x for x in lines if x.split()[:1] == [str(n)])
        over = [sum(e - f for e, f in zip(r["probe_errors"], r["probe_floors"])) / 16 for r in at]
        gross = sum(e - f > 0.02 for r in at for e, f in zip(r["probe_errors"], r["probe_floors"]))
        cols = row.split()
        assert cols[4] == f'{(at[0]["stored"] + at[1]["stored"]) / 2:.0f}'
        assert cols[5] == f'{(at[0]["recalled"] + at[1]["recalled"]) / 2:.1f}'
        assert float(cols[6]) == pytest.approx((over[0] + over[1]) / 2, abs=6e-5) and int(cols[7]) == gross
    before = {r["cell"]: r["probe_rel_error"] for r in rows if r["episode"] == 8}
    change = [r["probe_rel_error"] - before[r["cell"]] for r in rows if r["episode"] == 10]
    row10 = next(x for x in lines if x.split()[:1] == ["10"]).split()
    assert row10[8] == f"{sum(d < 0 for d in change)}/{sum(d > 0 for d in change)}"
