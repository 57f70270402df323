"""The battery's protocol (train/battery/tasks.py): no subject meets the test apparatus or a test object before trial 1,
positions are counterbalanced, choices are a softmax over the options' values, agents learn from each outcome; the
scoring's exact binomial test; the context option's default (off: the default agent's maps and output unchanged);
the bench's last line on a tiny run."""

import math
import random
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
import torch

import train.battery.tasks as battery
from aesop_torch.agent import Agent
from aesop_torch.encoders import (MAP_NAMES, EncoderConfig, SensoryEncoder, default_map_configs,
                                  developmental_samples)
from sim.apparatus import load_task
from train.battery.tasks import (CONTEXT, REWARD_SCALE, Protocol, Subjects, balanced_swaps, binomial_tail, context_agent,
                           make_config, make_subjects, play, run_task, score, softmax_choice, task_world)

ROOT = Path(__file__).resolve().parents[1]
TASKS = ROOT / "sim" / "tasks"
SMALL = Protocol(jar_objects=6, pretrain_repeats=1)


def test_binomial_tail_known_values():
    # by hand: sum_{i>=15} C(20, i) / 2^20 = (15504 + 4845 + 1140 + 190 + 20 + 1) / 1048576
    assert binomial_tail(15, 20, 0.5) == pytest.approx(21700 / 2 ** 20, abs=1e-12)
    assert binomial_tail(14, 20, 0.5) == pytest.approx(0.057659, abs=1e-6)
    assert binomial_tail(1, 1, 1 / 3) == pytest.approx(1 / 3)
    with pytest.raises(ValueError):
        binomial_tail(21, 20, 0.5)


def test_score_pools_subjects_per_window():
    right = [[True] * 20, [False] + [True] * 14 + [False] * 5]
    s = score(right, 0.5)
    assert (s["trial 1"].correct, s["trial 1"].n) == (1, 2)
    assert (s["1-5"].correct, s["1-5"].n) == (9, 10)
    assert (s["1-20"].correct, s["1-20"].n) == (34, 40)


def test_context_off_by_default():
    assert EncoderConfig().context == ()
    assert tuple(default_map_configs()) == MAP_NAMES
    g0, g1 = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    plain = developmental_samples(50, g0)
    ctx = developmental_samples(50, g1, EncoderConfig(context=("width",)))
    for name in MAP_NAMES:   # the context's draws come last: the maps' own samples are unchanged
        assert torch.equal(plain[name], ctx[name])
    with pytest.raises(ValueError, match="context"):
        SensoryEncoder()({"rgb": [0.5, 0.5, 0.5], "context": {"width": 0.3}})


@pytest.mark.parametrize("kind", ["naive", "experienced"])
def test_no_subject_meets_the_test_apparatus_or_a_test_object_before_trial_1(monkeypatch, kind):
    """Every measurement an agent learns from (Agent.step) before the first trial is compared with the task's: no
    test object (its rgb, extents and mass) and no test tube (its look, width and level) may be among them. An
    exploration of the test apparatus before trial 1 fails this."""
    task = load_task(TASKS / "sinking_vs_floating.json")
    options, *_ = task_world(task)
    phase, before = ["before"], []
    real_step, real_play = Agent.step, battery.play

    def step(self, measurement, *a, **k):
        if phase[0] == "before":
            before.append(measurement)
        return real_step(self, measurement, *a, **k)

    def play_(*a, **k):
        phase[0] = "trial"
        return real_play(*a, **k)
    monkeypatch.setattr(Agent, "step", step)
    monkeypatch.setattr(battery, "play", play_)
    r = run_task(task, "paper", [1], 2, trials=2, kind=kind, protocol=SMALL)
    assert len(before) == 3 + (6 if kind == "experienced" else 0)   # 3 stones once (and a jar life of 6 objects)
    test_objects = [torch.tensor(o["rgb"] + o["extent_cm"] + [o["mass_g"]]) for o in options[0]]
    test_tubes = [torch.tensor([o["context"][k] for k in ("surface", "width", "level")]) for o in options[0]]
    for m in before:
        for b in range(2):
            obj = torch.cat([m["rgb"][b], m["extent_cm"][b], m["mass_g"][b:b + 1]])
            tube = torch.stack([m["context"][k][b] for k in ("surface", "width", "level")])
            assert not any(torch.allclose(obj, o, atol=1e-3) for o in test_objects)
            assert not any(torch.allclose(tube, t, atol=1e-3) for t in test_tubes)
    # the log says the same: before the trials, only the jar and the pre-training tube
    assert all(where in ("jar", "pretraining") for subject in r["log"] for phase_, where, _ in subject
               if phase_ != "trial")
    assert [sum(p == "trial" for p, _, _ in subject) for subject in r["log"]] == [2, 2]


