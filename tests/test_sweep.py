"""train/sweep.py and train/report.py: a sweep on Ray gives the rows its cells give in-process, an interrupted sweep
resumes to the same table, a bad sweep file is refused in one line, and the report's figures are the table's.
One local Ray instance (2 CPUs, tests/conftest.py local_ray) serves the whole module."""

import json
import subprocess
import sys
from pathlib import Path

import pyarrow as pa
import pytest

from train import report as report_mod
from train import sweep
from train.common import models
from train.sweeps import cell as sweep_cell
from train.sweeps import provenance, store
from train.sweeps import spec as sweep_spec

ROOT = Path(__file__).resolve().parents[1]
CLEAN = "0123abc"   # the commit the tests' cells are written at (clean_commit)

TINY = """
description = "2 conditions x 2 generated sets of 4 objects x 2 orders"
[[conditions]]
name = "paper"
model = "paper"

[[conditions]]
name = "extended -prior"
model = "extended"
ablate = ["prior"]

[[sets]]
name = "fours"
generate = { seeds = [5, 7], train = 4, probe = 3, pairs = false }
orders = 2
checks = [1, 3, 4]
"""


@pytest.fixture(autouse=True)
def clean_commit(monkeypatch):
    """This checkout taken for a clean commit, CLEAN: a developer's uncommitted changes would make every --resume
    here refuse (that refusal has its own tests, which give the commits)."""
    monkeypatch.setattr(provenance, "commit", lambda: CLEAN)


