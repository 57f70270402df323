"""The battery's protocol (train/battery/tasks.py): no subject meets the test apparatus or a test object before trial 1,
positions are counterbalanced, choices are a softmax over the options' values, agents learn from each outcome; the
scoring's exact binomial test; the context option's default (off: the default agent's maps and output unchanged);
the bench's last line on a tiny run."""

import math
import random
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import train.battery.tasks as battery
from aesop_torch.agent import Agent
from aesop_torch.encoders import (MAP_NAMES, EncoderConfig, SensoryEncoder, default_map_configs,
                                  developmental_samples)
from sim.apparatus import load_task
from train.battery.tasks import (Protocol, balanced_swaps, binomial_tail, make_config, make_subjects, play, run_task, score,
                           softmax_choice, task_world)

ROOT = Path(__file__).resolve().parents[1]
TASKS = ROOT / "sim" / "tasks"
SMALL = Protocol(jar_objects=6, criterion=1, max_pretrain_trials=4)


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
        if k.get("phase", "trial") == "trial":
            phase[0] = "trial"
        return real_play(*a, **k)
    monkeypatch.setattr(Agent, "step", step)
    monkeypatch.setattr(battery, "play", play_)
    r = run_task(task, "paper", [1], 2, trials=2, kind=kind, protocol=SMALL)
    jar = 6 if kind == "experienced" else 0
    # a jar life of 6 objects, then the pre-training: at least `criterion` trials of drops_to_reach drops each
    assert len(before) >= jar + SMALL.criterion * SMALL.drops_to_reach
    for subject in r["log"]:
        phases = [p for p, _, _ in subject]
        assert phases[:jar] == ["jar"] * jar
        assert phases.count("pretraining") >= SMALL.criterion * SMALL.drops_to_reach
    test_objects = [torch.tensor(o["rgb"] + o["extent_cm"] + [o["mass_g"]]) for o in options[0]]
    levels = battery.trial_levels(task, SMALL)
    test_tubes = [torch.tensor([battery.perceive_option(task, t, {}, lv)["context"][k]
                                for k in ("surface", "width", "level")])
                  for t in task.tubes for lv in (levels, task.start_levels())]
    for m in before:
        for b in range(2):
            obj = torch.cat([m["rgb"][b], m["extent_cm"][b], m["mass_g"][b:b + 1]])
            tube = torch.stack([m["context"][k][b] for k in ("surface", "width", "level")])
            assert not any(torch.allclose(obj, o, atol=1e-3) for o in test_objects)
            assert not any(torch.allclose(tube, t, atol=1e-3) for t in test_tubes)
    # the log says the same: before the trials, only the jar and the pre-training tube
    assert all(where in ("jar", "pretraining") for subject in r["log"] for phase_, where, _ in subject
               if phase_ != "trial")
    assert [sum(p == "trial" for p, _, _ in subject) for subject in r["log"]] == [sum(d) for d in r["drops"]]
    assert [len(d) for d in r["drops"]] == [2, 2]


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


def test_a_trial_is_drops_with_the_water_carried_over():
    """sinking vs floating: the trial starts 2 functional drops below the file's level (the stone raises 35.34 /
    19.63 = 1.80 cm: 15.5 - 3.60 = 11.90 cm); every drop is asked of the world from the levels the last one left;
    a subject that drops the stone three times reaches, and the trial ends there."""
    task = load_task(TASKS / "sinking_vs_floating.json")
    rise = math.pi / 4 * 9 * 5 / (math.pi / 4 * 25)
    assert battery.trial_levels(task, Protocol())["tube"] == pytest.approx(15.5 - 2 * rise)
    from sim.apparatus import outcome
    asked = []

    def world(task_, levels, tube, obj):
        asked.append((dict(levels), obj.name))
        return outcome(task_, levels, tube, obj)
    subjects = make_subjects("paper", "naive", 1, 1, protocol=SMALL)     # one subject: the world's calls in order
    r = play(subjects, task, trials=3, protocol=SMALL, outcome=world)
    for (lv, name), (nxt, _) in zip(asked, asked[1:]):
        if nxt["tube"] != battery.trial_levels(task, SMALL)["tube"]:      # not a new trial's first drop
            assert nxt["tube"] == pytest.approx(lv["tube"] + (rise if name == "stone" else 12 / (math.pi / 4 * 25)))
    assert len(asked) == sum(r["drops"][0])
    for b in range(1):
        for choices, reached, drops in zip(r["choices"][b], r["reached"][b], r["drops"][b]):
            assert drops == len(choices) and reached == (choices.count("tube:stone") == 3)
            assert 1 <= drops <= 2 * SMALL.objects_each