def test_positions_are_counterbalanced():
    """Per subject half the trials mirrored, in an order of its own; the correct tube's perceived place is left on
    some trials and right on others."""
    assert sorted(balanced_swaps(20, random.Random(1))) == [False] * 10 + [True] * 10
    task = load_task(TASKS / "water_vs_sand.json")
    options, _, correct, _ = task_world(task)
    (c,) = correct
    assert options[0][c]["context"]["place"] == 0.0 and options[1][c]["context"]["place"] == 1.0
    r = run_task(task, "paper", [2], 2, trials=10, kind="naive", protocol=SMALL)
    assert [sum(s) for s in r["swapped"]] == [5, 5]
    assert len({tuple(s) for s in r["swapped"]}) == 2                 # each subject its own order
    assert all(any(s) and not all(s) for s in r["swapped"])
    # each task its own draws: the same subjects mirror another task on other trials
    other = run_task(load_task(TASKS / "water_vs_sawdust.json"), "paper", [2], 2, trials=10, kind="naive",
                     protocol=SMALL)
    assert other["swapped"] != r["swapped"]


def test_softmax_choice_draws_by_the_values():
    """Values 0 and T ln 3 at temperature T: the second 3 times as likely (0.75); a NaN is valued as the mean of the
    known values; all NaN: uniform."""
    rng = random.Random(0)
    t = 2.0
    draws = [softmax_choice([0.0, t * math.log(3)], t, rng) for _ in range(4000)]
    assert sum(draws) / 4000 == pytest.approx(0.75, abs=0.025)
    draws = [softmax_choice([float("nan"), 0.0, 2 * t * math.log(3)], t, rng) for _ in range(4000)]
    # the NaN takes the mean (t ln 3): weights 3 : 1 : 9 relative to exp(0)
    assert draws.count(0) / 4000 == pytest.approx(3 / 13, abs=0.025)
    draws = [softmax_choice([float("nan")] * 2, t, rng) for _ in range(4000)]
    assert sum(draws) / 4000 == pytest.approx(0.5, abs=0.03)


def _small(model):
    c = make_config(model, seed=1)
    return replace(c, som_samples=800, som_epochs=5)


def _subjects(model, options, world, first):
    """Two subjects that each tried both options once in each layout (subject b option first[b] first)."""
    agent = context_agent(_small(model), 2)
    no = torch.zeros(2, dtype=torch.bool)
    for layout in (0, 1):
        for step in range(2):
            chosen = [first[b] if step == 0 else 1 - first[b] for b in range(2)]
            outs = [world(i) for i in chosen]
            agent.step(battery.stack([options[layout][i] for i in chosen]),
                       torch.tensor([REWARD_SCALE * r for r, _ in outs]), no, torch.tensor([x for _, x in outs]))
    return Subjects(agent, [11, 12], "naive", [[], []])


@pytest.mark.parametrize("model", ["paper", "extended"])
def test_two_options_one_episode_each_chooses_the_better(model):
    """Same object, two tubes differing only in their contents' look: option 0 raises the reward 2 cm (in reach),
    option 1 not at all, each tried in both layouts. At a low temperature every choice is option 0, in either
    layout."""
    obj = {"rgb": [0.8, 0.1, 0.1], "extent_cm": [4.0, 4.0, 4.0], "fill": 1.0, "mass_g": 150.0}
    ctx = lambda s, place: {"surface": s, "width": 0.3, "level": 0.5, "place": place}
    options = [[dict(obj, context=ctx(0.15, 0.0)), dict(obj, context=ctx(0.6, 1.0))],
               [dict(obj, context=ctx(0.15, 1.0)), dict(obj, context=ctx(0.6, 0.0))]]
    world = lambda i: (2.0, True) if i == 0 else (0.0, False)
    subjects = _subjects(model, options, world, [0, 1])
    assert tuple(subjects.agent.maps)[-len(CONTEXT):] == CONTEXT
    r = play(subjects, "t", options, world, {0}, trials=4, protocol=Protocol(temperature=0.01))
    assert r["choices"] == [[0] * 4, [0] * 4] and r["right"] == [[True] * 4] * 2
    assert [sum(s) for s in r["swapped"]] == [2, 2]