def _write(tmp_path: Path, text: str, name: str = "sweep.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _sorted(table):
    return table.sort_by([("cell", "ascending"), ("order", "ascending"), ("episode", "ascending")])


def _direct(path: Path):
    """The sweep's cells run here, in this process, without Ray."""
    _, cells = sweep_spec.load_sweep(path)
    return _sorted(pa.concat_tables([sweep_cell.run_cell(c["spec"], c["objects"]) for c in cells]))


def test_a_sweep_on_ray_gives_the_rows_of_its_cells_run_in_process(tmp_path, local_ray, capsys):
    path = _write(tmp_path, TINY)
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 0
    out = tmp_path / "out"
    files = sorted((out / "cells").glob("*"))
    assert len(files) == 4 and all(f.suffix == ".parquet" for f in files)   # no temporary file left
    got = _sorted(store.read_cells(out))
    assert got.schema == sweep_cell.schema()
    assert got.num_rows == 2 * 2 * 2 * 4                                  # conditions x sets x orders x episodes
    assert got.equals(_direct(path))                                     # bit for bit
    rows = got.to_pylist()
    assert {r["condition"] for r in rows} == {"paper", "extended -prior"}
    assert {r["set"] for r in rows} == {"5", "6"} and {r["seed"] for r in rows} == {5, 6}
    assert {r["ablate"] for r in rows} == {"", "prior"}
    checked = [r for r in rows if r["probe_rel_error"] is not None]
    assert {r["episode"] for r in checked} == {1, 3, 4} and len(checked) == 2 * 2 * 2 * 3
    assert all(len(r["knowledge"]) == 4 and set(r["knowledge"]) <= set("ULDI") for r in rows)
    assert all(r["knowledge"] == r["color"] + r["shape"] + r["size"] + r["weight"] for r in rows)
    assert all(r["predicted_cm3"] is None for r in rows if r["episode"] == 1)   # nothing to recall yet
    recorded = json.loads((out / "sweep.json").read_text())
    assert recorded["spec"]["conditions"][1]["ablate"] == ["prior"]
    # a finished sweep resumed runs nothing, and says so
    capsys.readouterr()
    assert sweep.main([str(path), "--out", str(out), "--resume"]) == 0
    assert "4 on disk, 0 to run" in capsys.readouterr().out
    # every row names the code that made it; the report starts with it, the versions, the dates and the commands
    assert set(got.column("commit").to_pylist()) == {CLEAN}
    assert report_mod.main([str(out)]) == 0
    runs = json.loads((out / "sweep.json").read_text())["runs"]
    info = [store.cell_info(f) for f in files]
    versions = ", ".join(f"{k} {info[0]['versions'][k]}" for k in ("python", "torch", "numpy", "pybullet", "pyarrow",
                                                                     "ray"))
    about = [f"commit: {CLEAN}", f"versions: {versions}",
             f"date: {min(i['started'] for i in info)} to {max(i['ended'] for i in info)} (UTC, the cells' first start "
             f"to last end)",
             f"command: `train/sweep.py {path} --out {out}` ; then `train/sweep.py {path} --out {out} --resume`"]
    assert [r["command"] for r in runs] == [f"train/sweep.py {path} --out {out}",
                                           f"train/sweep.py {path} --out {out} --resume"]
    assert (out / "report.csv").read_text().splitlines()[:4] == [f"# {line}" for line in about]
    assert (out / "report.md").read_text().splitlines()[2:6] == [f"- {line}" for line in about]
    assert versions.startswith(f"python {sys.version.split()[0]}, torch ")


def test_an_interrupted_sweep_resumes_to_the_same_table(tmp_path, local_ray, capsys):
    path = _write(tmp_path, TINY)
    out = tmp_path / "out"

    def ctrl_c_after_two(cell, seen=[]):
        seen.append(cell)
        if len(seen) == 2:
            raise KeyboardInterrupt

    assert sweep.main([str(path), "--out", str(out)], on_cell=ctrl_c_after_two) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == f"train/sweep.py: interrupted: 2 of 4 cell(s) on disk in {out / 'cells'} (--resume runs the rest)"
    first = {p.name: p.stat().st_mtime_ns for p in (out / "cells").glob("*.parquet")}
    assert len(first) == 2
    # a new sweep into the same DIR is refused; so is a resume with another spec
    assert sweep.main([str(path), "--out", str(out)]) == 2
    other = _write(tmp_path, TINY.replace("orders = 2", "orders = 3"), "other.toml")
    assert sweep.main([str(other), "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "already holds files" in err[0]
    assert err[1].endswith("holds another sweep (sets[0].orders differs); give another --out")
    assert sweep.main([str(path), "--out", str(out), "--resume"]) == 0
    assert "2 on disk, 2 to run" in capsys.readouterr().out
    assert {p.name: p.stat().st_mtime_ns for p in (out / "cells").glob("*.parquet") if p.name in first} == first
    assert _sorted(store.read_cells(out)).equals(_direct(path))


def test_ctrl_c_ends_a_sweep_in_one_line_with_its_finished_cells_on_disk(tmp_path):
    """A real SIGINT to the sweep's process group, as a terminal's Ctrl-C sends it, while Ray runs cells."""
    import os
    import signal
    import time
    path = _write(tmp_path, TINY.replace("seeds = [5, 7]", "seeds = [5, 45]"))
    out = tmp_path / "out"
    p = subprocess.Popen([sys.executable, "train/sweep.py", str(path), "--out", str(out), "--workers", "2"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 90
        while not list((out / "cells").glob("*.parquet")) and time.monotonic() < deadline and p.poll() is None:
            time.sleep(0.05)
        os.killpg(p.pid, signal.SIGINT)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    done = list((out / "cells").glob("*.parquet"))
    assert p.returncode == 130, stderr
    assert stderr.strip().splitlines()[-1] == (f"train/sweep.py: interrupted: {len(done)} of 80 cell(s) on disk in "
                                               f"{out / 'cells'} (--resume runs the rest)")
    assert 1 <= len(done) < 80 and "Traceback" not in stderr
    assert sorted(p.name for p in (out / "cells").iterdir()) == sorted(p.name for p in done)   # no half file
    assert store.read_cells(out).num_rows == len(done) * 2 * 4


BAD = {
    "malformed TOML": ("[[conditions]\nname = 1", "malformed TOML"),
    "an unknown key": (TINY.replace('model = "paper"', 'modle = "paper"'), "unknown key 'modle'"),
    "a wrong type": (TINY.replace("train = 4", 'train = "4"'), "generate.train: expected a whole number"),
    "a bool for a number": (TINY.replace("orders = 2", "orders = true"), "orders: expected a whole number"),
    "an unknown model": (TINY.replace('model = "paper"', 'model = "papier"'), "is not a model"),
    "prior on paper": (TINY.replace('model = "extended"', 'model = "paper"'),
                       '"prior" is no ablation of the paper model'),
    "an unknown world": ('world = "moon"\n' + TINY, "is not a world"),
    "a missing objects file": (TINY.replace("generate = { seeds = [5, 7], train = 4, probe = 3, pairs = false }",
                                            'files = ["no_such.json"]'), "no_such.json: cannot read"),
    "an empty list of files": (TINY.replace("generate = { seeds = [5, 7], train = 4, probe = 3, pairs = false }",
                                            "files = []"), "files: the list is empty"),
    "no conditions": ("conditions = []\n" + TINY[TINY.index("[[sets]]"):], "conditions: the list is empty"),
    "empty checks": (TINY.replace("checks = [1, 3, 4]", "checks = []"), "checks: the list is empty"),
    "a check past the set": (TINY.replace("checks = [1, 3, 4]", "checks = [1, 5]"), "must be in 1..4, got 5"),
    "an empty seed range": (TINY.replace("seeds = [5, 7]", "seeds = [7, 7]"), "the range [7, 7) is empty"),
    "pairs on 4 objects": (TINY.replace("pairs = false", "pairs = true"), "--pairs needs n_train >= 6"),
    "two conditions of one name": (TINY.replace('name = "extended -prior"', 'name = "paper"'),
                                   "'paper' is the name of another condition"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_sweep_file_is_refused_in_one_line_before_anything_is_written(tmp_path, case, capsys):
    text, words = BAD[case]
    path = _write(tmp_path, text)
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"train/sweep.py: error: {path}: ") and words in lines[0], lines
    assert captured.out == "" and not (tmp_path / "out").exists()


def test_the_command_line_refuses_a_bad_sweep_file_in_one_line(tmp_path):
    path = _write(tmp_path, BAD["prior on paper"][0])
    r = subprocess.run([sys.executable, "train/sweep.py", str(path), "--out", str(tmp_path / "out")], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == "" and not (tmp_path / "out").exists()
    assert r.stderr.count("\n") == 1 and '"prior" is no ablation of the paper model' in r.stderr, r.stderr


def test_a_physics_world_is_simulated_once_and_shared_by_the_conditions(tmp_path, local_ray):
    text = TINY.replace("seeds = [5, 7], train = 4, probe = 3, pairs = false",
                        'seeds = [5, 6], train = 4, probe = 1, pairs = false, jar = "default"')
    path = _write(tmp_path, 'world = "physics"\n' + text.replace("orders = 2", "orders = 1"))
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 0
    got = _sorted(store.read_cells(tmp_path / "out"))
    assert got.num_rows == 2 * 4 and set(got.column("world").to_pylist()) == {"physics"}
    by = {}
    for r in got.to_pylist():
        by.setdefault(r["condition"], {})[r["object"]] = r["observed_cm3"]
    assert by["paper"] == by["extended -prior"]                       # one world for both conditions
    _, cells = sweep_spec.load_sweep(path)
    direct = sweep_cell.run_cell(cells[0]["spec"], cells[0]["objects"])    # simulated again, here: the same outcomes
    assert {o: v for o, v in zip(direct.column("object").to_pylist(), direct.column("observed_cm3").to_pylist())} \
        == by[cells[0]["spec"]["condition"]["name"]]


OVERRIDDEN = TINY + """
[[conditions]]
name = "paper, no decay"
model = "paper"
overrides = { rules = { uncertain_decay = 1.0 }, "recall_sharpness" = 8 }
"""


def test_overrides_reach_the_agent_and_the_rows(tmp_path):
    pytest.importorskip("train.common.config")
    spec, cells = sweep_spec.load_sweep(_write(tmp_path, OVERRIDDEN))
    cond = spec["conditions"][2]
    assert cond["overrides"] == {"recall_sharpness": 8, "rules.uncertain_decay": 1.0}   # nested or dotted: one form
    cfg = sweep_spec.agent_config(cond, 5, 4)
    assert (cfg.rules.uncertain_decay, cfg.recall_sharpness, cfg.seed, cfg.memory.max_episodes) == (1.0, 8, 5, 4)
    # the buffers are sized to the set first, so an override may size them otherwise
    cfg = sweep_spec.agent_config({**cond, "overrides": {"memory.max_episodes": 2}}, 5, 4)
    assert cfg.memory.max_episodes == 2 and cfg.hub.max_assemblies == 4
    cell = next(c for c in cells if c["spec"]["condition"]["name"] == "paper, no decay")
    table = sweep_cell.run_cell(cell["spec"], cell["objects"])
    assert set(table.column("overrides").to_pylist()) == {'{"recall_sharpness": 8, "rules.uncertain_decay": 1.0}'}
    assert set(table.column("cell").to_pylist()) == {cell["id"]}


@pytest.mark.parametrize("override, words", [
    ('"rules.uncertain_decy" = 1.0', "overrides: unknown key rules.uncertain_decy"),
    ('"rules.uncertain_decay" = "slow"', "overrides: rules.uncertain_decay takes a number"),
    ('"world.mass_noise_g" = 2.0', "overrides: world.mass_noise_g is a key of the world's config"),
    ("seed = 3", "overrides: 'seed' is set by a set's seeds"),
    ('model = "extended"', "overrides: 'model' is set by the condition's model"),
    # each in range, together the knowledge inverted or recall cut off: the runner's agent checks, the same lines
    ('"rules.eliminated_strength" = 0.9, "rules.dominant_strength" = 0.5',
     "overrides: rules.eliminated_strength: rules.eliminated_strength 0.9 is not <= retro_floor"),
    ('"rules.same_rel" = 0.5, "rules.contradiction_rel" = 0.1', "overrides: rules.same_rel: rules.same_rel 0.5 is above"),
    ('"memory.cue_rows" = [0]', "overrides: memory.cue_rows: the agent cues recall with its object hub"),
])
def test_a_bad_override_is_refused_in_one_line(tmp_path, capsys, override, words):
    pytest.importorskip("train.common.config")
    path = _write(tmp_path, OVERRIDDEN.replace('rules = { uncertain_decay = 1.0 }, "recall_sharpness" = 8', override))
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "conditions[2] 'paper, no decay': " + words in lines[0], lines
    assert not (tmp_path / "out").exists()


SMALL_MEMORY = """
[[conditions]]
name = "small"
model = "paper"
overrides = { "memory.max_episodes" = 4, "hub.max_assemblies" = 4, "memory.when_full" = "POLICY", "hub.when_full" = "POLICY" }

[[sets]]
name = "eights"
generate = { seeds = [3, 4], train = 8, probe = 2, pairs = true }
orders = 2
"""


@pytest.mark.parametrize("policy", ["forget_oldest", "forget_weakest"])
def test_eight_objects_through_a_memory_and_hub_of_four_run_to_the_end(tmp_path, policy):
    pytest.importorskip("train.common.config")
    _, (cell,) = sweep_spec.load_sweep(_write(tmp_path, SMALL_MEMORY.replace("POLICY", policy)))
    cfg = sweep_spec.agent_config(cell["spec"]["condition"], 3, 8)
    assert (cfg.memory.max_episodes, cfg.hub.max_assemblies, cfg.memory.when_full) == (4, 4, policy)
    rows = sweep_cell.run_cell(cell["spec"], cell["objects"]).to_pylist()
    assert [(r["order"], r["episode"]) for r in rows] == [(o, e) for o in range(2) for e in range(1, 9)]
    assert all(r["probe_rel_error"] is not None for r in rows)   # predicted to the end, past the fifth object


@pytest.mark.parametrize("part", ["memory", "hub"])
def test_a_refusing_memory_or_hub_too_small_for_the_set_is_refused_before_anything_is_written(tmp_path, capsys, part):
    pytest.importorskip("train.common.config")
    other = {"memory": "hub", "hub": "memory"}[part]
    text = SMALL_MEMORY.replace(f'"{part}.when_full" = "POLICY"', f'"{part}.when_full" = "refuse"')
    path = _write(tmp_path, text.replace("POLICY", "forget_oldest"))
    assert sweep.main([str(path), "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    size = {"memory": "max_episodes", "hub": "max_assemblies"}[part]
    assert len(lines) == 1 and "conditions[0] 'small': 8 train objects but " in lines[0], lines
    assert f"{part}.{size} = 4 and {part}.when_full = refuse" in lines[0] and other + "." not in lines[0], lines
    assert f'overrides {{ "{part}.when_full" = "forget_oldest" }}' in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_the_runner_refuses_eight_objects_through_a_refusing_memory_of_four_in_one_line(tmp_path):
    from sim.make_objects import generate
    f = tmp_path / "eight.json"
    f.write_text(json.dumps(generate(3, 8, 2, pairs=True)))
    r = subprocess.run([sys.executable, "train/run.py", "--objects", str(f), "--orders", "1", "--out",
                        str(tmp_path / "o"), "--set", "memory.max_episodes=4"], cwd=ROOT, capture_output=True,
                       text=True, timeout=180)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert "8 train objects but memory.max_episodes = 4 and memory.when_full = refuse" in lines[0], lines
    assert "--set memory.when_full=forget_oldest" in lines[0] and not (tmp_path / "o").exists()


def test_cells_are_named_by_a_stable_hash_of_their_spec(tmp_path):
    _, cells = sweep_spec.load_sweep(_write(tmp_path, TINY))
    assert len({c["id"] for c in cells}) == 4
    spec = {"format": 4, "world": "closed_form", "condition": {"name": "paper", "model": "paper", "ablate": [],
                                                                "overrides": {}},
            "set_group": "fours", "set": "5", "source": {"generate": {"seed": 5, "train": 4, "probe": 3,
                                                                      "pairs": False, "jar": "random"}},
            "n_train": 4, "n_probe": 3, "seed": 5, "orders": "2", "checks": [1, 3, 4]}
    assert spec in [c["spec"] for c in cells]
    # fixed: a resumed sweep finds the cells an older run wrote (format 1's rows, without the batch answer, memory
    # and per-probe columns, were "adf20a285d537c59"; format 2's, without the config column, "0d2ac7d39c86682e";
    # format 3's, without the commit column, "3ef18f6bc10cafcd")
    assert sweep_cell.cell_id(spec) == "457d4a6853e97c5a"


def _hand_made_table():
    """Two conditions on one set group: 2 cells x 2 orders x 2 episodes each, probe errors at episode 2."""
    rows = []
    for cond, errs, finals in (("a", [0.1, 0.2, 0.3, 0.4], [["IUUD", "IUUD"], ["IUUD", "UUUD"]]),
                               ("b", [1.0, 2.0, 3.0, 5.0], [["UUUU", "UUUU"], ["UUUU", "UUUU"]])):
        for c in range(2):
            for o in range(2):
                for ep in (1, 2):
                    k = finals[c][o] if ep == 2 else "UUUU"
                    rows.append({"cell": f"{cond}{c}", "condition": cond, "model": "paper", "ablate": "",
                                 "overrides": "{}", "commit": "abc1234", "world": "closed_form", "set_group": "g",
                                 "set": str(c),
                                 "generator_seed": c, "seed": c, "n_train": 2, "n_probe": 3, "n_orders": 2,
                                 "order": o, "episode": ep, "object": f"t{ep}", "predicted_cm3": None,
                                 "observed_cm3": 1.0, "archimedes_cm3": 1.0, "sank": False, "goal_reached": False,
                                 "rules": "SSSS", "knowledge": k, "color": k[0], "shape": k[1], "size": k[2],
                                 "weight": k[3], "stored": ep,
                                 "probe_rel_error": errs[2 * c + o] if ep == 2 else None})
    return pa.Table.from_pylist(rows, schema=sweep_cell.schema())


def test_the_report_writes_the_medians_iqr_agreement_and_plots_of_a_hand_made_table(tmp_path, capsys):
    table = _hand_made_table()
    (tmp_path / "cells").mkdir()
    for cell in ("a0", "a1", "b0", "b1"):
        import pyarrow.compute as pc
        store.write_cell(tmp_path, cell, table.filter(pc.equal(table.column("cell"), cell)))
    assert report_mod.main([str(tmp_path)]) == 0
    csv = (tmp_path / "report.csv").read_text().splitlines()
    # the rows' commit first; per condition: the median of its 4 runs, no 95 % interval over its 2 sets (a bootstrap
    # of 2 sets has 3 distinct resamples: "n too small" stands in its place), the runs' 25-75 % range, and the
    # knowledge shares; b learned nothing: its 100 % agreement is marked
    assert csv[0] == "# commit: abc1234" and len(csv) == 7
    assert csv[4:] == ["condition,set_group,episode,sets,runs,error_median_pct,error_ci95_lo_pct,error_ci95_hi_pct,"
                   "error_ci95_note,error_q25_pct,error_q75_pct,floor_pct,over_floor_pct,probes_over_2pts,stored,recalled,runs_fell,"
                   "runs_rose,change_median_pct,cells,cell_sets,cell_runs,order_agreement_pct,nothing_learned,"
                   "colour_irrelevant_pct,weight_dominant_pct,equals_batch_pct",
                   "a,g,2,2,4,25.0000,,,n too small: 2 sets (a 95 % interval needs 10),17.5000,32.5000,,,,,,,,,2,2,4,"
                   "50.00,no,75.00,100.00,",
                   "b,g,2,2,4,250.0000,,,n too small: 2 sets (a 95 % interval needs 10),175.0000,350.0000,,,,,,,,,2,2,4,"
                   "100.00,yes,0.00,0.00,"]
    md = (tmp_path / "report.md").read_text()
    assert "| condition | sets | runs | after 2 episodes |" in md
    assert "| a | 2 | 4 | 25.0 % (n too small: 2 sets) |" in md and "| b | 2 | 4 | 250.0 % (n too small: 2 sets) |" in md
    assert "| a | g | 2 | 2 | 4 | 50.0 % | 75.0 % |" in md and "| b | g | 2 | 2 | 4 | 100.0 % (nothing learned) |" in md
    for png in ("errors.png", "agreement.png"):
        data = (tmp_path / png).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    # and as a script; a DIR without cells is refused in one line
    r = subprocess.run([sys.executable, "train/report.py", str(tmp_path / "cells")], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "holds no finished cells" in r.stderr


def test_the_constants_kept_without_torch_are_the_agents():
    from aesop_torch.agent import ABLATIONS, MODELS
    from aesop_torch.encoders import OBJECT_PROPERTIES
    from aesop_torch.rules import KNOWLEDGE_LETTERS, RULE_NAMES, STATES
    assert models.MODELS == MODELS and models.ABLATIONS == ABLATIONS
    assert sweep_cell.PROPERTY_COLUMNS == OBJECT_PROPERTIES and sweep_cell.RULE_LETTERS == "".join(RULE_NAMES)
    assert sweep_cell.STATE_LETTERS == KNOWLEDGE_LETTERS
    assert len(set(KNOWLEDGE_LETTERS)) == len(KNOWLEDGE_LETTERS) == len(STATES)   # one letter per state, one table


def test_the_docs_name_every_model_and_ablation_and_the_usage_the_command_typed(capsys):
    """docs/sweeps.md's model and ablate rows and the example's comment follow the tables (they said "paper or
    extended" after the contextual model came); each usage line names what a person types."""
    text = (ROOT / "docs" / "sweeps.md").read_text()
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| `conditions[].")}
    assert all(f"`{m}`" in rows["`conditions[].model`"] for m in models.MODELS)
    assert all(f"`{a}`" in rows["`conditions[].ablate`"] for m in models.MODELS for a in models.ABLATIONS[m])
    assert all(f'"{m}"' in next(x for x in text.splitlines() if "# required: " in x and "model =" in x)
               for m in models.MODELS)
    from aesop_torch import cli
    for call, usage in ((lambda: cli.sweep(["--help"]), "usage: aesop-sweep "),
                        (lambda: sweep.main(["--help"]), "usage: python train/sweep.py ")):
        with pytest.raises(SystemExit):
            call()
        out = capsys.readouterr().out
        assert out.startswith(usage) and "--allow-mixed-commits" in out and out.rstrip().endswith("aesop-report DIR.")


def test_the_example_in_docs_and_the_shipped_sweep_files_load():
    import tomllib
    text = (ROOT / "docs" / "sweeps.md").read_text()
    doc = tomllib.loads(text.split("```toml\n")[1].split("```")[0])
    try:
        import train.common.config  # noqa: F401
    except ModuleNotFoundError:   # overrides need train/common/config.py
        for c in doc["conditions"]:
            c.pop("overrides", None)
    spec, cells = sweep_spec.resolve(doc, ROOT / "docs")
    assert [c["name"] for c in spec["conditions"]] == ["paper", "paper -rules", "paper, no uncertainty decay"]
    assert len(cells) == 3 * (10 + 4)
    for f in ("examples/tiny.toml", "examples/ablation.toml", "benches/ablation.toml", "benches/generalization.toml",
              "benches/learning_curve.toml"):
        assert sweep_spec.load_sweep(ROOT / f)[1]
    _, cells = sweep_spec.load_sweep(ROOT / "benches" / "ablation.toml")
    # paper and extended with their two ablations each (3 + 3); contextual, its ten ablations and +active (12)
    assert len(cells) == 18 * (30 + 10 + 8)