def test_no_task_is_reached_with_its_wrong_objects_alone():
    """Every task of sim/tasks (but crows.json, the goal trials' file): from the trial's start the functional option
    reaches in exactly drops_to_reach drops, and objects_each drops of any one wrong option never reach."""
    from sim.apparatus import outcome
    p = Protocol()
    for f in sorted(TASKS.glob("*.json")):
        if f.stem == "crows":
            continue
        task = load_task(f)
        for tube, obj in task.options():
            levels = battery.trial_levels(task, p)
            good = (tube.name, obj.name) in set(task.correct)
            for d in range(1, p.objects_each + 1):
                o = outcome(task, levels, tube, obj)
                levels = o["levels"]
                if good:
                    assert o["reached"] == (d >= p.drops_to_reach), (f.stem, d)
                else:
                    assert not o["reached"], (f.stem, tube.name, obj.name, d)


def test_test_objects_are_perceived_with_the_sensor_noise_and_the_cup_as_hollow():
    """Each drop sees the objects anew through sim.sensor_model (its sd): two looks at the stone differ, within
    5 sd of the truth; the cup's fill is its walls over its box (9.90 / 45 cm^3 = 0.220), the solid's pi / 4."""
    from sim.sensor_model import SensorModel
    task = load_task(TASKS / "solid_vs_hollow.json")
    cup = next(o for o in task.objects if o.hollow)
    walls = math.pi / 4 * (9 * 5 - 2.6 ** 2 * 4.8)
    assert cup.fill == pytest.approx(walls / 45.0) and cup.fill == pytest.approx(0.2199, abs=1e-3)
    assert next(o for o in task.objects if not o.hollow).fill == pytest.approx(math.pi / 4)
    seen = []

    def look(task_, tube, obj_seen, levels):
        seen.append(obj_seen)
        return battery.perceive_option(task_, tube, obj_seen, levels)
    play(make_subjects("paper", "naive", 1, 1, protocol=SMALL), task, trials=2, protocol=SMALL, look=look)
    fills = [m["fill"] for m in seen if m["mass_g"] < 60]
    masses = [m["mass_g"] for m in seen if m["mass_g"] > 60]
    sd = SensorModel()
    assert len(set(masses)) == len(masses) > 1
    assert all(abs(x - 100.0) < 5 * sd.mass_sd_g for x in masses)
    assert all(abs(x - cup.fill) < 5 * sd.fill_sd + 0.01 for x in fills)


def test_the_expected_p_correct_is_the_softmax_of_the_values():
    assert battery.softmax_probs([0.0, 3.0 * math.log(3)], 3.0) == pytest.approx([0.25, 0.75])
    # the NaN is valued as the mean of the known values (1): weights e, 1, e^2
    z = 1 + math.e + math.e ** 2
    assert battery.softmax_probs([float("nan"), 0.0, 2.0], 1.0) == pytest.approx([math.e / z, 1 / z, math.e ** 2 / z])
    assert battery.softmax_probs([float("nan")] * 2, 1.0) == pytest.approx([0.5, 0.5])


def test_a_choice_aims_at_the_rewards_gap():
    """high vs low water: two tubes alike but for their level, one stone. The predicted rises of a subject that
    knows neither tube tie closely; the values differ by the gaps (3.5 cm = 350 units at a temperature of 3): the
    high tube is chosen with P > 0.99 on every first drop. aim must be one of AIMS."""
    task = load_task(TASKS / "high_vs_low_water.json")
    r = play(make_subjects("paper", "naive", 1, 2, protocol=SMALL), task, trials=3, protocol=SMALL)
    assert all(p > 0.99 for subject in r["p_right"] for p in subject)
    with pytest.raises(ValueError, match="aim"):
        play(make_subjects("paper", "naive", 1, 1, protocol=SMALL), task, trials=1, aim="nearest")


