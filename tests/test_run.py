"""The runner end to end, with physics: the paper's episodes 1-3, summary.json, tensorboard, checkpoints, resume."""

import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from in_process import run_main, wait_until_unlocked

ROOT = Path(__file__).resolve().parents[1]
PAPER = {"train": [
    {"name": "red_heavy_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 420},
    {"name": "blue_heavy_cylinder", "shape": "cylinder", "color": "blue", "dims_cm": [6.36, 11.5], "mass_g": 420},
    {"name": "red_light_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 14}],
    "probe": [
    {"name": "purple_heavy_cylinder", "shape": "cylinder", "color": "purple", "dims_cm": [6.36, 11.5], "mass_g": 400},
    {"name": "green_light_cylinder", "shape": "cylinder", "color": "green", "dims_cm": [6.36, 11.5], "mass_g": 20}],
    # a goal trial after the exploration: the same look, 400 g (sinks, 365 cm^3, reaches the ball) or 14 g (floats)
    "trials": [{"stand": ["red_light_cylinder", "purple_heavy_cylinder"]}]}


def runner(*args):
    return [sys.executable, str(ROOT / "train" / "run.py"), *args]


@pytest.fixture(scope="module")
def paper_file(tmp_path_factory):
    f = tmp_path_factory.mktemp("objects") / "paper.json"
    f.write_text(json.dumps(PAPER))
    return f


@pytest.fixture(scope="module")
def paper_run(paper_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "paper"
    r = run_main("--objects", paper_file, "--orders", "listed", "--out", out)
    assert r.returncode == 0, r.stderr
    return out, json.loads((out / "summary.json").read_text()), r.stdout


def test_paper_episodes_1_to_3_with_physics(paper_run):
    _, summary, _ = paper_run
    (run,) = summary["runs"]
    e1, e2, e3 = run["episodes"]
    assert run["order"] == [o["name"] for o in PAPER["train"]]
    # episode 1: nothing to recall, explores, the heavy cylinder sinks (~365 cm^3) and makes the ball reachable
    assert e1["predicted_cm3"] is None and e1["encoded"] and e1["goal_reached"]
    assert e1["observed_cm3"] == pytest.approx(e1["archimedes_cm3"], rel=0.02) and e1["archimedes_cm3"] > 360
    assert set(e1["rules"].values()) == {"S"}
    # episode 2: expects ~365, observes it, eliminates colour, is not encoded
    assert e2["predicted_cm3"] == pytest.approx(365, abs=3) and not e2["encoded"]
    assert e2["rules"] == {"color": "E", "shape": "S", "size": "S", "weight": "S"}
    assert e2["knowledge"]["color"] == {"state": "irrelevant", "certainty": 1.0}
    # episode 3: expects ~365, observes far less (it floats), grows weight, shape and size uncertain, encoded
    assert e3["predicted_cm3"] == pytest.approx(365, abs=3) and e3["observed_cm3"] < 30 and e3["encoded"]
    assert e3["rules"] == {"color": "S", "shape": "U", "size": "U", "weight": "G"}
    assert not e3["goal_reached"]
    assert run["confounded"] == []                          # the paper model's Growth fires only on a clean change
    assert run["knowledge_by_context"]["sinking"] == run["knowledge_by_context"]["floating"]   # it has no contexts
    assert "color" in run["knowledge_by_context"]["mixed"]["irrelevant"]
    k = run["final_knowledge"]
    assert k["weight"]["state"] == "dominant" and k["shape"]["state"] == "likely_irrelevant"
    assert summary["order_independent"] is None            # one order: undefined, not a vacuous true


def test_summary_contract(paper_run):
    out, summary, stdout = paper_run
    assert set(summary) >= {"seed", "runs", "order_independent", "model", "ablate"} and summary["seed"] == 0
    assert summary["model"] == "paper" and summary["ablate"] == []   # the default: the paper's model, whole
    ep_keys = {"object", "predicted_cm3", "observed_cm3", "archimedes_cm3", "rules", "knowledge", "encoded",
               "goal_reached", "probe_rel_error", "perceived", "true"}
    for e in summary["runs"][0]["episodes"]:
        assert set(e) == ep_keys
        for k in e["knowledge"].values():
            assert k["state"] in ("unknown", "dominant", "irrelevant", "likely_irrelevant")
            assert 0.0 <= k["certainty"] <= 1.0
        seen, true = e["perceived"], e["true"]   # what the camera and the hand perceived, beside the file's values
        assert all(abs(a - b) <= 0.05 * b for a, b in zip(seen["extent_cm"], true["extent_cm"]))
        assert abs(seen["fill"] - true["fill"]) <= 0.08 and abs(seen["mass_g"] - true["mass_g"]) <= 5.0
    # probes (a heavy and a 20 g cylinder): after episode 1 both are expected to sink like it, so the light one is
    # off by ~17x (median of two = their mean, ~8.6); after episode 3 it is expected to float like the 14 g one
    errs = [e["probe_rel_error"] for e in summary["runs"][0]["episodes"]]
    assert errs[0] > 5 and errs[-1] < 0.5
    assert (out / "figure2.png").stat().st_size > 10_000
    assert "order_independent: undefined (one order)" in stdout and str(out) in stdout
    # the goal trial, by hand: the 400 g cylinder (expected like the heavy one) alone makes the ball reachable
    (t,) = summary["runs"][0]["trials"]
    assert set(t) == {"goal", "stand", "chosen", "expected_cm3", "observed_cm3", "drops", "goal_reached", "fewest_drops",
                      "random_drops_mean", "excess_drops", "first_choice_optimal", "expected_drops",
                      "recall_strength", "agreeing_episodes", "explored"}
    assert t["goal"] == "reach the green ball"                # the teacher's default goal
    assert t["stand"] == ["red_light_cylinder", "purple_heavy_cylinder"] and t["chosen"] == ["purple_heavy_cylinder"]
    assert t["expected_cm3"][0] == pytest.approx(365, rel=0.05) and t["explored"] == [False]
    assert t["observed_cm3"][0] == pytest.approx(365.3, rel=0.02) and t["goal_reached"]
    assert (t["drops"], t["fewest_drops"], t["random_drops_mean"], t["excess_drops"]) == (1, 1, 1.5, 0)
    assert "trial 1: purple_heavy_cylinder" in stdout


def test_tensorboard_tags_and_values(paper_run):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    out, summary, _ = paper_run
    acc = EventAccumulator(str(out / "tb" / "order_01"), size_guidance={"tensors": 0, "scalars": 0})
    acc.Reload()
    tags = set(acc.Tags()["scalars"]) | set(acc.Tags()["tensors"])
    for p in ("color", "shape", "size", "weight"):
        assert f"certainty/{p}" in tags
        for r in "EGUS":
            assert f"rules/{p}/{r}" in tags
    assert {"prediction/abs_error_cm3", "prediction/probe_rel_error"} <= tags
    assert any(t.startswith("episodes") for t in tags)
    text = acc.Tensors(next(t for t in tags if t.startswith("episodes")))[0].tensor_proto.string_val[0].decode()
    assert "perceived: rgb=" in text and "fill=0.7" in text     # perceived vs true: the cylinder's fill is pi/4
    assert [e.step for e in acc.Images("figure2")] == [3]   # Figure 2, once, at the last episode

    def series(tag):
        return {e.step: e.value for e in acc.Scalars(tag)}
    assert series("rules/color/E") == {1: 0.0, 2: 1.0, 3: 0.0}
    assert series("rules/weight/G") == {1: 0.0, 2: 0.0, 3: 1.0}
    assert series("certainty/weight") == {1: 0.0, 2: 0.0, 3: 1.0}
    assert series("certainty/shape")[3] == pytest.approx(0.3)
    eps = summary["runs"][0]["episodes"]
    err = series("prediction/abs_error_cm3")
    assert set(err) == {2, 3}  # no prediction in episode 1
    assert err[3] == pytest.approx(abs(eps[2]["predicted_cm3"] - eps[2]["archimedes_cm3"]), abs=0.01)
    assert series("trials/drops") == {1: 1.0} and series("trials/excess_drops") == {1: 0.0}


def test_checkpoint_loads_weights_only_and_predicts_for_a_new_object(paper_run):
    from train.learning.experiment import load_experiment
    out, summary, _ = paper_run
    state = torch.load(out / "checkpoints" / "latest.pt", weights_only=True)
    assert state["experiment"]["t"] == 3
    exp = load_experiment(out / "checkpoints" / "latest.pt")
    heavy = {"rgb": [0.2, 0.8, 0.2], "extent_cm": [11.5, 6.36, 6.36], "fill": math.pi / 4, "mass_g": 420.0}
    assert exp.predict(heavy).item() == pytest.approx(365, abs=5)  # a green heavy cylinder: colour is irrelevant
    assert exp.final_knowledge() == [summary["runs"][0]["final_knowledge"]]


def test_killed_run_resumes_to_the_same_summary(paper_file, tmp_path):
    # per-episode physics: every episode simulates a drop (~1 s), so the kill lands between episodes
    args = ["--objects", str(paper_file), "--orders", "listed", "--physics", "per-episode"]
    whole = tmp_path / "whole"
    r = run_main(*args, "--out", whole)   # the uninterrupted run in this process: SIGKILL's is the next one
    assert r.returncode == 0, r.stderr
    out = tmp_path / "killed"
    proc = subprocess.Popen(runner(*args, "--out", str(out)), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ckpt = out / "checkpoints" / "latest.pt"
    deadline = time.time() + 120
    while proc.poll() is None and time.time() < deadline:
        if ckpt.exists() and torch.load(ckpt, weights_only=True)["experiment"]["t"] >= 1:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "summary.json").exists(), "the run finished before it could be killed"
    wait_until_unlocked(out)   # its workers' exit, before a resume in this process
    assert 1 <= torch.load(ckpt, weights_only=True)["experiment"]["t"] < 3
    r = run_main(*args, "--out", out, "--resume")
    assert r.returncode == 0, r.stderr
    assert (out / "summary.json").read_text() == (whole / "summary.json").read_text()
    # resuming with other settings is refused, and leaves the finished run as it was
    before = (out / "summary.json").read_text()
    r = run_main(*args, "--out", out, "--resume", "--seed", "5")
    assert r.returncode == 2 and "seed" in r.stderr and (out / "summary.json").read_text() == before
    for other, word in ((["--model", "extended"], "model"), (["--ablate", "rules"], "ablate")):
        r = run_main(*args, "--out", out, "--resume", *other)
        assert r.returncode == 2 and word in r.stderr and (out / "summary.json").read_text() == before


def test_shipped_default_checkpoint_predicts_as_the_readme_says():
    from train.learning.experiment import load_experiment
    path = ROOT / "checkpoints" / "default.pt"
    assert torch.load(path, weights_only=True)["run"]["orders_arg"] == "4"
    exp = load_experiment(path)
    green_heavy_cylinder = {"rgb": [0.1, 0.7, 0.2], "extent_cm": [11.5, 6.36, 6.36], "fill": 0.785, "mass_g": 420.0}
    # the paper model, as shipped: colour eliminated, the cue recalls the red and blue heavy cylinders of this size
    # and weight, and their rewards (365 cm^3 each) are what it averages: within 1 % of Archimedes' 365.3
    assert exp.config.model == "paper"
    assert exp.predict(green_heavy_cylinder).tolist() == pytest.approx([365.3] * 4, rel=0.01)
    assert exp.final_knowledge()[0]["color"]["state"] == "irrelevant"
    assert exp.final_knowledge()[0]["weight"]["state"] == "dominant"


def test_more_orders_than_full_records_run_as_a_population(paper_file, tmp_path):
    out = tmp_path / "pop"
    r = run_main("--objects", paper_file, "--orders", "70", "--out", out)
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    from train.learning.experiment import draw_orders
    from train.runner.settings import FULL_RUNS
    from train.runner.summary import knowledge_key
    orders = draw_orders(3, "70", seed=0)
    names = [o["name"] for o in PAPER["train"]]
    # the first FULL_RUNS orders in full detail, every order in the compact block
    assert [run["order"] for run in summary["runs"]] == [[names[i] for i in o] for o in orders[:FULL_RUNS]]
    pop = summary["population"]
    assert pop["orders"] == 70 and len(pop["final_knowledge"]) == len(pop["final_probe_rel_error"]) == 70
    # the population's agents end where the detailed ones do, order by order
    assert pop["final_knowledge"][:FULL_RUNS] == [knowledge_key(run["final_knowledge"]) for run in summary["runs"]]
    for err, run in zip(pop["final_probe_rel_error"], summary["runs"]):
        assert err == pytest.approx(run["episodes"][-1]["probe_rel_error"], abs=1e-4)
    # an order's knowledge depends on its order: the same order, the same key, wherever it comes
    by_order = {}
    for o, key in zip(orders, pop["final_knowledge"]):
        assert by_order.setdefault(tuple(o), key) == key
    common = max(set(pop["final_knowledge"]), key=pop["final_knowledge"].count)
    assert pop["most_common_knowledge"] == common
    assert pop["agree_fraction"] == pop["final_knowledge"].count(common) / 70
    assert summary["order_independent"] == (len(set(pop["final_knowledge"])) == 1)
    assert "population: 70 orders" in r.stdout


def test_per_episode_physics_for_a_population_is_refused_before_anything_is_written(paper_file, tmp_path):
    out = tmp_path / "refused"
    r = run_main("--objects", paper_file, "--orders", "70", "--physics", "per-episode", "--out", out)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "per-episode" in r.stderr
    assert not out.exists()


def test_an_object_in_the_files_schema_is_predicted_as_its_measurement(tmp_path, capsys):
    """One schema for an object: Experiment.predict takes the objects file's {shape, color, dims_cm, mass_g} (perceived
    exactly) as it takes a measurement, refuses what the file would refuse, and train/ask.py --objects predicts a
    whole file against Archimedes."""
    from sim.objects import ObjectsFileError, parse_object
    from train.learning.experiment import load_experiment
    exp = load_experiment(ROOT / "checkpoints" / "default.pt")
    spec = {"shape": "cylinder", "color": [0.1, 0.7, 0.2], "dims_cm": [6.36, 11.5], "mass_g": 420}
    assert torch.equal(exp.predict(spec), exp.predict(parse_object(spec).exact_measurement()))
    with pytest.raises(ObjectsFileError, match="mass_g"):
        exp.predict({**spec, "mass_g": -1})
    objects = tmp_path / "two.json"
    objects.write_text(json.dumps({"train": [{"name": "green_heavy_cylinder", **spec}],
                                   "probe": [{"name": "light", **spec, "mass_g": 14}]}))
    # the command's main() in this process (tests/test_trials.py runs the script itself): no interpreter and
    # torch import per call
    from train.ask import main as ask
    capsys.readouterr()
    code = ask([str(ROOT / "checkpoints" / "default.pt"), "--objects", str(objects)])
    out, err = capsys.readouterr()
    lines = out.strip().splitlines()
    assert code == 0 and len(lines) == 3 and lines[0].startswith("green_heavy_cylinder: expected")
    assert "Archimedes 365.3" in lines[0] and lines[-1].startswith("median_rel_error=")
    objects.write_text('{"train": [{"name": "x", "shape": "cube", "color": "red", "dims_cm": [5], "mass_g": 0}]}')
    code = ask([str(ROOT / "checkpoints" / "default.pt"), "--objects", str(objects)])
    out, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1 and "mass_g" in err


def test_summary_says_what_the_extended_knowledge_rests_on():
    """The extended model's knowledge by context (size dominant among sinkers, weight among floaters on the default
    set) and its confounded properties reach summary.json and the console's table."""
    from aesop_torch.agent import AgentConfig
    from sim.objects import load_objects
    from train.learning.experiment import Experiment, closed_form_outcomes
    from train.runner.summary import build_summary, knowledge_table
    objects = load_objects(ROOT / "sim" / "default_objects.json")
    outcomes, probes = closed_form_outcomes(objects)
    exp = Experiment([o.name for o in objects.train], [], [list(range(len(objects.train)))],
                     config=AgentConfig.extended(), outcomes=outcomes, probes={})
    while not exp.done:
        exp.step(lambda name, b, t: outcomes[name])
    summary = build_summary(exp)
    run = summary["runs"][0]
    by = run["knowledge_by_context"]
    assert "size" in by["sinking"]["dominant"] and "weight" in by["floating"]["dominant"]
    assert by["sinking"] != by["floating"]
    shown = exp.agent.rules.confounded[0].tolist()
    assert run["confounded"] == [p for p, c in zip(("color", "shape", "size", "weight"), shown) if c]
    assert "by context: floating: dominant" in knowledge_table(summary)
