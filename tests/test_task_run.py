"""A task file of the Aesop battery through train/run.py: the apparatus in pybullet, seen from the camera, each option's
measured rise against the closed form (sim.apparatus.outcome: V / area), and the run's outputs."""

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from sim.apparatus import load_task, outcome
from train.battery.tasks import WIDTH_RANGE_CM
from train.battery.task_run import PhysicsWorld, look

ROOT = Path(__file__).resolve().parents[1]
TASKS = ROOT / "sim" / "tasks"


def test_a_surfaces_look_is_its_mean_brightness():
    assert look((0.85, 0.75, 0.45)) == pytest.approx(0.6833, abs=1e-4)   # sand's colour
    assert look((2.0, 2.0, 2.0)) == 1.0 and look((0.0, 0.0, 0.0)) == 0.0


@pytest.mark.parametrize("name", ["narrow_vs_wide", "water_vs_sand"])
def test_the_simulated_options_rise_as_the_closed_form_and_the_camera_reads_the_tubes(name):
    task = load_task(TASKS / f"{name}.json")
    world = PhysicsWorld(task)
    start = task.start_levels()
    lo, hi = WIDTH_RANGE_CM
    for tube, obj in task.options():
        got, want = world.outcome(task, start, tube, obj), outcome(task, dict(start), tube, obj)
        assert got["settled"], (tube.name, obj.name)
        # a sinker in water: V / area (e.g. 35.3 cm^3 in a 5 cm tube, +1.80 cm); on sand: nothing
        assert got["reward_rise_cm"] == pytest.approx(want["reward_rise_cm"], abs=0.01), (tube.name, obj.name)
        assert got["reached"] == want["reached"], (tube.name, obj.name)
        ctx = world.measurement(task, tube, obj)["context"]
        width = math.exp(math.log(lo) + ctx["width"] * (math.log(hi) - math.log(lo)))
        assert width == pytest.approx(tube.inner_diameter_cm, abs=0.15), tube.name   # read 1-1.5 % narrow
        assert ctx["level"] * tube.height_cm == pytest.approx(tube.level_cm, abs=0.02), tube.name
    looks = {t.substrate: world.measurement(task, t, task.objects[0])["context"]["surface"] for t in task.tubes}
    assert len(set(round(v, 2) for v in looks.values())) == len(looks)   # each substrate looks different


def _run(*args, timeout=600):
    return subprocess.run([sys.executable, str(ROOT / "train" / "run.py"), *map(str, args)], capture_output=True,
                          text=True, timeout=timeout)


def test_a_task_file_runs_through_the_runner_with_physics_and_tensorboard(tmp_path):
    out = tmp_path / "out"
    r = _run("--objects", TASKS / "u_tube.json", "--orders", "1", "--seed", "3", "--out", out)
    assert r.returncode == 0, r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["task"] == "u_tube" and s["agents"] == 1 and s["seed"] == 3
    assert [o["option"] for o in s["options"]] == ["side:stone", "middle:stone"]
    side, middle = s["options"]
    # 35.3 cm^3 into the side tube, shared with the reward tube over 2 x 19.63 cm^2: +0.90 cm; the middle: 0
    assert side["simulated_rise_cm"] == pytest.approx(0.90, abs=0.01) and side["correct"] and side["reached"]
    assert middle["simulated_rise_cm"] == pytest.approx(0.0, abs=0.01) and not middle["correct"]
    assert [s["scores"][k]["n"] for k in ("trial 1", "1-5", "1-20")] == [1, 5, 20]
    assert len(s["choices"]) == 1 and len(s["choices"][0]) == 20
    assert list((out / "tb").glob("events.out.tfevents.*"))


@pytest.mark.parametrize("args, words", [(["--resume"], "--resume"), (["--orders", "all"], "--orders"),
                                         (["--set", "rules.uncertain_decay=1.0"], "--set")])
def test_what_a_task_run_does_not_take_is_refused_in_one_line(tmp_path, args, words):
    out = tmp_path / "out"
    r = _run("--objects", TASKS / "u_tube.json", "--out", out, *args, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and words in r.stderr, r.stderr
    assert not (out / "summary.json").exists()