def test_subjects_are_independent_with_maps_of_their_own():
    """Two subjects' maps come from their own seeds (they differ); a batch of one subject of seed s perceives,
    recalls and predicts as a plain Agent of seed s, bit for bit."""
    from aesop_torch.agent import Agent
    from train.battery.subject_maps import OwnMapsAgent
    c = make_config("contextual", seed=7, extra=0)
    two = OwnMapsAgent.of_seeds(c, [7, 8])
    assert not torch.equal(two.map_sets[0]["weight"].weights, two.map_sets[1]["weight"].weights)
    one, ref = OwnMapsAgent.of_seeds(c, [7]), Agent(c, batch=1)
    no = torch.zeros(1, dtype=torch.bool)
    life = battery.jar_world(7, 8)
    for e in life:
        for ag in (one, ref):
            ag.step(battery.stack([e[0]]), torch.tensor([e[1]]), no, torch.tensor([e[2]]), sank=torch.tensor([e[3]]))
    m = battery.stack([life[0][0], life[3][0]])
    assert torch.equal(one.select([0, 0]).predict(m), ref.select([0, 0]).predict(m))
    assert torch.equal(one.memory.patterns, ref.memory.patterns)


def test_pretraining_runs_to_its_criterion():
    """Each subject's pre-training trials: it stops at the first run of `criterion` trials solved with the fewest
    drops (drops_to_reach, every drop the largest stone); the log holds its drops."""
    s = make_subjects("paper", "naive", 3, 2, protocol=SMALL)
    for b, n in enumerate(s.pretrain_trials):
        assert n is not None and SMALL.criterion <= n <= SMALL.max_pretrain_trials
        drops = [w for p, _, w in s.log[b] if p == "pretraining"]
        assert drops[-SMALL.drops_to_reach * SMALL.criterion:] == ["pebble_large"] * (SMALL.drops_to_reach
                                                                                      * SMALL.criterion)


def test_an_experienced_subject_has_lived_its_jar_life():
    """The jar life is the Crow and Pitcher experiment: N generated objects, each an episode step (the log), before
    the pre-training; a naive subject has the pre-training alone."""
    e = make_subjects("paper", "experienced", 1, 2, protocol=SMALL)
    n = make_subjects("paper", "naive", 1, 2, protocol=SMALL)
    assert [p for p, _, _ in e.log[0]][:6] == ["jar"] * 6
    assert set(p for p, _, _ in e.log[0][6:]) == {"pretraining"}
    assert set(p for p, _, _ in n.log[0]) == {"pretraining"}
    assert e.log[0][:6] != e.log[1][:6]                     # each subject its own jar life
    assert int(e.agent.memory.count.min()) > int(n.agent.memory.count.max())
    with pytest.raises(ValueError, match="kind"):
        make_subjects("paper", "wise", 1, 1)