def test_a_choice_aims_at_the_rewards_gap():
    """Two tubes alike but for their level: each option raises its own reward 1.8 cm; only the high tube's (seen
    1.5 cm below reach, the low one's 5 cm) comes in reach. The predicted rises tie, so the values differ by the
    gaps (3.5 cm = 350 units): aiming at the gap chooses the high tube on every trial at any sane temperature."""
    obj = {"rgb": [0.5, 0.5, 0.5], "extent_cm": [3.0, 3.0, 5.0], "fill": 0.785, "mass_g": 100.0}
    ctx = lambda level, place: {"surface": 0.15, "width": 0.3, "level": level, "place": place}
    options = [[dict(obj, context=ctx(0.775, 0.0), gap_cm=1.5), dict(obj, context=ctx(0.6, 1.0), gap_cm=5.0)],
               [dict(obj, context=ctx(0.775, 1.0), gap_cm=1.5), dict(obj, context=ctx(0.6, 0.0), gap_cm=5.0)]]
    world = lambda i: (1.8, i == 0)
    r = play(_subjects("paper", options, world, [0, 1]), "t", options, world, {0}, trials=4)
    assert r["choices"] == [[0] * 4, [0] * 4]
    with pytest.raises(ValueError, match="aim"):
        play(_subjects("paper", options, world, [0, 1]), "t", options, world, {0}, trials=1, aim="nearest")


def test_an_experienced_subject_has_lived_its_jar_life():
    """The jar life is the Crow and Pitcher experiment: N generated objects, each an episode step (the log), before
    the pre-training; a naive subject has the pre-training alone."""
    e = make_subjects("paper", "experienced", 1, 2, protocol=SMALL)
    n = make_subjects("paper", "naive", 1, 2, protocol=SMALL)
    assert [p for p, _, _ in e.log[0]] == ["jar"] * 6 + ["pretraining"] * 3
    assert [p for p, _, _ in n.log[0]] == ["pretraining"] * 3
    assert e.log[0][:6] != e.log[1][:6]                     # each subject its own jar life
    assert int(e.agent.memory.count.min()) > int(n.agent.memory.count.max())
    with pytest.raises(ValueError, match="kind"):
        make_subjects("paper", "wise", 1, 1)


def test_bench_help():
    r = subprocess.run([sys.executable, str(ROOT / "benches" / "battery.py"), "--help"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and "--ablate" in r.stdout and "--record" in r.stdout and "--models" in r.stdout


def bench_model() -> str:
    import importlib.util
    spec = importlib.util.spec_from_file_location("battery_bench", ROOT / "benches" / "battery.py")
    sys.path.insert(0, str(ROOT / "benches"))
    try:
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(ROOT / "benches"))
    return module.MODEL


@pytest.mark.timeout(200)
def test_bench_last_line_on_a_tiny_run(tmp_path):
    """1 seed, 1 subject, 3 trials, one task: ~9 s of CPU (8.2 s user measured)."""
    r = subprocess.run([sys.executable, str(ROOT / "benches" / "battery.py"), "--quick", "--tasks",
                        "sinking_vs_floating", "--trials", "3", "--workers", "1", "--out", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT, timeout=180)
    assert r.returncode == 0, r.stderr
    last = r.stdout.splitlines()[-1]
    rate = r"(0\.\d\d|1\.00)"
    m = bench_model()   # the transfer model, one constant in the bench
    assert re.fullmatch(rf"transfer_trial1_{m}={rate} transfer_trial1_{m}_rules_off={rate} "
                        rf"transfer_trial1_paper=n/a learned_tasks_naive_{m}=[01]/1 crows_agreement=[01]/1",
                        last), last
    assert (tmp_path / "battery_curves.png").stat().st_size > 0
    assert "before trial 1: 0" in r.stdout


def test_bench_refuses_an_unknown_model_in_one_line(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "benches" / "battery.py"), "--models", "oracle", "--out",
                        str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "oracle" in r.stderr
    assert not list(tmp_path.iterdir())