def test_bench_help():
    r = subprocess.run([sys.executable, str(ROOT / "benches" / "battery.py"), "--help"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and "--ablate" in r.stdout and "--record" in r.stdout and "--models" in r.stdout


def bench_module():
    import importlib.util
    spec = importlib.util.spec_from_file_location("battery_bench", ROOT / "benches" / "battery.py")
    sys.path.insert(0, str(ROOT / "benches"))
    try:
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(ROOT / "benches"))
    return module


def bench_model() -> str:
    return bench_module().MODEL


def test_record_rewrites_the_battery_table_and_nothing_else(tmp_path):
    bench = bench_module()
    f = tmp_path / "BENCHMARKS.md"
    f.write_text("a\n<!-- table:battery -->\nold table\n<!-- /table:battery -->\nb\n<!-- bench:battery -->\nraw\n")
    bench.write_table_block("new table\n", f)
    assert f.read_text() == ("a\n<!-- table:battery -->\nnew table\n<!-- /table:battery -->\nb\n"
                             "<!-- bench:battery -->\nraw\n")   # the raw block is record.py's, left as it is
    g = tmp_path / "OTHER.md"
    g.write_text("no block\n")
    with pytest.raises(ValueError, match="table:battery"):
        bench.write_table_block("x", g)
    assert g.read_text() == "no block\n"
    assert "<!-- table:battery -->" in (ROOT / "BENCHMARKS.md").read_text()


@pytest.mark.timeout(300)
def test_bench_last_line_on_a_tiny_run(tmp_path):
    """2 subjects, 2 trials, one task and one conflict task, the transfer model with its rules on and off: ~20 s of
    CPU (--quick's 8 jar objects)."""
    r = subprocess.run([sys.executable, str(ROOT / "benches" / "battery.py"), "--quick", "--tasks",
                        "sinking_vs_floating", "large_light_vs_small_heavy", "--trials", "2", "--workers", "1",
                        "--out", str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=280)
    assert r.returncode == 0, r.stderr
    last = r.stdout.splitlines()[-1]
    g = r"-?\d\.\d\d"
    rate = r"(0\.\d\d|1\.00)"
    m = bench_model()   # the transfer model, one constant in the bench
    assert re.fullmatch(rf"transfer_gain_{m}={g} \[{g}, {g}\] transfer_gain_{m}_rules_off={g} \[{g}, {g}\] "
                        rf"conflict_trial1_experienced={rate} conflict_trial1_experienced_rules_off={rate} "
                        rf"conflict_trial1_naive={rate} learned_tasks_naive_{m}=[01]/1 crows_agreement=[01]/1 "
                        rf"pass_everything_agreement=1/1 subjects=2", last), last
    assert (tmp_path / "battery_curves.png").stat().st_size > 0
    assert "before trial 1: 0" in r.stdout


def test_bench_refuses_an_unknown_model_in_one_line(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "benches" / "battery.py"), "--models", "oracle", "--out",
                        str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "oracle" in r.stderr
    assert not list(tmp_path.iterdir())


def test_the_chosen_options_anticipation_is_the_steps_own():
    """play anticipates every option in one batch of subject copies and hands the chosen row to Agent.step
    (OwnMapsAgent.give): the row equals what step would recompute from the same activities and state, bit for bit;
    a given anticipation is used once, and only for exactly its activities."""
    from train.battery.subject_maps import OwnMapsAgent, rows_of
    agent = OwnMapsAgent.of_seeds(make_config("contextual", seed=7, extra=0), [7, 8])
    no = torch.zeros(2, dtype=torch.bool)
    lives = [battery.jar_world(7, 6), battery.jar_world(8, 6)]
    for t in range(6):
        ep = [life[t] for life in lives]
        agent.step(battery.stack([e[0] for e in ep]), torch.tensor([e[1] for e in ep]), no,
                   torch.tensor([e[2] for e in ep]), sank=torch.tensor([e[3] for e in ep]))
    m = battery.stack([lives[0][0][0], lives[0][3][0], lives[1][1][0], lives[1][4][0]])
    view = agent.select([0, 0, 1, 1])
    ant = view.anticipate_acts(*view.activities(m))
    given = rows_of(ant, [1, 2])
    fresh = agent.anticipate_acts(given.acts, given.present)
    for f in ("expected", "rewards", "fates", "by_fate", "p_sink"):
        assert torch.equal(torch.nan_to_num(getattr(fresh, f), 99.0), torch.nan_to_num(getattr(given, f), 99.0)), f
    assert torch.equal(fresh.recall.episodes, given.recall.episodes)
    assert torch.equal(fresh.recall.strength, given.recall.strength)
    assert all(torch.equal(fresh.values[k], given.values[k]) for k in fresh.values)
    agent.give(given)
    assert agent.anticipate_acts(given.acts, given.present) is given
    assert agent.anticipate_acts(given.acts, given.present) is not given        # once
    agent.give(given)
    assert agent.anticipate_acts(given.acts + 1e-3, given.present) is not given  # other activities: recalled


def test_play_reusing_the_chosen_anticipation_is_play_recomputing_it(monkeypatch):
    """The reuse changes nothing: the same subjects play the same trials with Agent.step recalling again (give a
    no-op) and get the same expected P(correct) and choices, bit for bit."""
    from train.battery.subject_maps import OwnMapsAgent
    task = load_task(TASKS / "conflict_sinking_vs_floating.json")
    s = make_subjects("contextual", "experienced", 2, 2, protocol=SMALL)
    r = play(s.select(), task, trials=2, protocol=SMALL)
    monkeypatch.setattr(OwnMapsAgent, "give", lambda self, a: None)
    again = play(s.select(), task, trials=2, protocol=SMALL)
    assert r["p_right"] == again["p_right"] and r["choices"] == again["choices"]


def test_a_battery_subjects_recall_is_bounded_by_the_protocol():
    """Protocol.max_recalls bounds every recall of a battery subject (the models' own is unbounded); None leaves the
    model's."""
    from dataclasses import replace
    s = make_subjects("contextual", "experienced", 1, 1, protocol=replace(SMALL, max_recalls=3))
    assert s.agent.config.memory.max_recalls == 3
    m = battery.stack([battery.jar_world(1000, 6)[0][0]])
    assert int(s.agent.anticipate(m).recall.valid.sum()) == 3
    free = make_subjects("contextual", "experienced", 1, 1, protocol=replace(SMALL, max_recalls=None))
    assert free.agent.config.memory.max_recalls is None
    assert int(free.agent.anticipate(m).recall.valid.sum()) > 3                 # unbounded, it brings back more
    assert battery.AgentConfig.named("contextual").memory.max_recalls is None


def test_conflict_tasks_run_the_probe_trials():
    """The bench runs Protocol.trials trials of a study's task and probe_trials of a conflict task (a transfer
    probe)."""
    bench = bench_module()
    out = bench._job(([("paper", (), "naive")], [5], ["sinking_vs_floating", "large_light_vs_small_heavy"], "gap", 6,
                      3, 2, 16))
    assert [len(r) for r in out[("paper", (), "naive", "sinking_vs_floating")]["right"]] == [3]
    assert [len(r) for r in out[("paper", (), "naive", "large_light_vs_small_heavy")]["right"]] == [2]


def test_the_readme_block_is_the_conflict_tasks_trial_1_and_gains():
    """README.md's battery block: per conflict task trial 1 of each condition and the paired gains (by hand: two
    subjects, experienced - naive = 0.4 and 0.2, mean 0.30; rules off - naive = -0.1 twice)."""
    bench = bench_module()
    t, M = "large_light_vs_small_heavy", "contextual"
    t1 = {"naive": [0.5, 0.7], "experienced": [0.9, 0.9], "off": [0.4, 0.6]}
    from train.battery.analysis import mean_interval
    merged = {}
    for key, ab, kind in (("naive", (), "naive"), ("experienced", (), "experienced"), ("off", ("rules",), "experienced")):
        merged[(M, ab, kind, t)] = {"t1": mean_interval(t1[key]), "seeds": [1, 2], "p_right": [[p] for p in t1[key]]}
    text = bench.readme_block(merged, M, [t], "LAST", 2, "python benches/battery.py")
    row = [x for x in text.splitlines() if x.startswith("| large light")][0]
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1].startswith("0.60 ") and cells[2].startswith("0.90 ") and cells[3].startswith("0.50 ")
    assert cells[4].startswith("0.30 ") and cells[5] == "-0.10 [-0.10, -0.10]"
    assert text.endswith("Last line: `LAST`")
    assert "<!-- table:battery -->" in (ROOT / "README.md").read_text()


def test_record_refuses_a_partial_configuration(tmp_path):
    """--record writes the README's and BENCHMARKS' battery blocks from the full configuration only: a partial one
    (here a short jar life) is refused in one line before any work, nothing written."""
    before = (ROOT / "BENCHMARKS.md").read_text(), (ROOT / "README.md").read_text()
    r = subprocess.run([sys.executable, str(ROOT / "benches" / "battery.py"), "--record", "--jar-objects", "6"],
                       capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "full configuration" in r.stderr
    assert ((ROOT / "BENCHMARKS.md").read_text(), (ROOT / "README.md").read_text()) == before
