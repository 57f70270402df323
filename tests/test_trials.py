"""Goal trials: the yardsticks by hand, a 2-object trial's choice by hand, water accumulating within a trial (closed
form and physics), the objects file's trials, and the word path (names bound in the hub, imagined from words)."""

import itertools
import math
import re

import pytest
import torch

from aesop_torch import Agent, AgentConfig
from sim.objects import ObjectsFileError, archimedes_cm3, load_objects, parse_objects
from sim.trial import (closed_form_drop, drops_to_goal, fewest_drops, optimal_first, random_drops_mean, reach_cm3,
                       reach_rise_cm)
from train.learning.experiment import Experiment, closed_form_outcomes, stack_measurements
from train.learning.goal_trials import choose, needed_cm3, roomy_copy, run_trials

JAR = {"inner_diameter_cm": 12.0, "height_cm": 19.5, "water_depth_cm": 14.0}
CYL = {"shape": "cylinder", "dims_cm": [6.36, 11.5]}
OBJECTS = {"jar": JAR, "train": [
    {"name": "red_heavy_cylinder", "color": "red", "mass_g": 420, **CYL},
    {"name": "red_light_cylinder", "color": "red", "mass_g": 14, **CYL},
    {"name": "green_heavy_box", "shape": "box", "color": "green", "dims_cm": [4.0, 5.0, 9.0], "mass_g": 300}],
    "pool": [{"name": "blue_heavy_cylinder", "color": "blue", "mass_g": 400, **CYL},
             {"name": "blue_light_cylinder", "color": "blue", "mass_g": 30, **CYL}],
    "trials": [{"stand": ["blue_light_cylinder", "blue_heavy_cylinder"]}]}


def test_reach_volume_by_hand():
    # the 4 cm, 2.7 g ball floats with a cap of depth h holding 2.7 cm^3: pi h^2 (6 - h) / 3 = 2.7 -> h = 0.6973;
    # its top starts at 14 + 4 - 0.6973 = 17.303 cm and is reachable 0.1 cm below the 19.5 cm rim
    jar = parse_objects(OBJECTS).jar
    h = 0.6973
    assert math.pi * h * h * (6 - h) / 3 == pytest.approx(2.7, abs=1e-3)
    assert reach_rise_cm(jar) == pytest.approx(19.5 - 0.1 - (18 - h), abs=1e-3)
    assert reach_cm3(jar) == pytest.approx((19.4 - 18 + h) * math.pi * 36, abs=0.1)


def test_planner_and_random_chooser_by_hand():
    # 300 alone reaches 237: one drop. A random order starts with it 1 time in 3, else needs exactly 2 drops
    # (100 + 300, 100 + 150 = 250, 150 + 300, 150 + 100 = 250): 1/3 + 2 * 2/3 = 5/3
    v = [300.0, 100.0, 150.0]
    assert fewest_drops(v, 237) == 1 and optimal_first(v, 237) == [True, False, False]
    assert random_drops_mean(v, 237) == pytest.approx(5 / 3)
    assert random_drops_mean(v, 237) == pytest.approx(
        sum(drops_to_goal(p, 237) for p in itertools.permutations(v)) / 6)     # the same, counted over all orders
    # none alone, any two: every first choice is optimal
    assert fewest_drops([100.0, 150.0, 120.0], 237) == 2 and all(optimal_first([100.0, 150.0, 120.0], 237))
    # never reachable: every order drops everything
    assert fewest_drops([10.0, 20.0], 237) == 2 and random_drops_mean([10.0, 20.0], 237) == 2


def test_water_accumulates_within_a_trial_closed_form():
    outcomes = {"a": {"observed_cm3": 150.0, "sank": True}, "b": {"observed_cm3": 100.0, "sank": False}}
    drop = closed_form_drop(outcomes, 237.0)
    # one call answers every agent's sequence; the second drop starts from the water the first left: 150 + 100 = 250
    assert drop([("a",), ("a", "b")]) == [
        {"observed_cm3": 150.0, "goal_before": False, "goal_after": False, "sank": True},
        {"observed_cm3": 100.0, "goal_before": False, "goal_after": True, "sank": False}]
    assert drop([("b",)])[0]["goal_after"] is False


def test_objects_file_trials_and_pool():
    objs = parse_objects(OBJECTS)
    assert objs.trials == [("blue_light_cylinder", "blue_heavy_cylinder")] and objs.get("blue_heavy_cylinder")
    assert set(objs.canonical()) == {"jar", "train", "probe", "pool", "trials"}
    plain = parse_objects({k: v for k, v in OBJECTS.items() if k not in ("pool", "trials")})
    assert set(plain.canonical()) == {"jar", "train", "probe"}        # a file without them: as it always was
    for bad, words in [({"stand": []}, "1 to 8"), ({"stand": ["nope"]}, '"nope" is not an object'),
                       ({"stand": ["red_heavy_cylinder"] * 2}, "twice"), ({"stand": "red"}, "list"),
                       ({"stand": ["red_heavy_cylinder"], "x": 1}, "unknown key 'x'"), ([], "must be an object")]:
        with pytest.raises(ObjectsFileError, match=words):
            parse_objects({**OBJECTS, "trials": [bad]})
    with pytest.raises(ObjectsFileError, match="duplicate name"):
        parse_objects({**OBJECTS, "pool": OBJECTS["pool"] + [OBJECTS["train"][0]]})


@pytest.fixture(scope="module", params=["paper", "extended"])
def explored(request):
    """One order's agent after the three train objects, closed form (every object displaces its Archimedes volume);
    each model."""
    objs = parse_objects(OBJECTS)
    every = parse_objects({**OBJECTS, "train": OBJECTS["train"] + OBJECTS["pool"], "pool": [], "trials": []})
    outcomes, _ = closed_form_outcomes(every, reachable_above_cm3=reach_cm3(objs.jar))
    exp = Experiment([o["name"] for o in OBJECTS["train"]], [], [[0, 1, 2]],
                     config=AgentConfig.named(request.param, som_samples=2000, som_epochs=10))
    exp.outcomes = {n: outcomes[n] for n in exp.train_names}
    while not exp.done:
        exp.step(lambda name, b, t: outcomes[name])
    return exp, objs, outcomes


def test_two_object_trial_chooses_what_closes_the_gap_by_hand(explored):
    exp, objs, outcomes = explored
    # by hand: the ball needs 237 cm^3; the 400 g cylinder sinks and displaces 365 (one drop), the 30 g one floats
    # and displaces 30 (it would need the other after it): the right first choice is the heavy one. The agent saw a
    # 420 g and a 14 g cylinder of this size (and a box): it must expect more of the heavy one
    need = reach_cm3(objs.jar)
    assert 30 < need < archimedes_cm3(objs.get("blue_heavy_cylinder"), objs.jar)
    # the agent's own estimate of the need, from memory: between 180 (the box, ball out of reach) and 365 (reached)
    assert float(needed_cm3(exp.agent)[0]) == pytest.approx((180 + 365.3) / 2, rel=0.02)
    stand = objs.trials[0]
    arch = {n: archimedes_cm3(objs.get(n), objs.jar) for n in stand}
    meas = {n: outcomes[n]["measurement"] for n in stand}
    before = {k: v.clone() for k, v in exp.agent.state_dict().items()}
    (rec,), = run_trials(roomy_copy(exp.agent, 2), [stand], meas, closed_form_drop(outcomes, need), objs.jar, arch)
    assert rec["chosen"] == ["blue_heavy_cylinder"] and rec["drops"] == 1 and rec["goal_reached"]
    heavy, light = (float(exp.agent.predict(stack_measurements([meas[n]]))[0]) for n in stand[::-1])
    assert heavy > light and rec["expected_cm3"][0] == pytest.approx(heavy, abs=0.01) and rec["first_choice_optimal"]
    assert (rec["fewest_drops"], rec["random_drops_mean"], rec["excess_drops"]) == (1, 1.5, 0)
    assert 0.5 < rec["recall_strength"][0] <= 1 and 0 <= rec["agreeing_episodes"][0] <= 3
    # the trial learned on a copy: the run's agent (its checkpoint) is as the exploration left it
    assert all(torch.equal(before[k], v) for k, v in exp.agent.state_dict().items())


def test_a_novice_explores_and_water_accumulates_to_the_goal(explored):
    exp, objs, outcomes = explored
    novice = Agent(exp.config, batch=1, develop=False)
    novice.maps = exp.agent.maps
    stand = ("red_light_cylinder", "green_heavy_box", "blue_light_cylinder")
    arch = {n: archimedes_cm3(objs.get(n), objs.jar) for n in stand}
    meas = {n: outcomes[n]["measurement"] for n in stand}
    (rec,), = run_trials(novice, [stand], meas, closed_form_drop(outcomes, reach_cm3(objs.jar)), objs.jar, arch)
    assert rec["explored"][0] and rec["expected_cm3"][0] is None        # nothing recalled: a random first choice
    # 14 + 180 + 30 = 224 < 237: the stand empties, the ball stays out of reach, every object was dropped
    assert rec["drops"] == 3 and not rec["goal_reached"] and sorted(rec["chosen"]) == sorted(stand)
    assert sum(rec["observed_cm3"]) == pytest.approx(sum(arch.values()), abs=0.1)


def test_planner_sequences_by_hand():
    from train.learning.goal_trials import planner_sequences
    # the ball needs 237 cm^3. [30 g float (30), 400 g sinker (365)]: one drop, nothing to simulate ahead.
    # [14 g float (14), box (180), 30 g float (30)]: 224 < 237, so the planner drops all three, the largest first
    objs = parse_objects({**OBJECTS, "trials": [{"stand": ["blue_light_cylinder", "blue_heavy_cylinder"]},
                                                {"stand": ["red_light_cylinder", "green_heavy_box",
                                                           "blue_light_cylinder"]}]})
    assert planner_sequences(objs) == [("green_heavy_box", "blue_light_cylinder", "red_light_cylinder")]


class _ClosedFormPhysics:
    """play_trials' physics in closed form (Archimedes adds up), every job it is handed kept in `jobs`."""

    def __init__(self, outcomes: dict, need_cm3: float):
        self.outcomes, self.need, self.jobs = outcomes, need_cm3, []

    def submit(self, jobs):
        from types import SimpleNamespace
        self.jobs += jobs
        drop = closed_form_drop(self.outcomes, self.need)
        for _, names, _ in jobs:
            yield [SimpleNamespace(observed_cm3=o["observed_cm3"], goal_reachable_before=o["goal_before"],
                                   goal_reached_after=o["goal_after"], sank=o["sank"],
                                   measurement=self.outcomes[n]["measurement"])
                   for n, o in zip(names, drop([names[:k] for k in range(1, len(names) + 1)]))]

    def run(self, jobs):
        return list(self.submit(jobs))


def test_a_sequence_simulated_ahead_is_taken_not_simulated_again(explored):
    """The runner simulates the planner's sequences while its workers would idle: an agent that drops one (or a part
    of one) takes its outcomes from there, and every record is as if it had been simulated when asked."""
    from train.learning.goal_trials import planner_sequences, play_trials
    exp, _, outcomes = explored
    objs = parse_objects({**OBJECTS, "trials": [{"stand": ["red_light_cylinder", "green_heavy_box",
                                                           "blue_light_cylinder"]}]})
    need = reach_cm3(objs.jar)
    first = {n: outcomes[n] for n in objs.trials[0]}   # first drops known (the exploration's), as in the runner
    asked = _ClosedFormPhysics(outcomes, need)
    plain = play_trials(exp, objs, asked, first_drops=first)
    (whole,) = planner_sequences(objs)
    assert plain[0][0]["chosen"] == list(whole)                        # the agent drops what the planner does
    assert [j[1] for j in asked.jobs] == [whole[:2], whole]            # round by round, each from a fresh jar
    ahead = _ClosedFormPhysics(outcomes, need)
    done = next(ahead.submit([("trial", whole, None)]))
    started = {whole: type("Started", (), {"get": lambda self: done})()}   # as Physics.ahead returns it
    ahead.jobs.clear()
    assert play_trials(exp, objs, ahead, first_drops=first, ahead=started) == plain
    assert ahead.jobs == []                                            # its prefix and itself: taken, not simulated


def test_choice_rule_by_hand():
    g = torch.Generator().manual_seed(0)
    # the gap is 200: 250 closes it alone (1 drop), 120 + 90 needs two; ties in drops go to the larger expectation
    assert choose([120.0, 250.0, 90.0], 200.0, g)[:2] == (1, False)
    assert choose([120.0, 250.0, 300.0], 200.0, g)[0] == 2
    assert choose([120.0, 90.0], 200.0, g)[2] == [2.0, 2.0] and choose([120.0, 90.0], 200.0, g)[0] == 0
    # an unknown need: the largest; nothing anticipated: explore
    assert choose([120.0, 250.0], math.inf, g)[0] == 1
    assert choose([math.nan, math.nan], 200.0, g)[1] is True
    # ties in drops go to the largest displacement expected over the fates: a sure 250 before a 300 that floats
    # at 100 with probability 0.4 (average 220); fewer drops still come first
    assert choose([250.0, 300.0], 200.0, g, [250.0, 220.0])[0] == 0
    assert choose([250.0, 300.0], 200.0, g)[0] == 1
    assert choose([150.0, 300.0], 200.0, g, [150.0, 220.0])[0] == 1


def test_physics_water_is_not_reset_between_the_drops_of_a_trial():
    from sim.trial import simulate_sequence
    from sim.world import World
    objs = load_objects("sim/default_objects.json")
    world = World(objs, seed=0)
    try:
        first, second = simulate_sequence(world, ("green_heavy_box", "red_small_heavy_cylinder"))
    finally:
        world.close()
    area = objs.jar.area_cm2
    # the second drop starts at the level the first left (not the start level), and the level keeps both
    assert second.level_before_cm == pytest.approx(first.level_after_cm, abs=0.005)
    assert first.level_before_cm == pytest.approx(objs.jar.water_depth_cm, abs=0.01)
    both = archimedes_cm3(objs.get("green_heavy_box"), objs.jar) + \
        archimedes_cm3(objs.get("red_small_heavy_cylinder"), objs.jar)
    assert (second.level_after_cm - first.level_before_cm) * area == pytest.approx(both, rel=0.03)
    assert second.observed_cm3 == pytest.approx(45.7, rel=0.05) and second.sank
    assert not second.goal_reached_after       # 180 + 46 < 237: still out of reach


def test_trials_play_the_same_on_the_worker_pool_as_in_this_process(explored):
    """The runner simulates the trials' drops on its worker pool, and takes a trial's first drop of an object it
    dropped in the exploration from there: the same outcomes, bit for bit, as simulating them here."""
    from train.learning.experiment import outcome_record
    from train.learning.sim_pool import Physics
    from train.learning.goal_trials import TRIAL_OUTCOME_KEYS, outcome_dict, play_trials
    exp, objs, _ = explored
    here = play_trials(exp, objs, Physics(objs, seed=0, workers=1))   # the pool objects inspected, then dropped
    assert here[0][0]["chosen"] == ["blue_heavy_cylinder"] and here[0][0]["goal_reached"]
    pool = Physics(objs, seed=0, workers=2)
    try:
        explored_drop, trial_drops = pool.run([("drop", "blue_heavy_cylinder", False),
                                                ("trial", ("blue_heavy_cylinder",), None)])
        record = outcome_record(explored_drop)
        # the exploration's drop and the trial's first drop: the same fresh jar and noise seed, every float equal
        assert outcome_dict(trial_drops[0]) == {k: record[k] for k in TRIAL_OUTCOME_KEYS}
        assert play_trials(exp, objs, pool) == here
        assert play_trials(exp, objs, pool, first_drops={"blue_heavy_cylinder": record}) == here
    finally:
        pool.close()


# -- words ------------------------------------------------------------------------------------------------------

def test_word_cue_retro_activates_the_named_objects_units(explored):
    exp, objs, outcomes = explored
    agent = exp.agent
    maps = list(agent.maps)

    def units(name):
        acts, _ = agent.activities(stack_measurements([outcomes[name]["measurement"]]))
        return {p: int(acts[0, maps.index(p)].argmax()) for p in ("color", "shape", "size", "weight")}

    for words, name in (("heavy red cylinder", "red_heavy_cylinder"), ("red light cylinder", "red_light_cylinder"),
                        ("green box", "green_heavy_box")):
        im = agent.imagine(words)
        assert bool(im.known[0]), words
        got = {p: int(im.acts[0, maps.index(p)].argmax()) for p in ("color", "shape", "size", "weight")}
        assert got == units(name), words        # the named object's own winner unit in every property map
        assert float(im.anticipation.expected[0]) == pytest.approx(outcomes[name]["observed_cm3"], rel=0.05)
    # the exact name scores 1; two of its three words 0.82 (cosine of bags of words, sqrt(2/3))
    assert float(agent.imagine("red heavy cylinder").score[0]) == pytest.approx(1.0, abs=1e-4)
    assert float(agent.imagine("green box").score[0]) == pytest.approx(math.sqrt(2 / 3), abs=0.02)
    # words that name no stored object: a clear "not known", no guess; an unknown word: refused
    nothing = agent.imagine("yellow sphere")
    assert not bool(nothing.known[0]) and math.isnan(float(nothing.anticipation.expected[0]))
    with pytest.raises(ValueError, match="unknown word.*'elephant'"):
        agent.imagine("blue elephant")


def test_names_do_not_change_what_an_object_in_view_recalls(explored):
    exp, _, outcomes = explored
    m = stack_measurements([outcomes["blue_heavy_cylinder"]["measurement"]])
    plain, named = exp.agent.anticipate(m), exp.agent.anticipate({**m, "words": ["blue_heavy_cylinder"]})
    assert bool(named.present[0, -1]) and not bool(plain.present[0, -1])
    assert torch.equal(plain.recall.episodes, named.recall.episodes)
    assert torch.equal(plain.recall.strength, named.recall.strength) and torch.equal(plain.expected, named.expected)


def test_ask_cli(tmp_path, capsys):
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    ask = [sys.executable, str(root / "train" / "ask.py"), str(root / "checkpoints" / "default.pt")]
    r = subprocess.run(ask + ["heavy red cylinder"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    last = r.stdout.strip().splitlines()[-1]
    assert last.startswith("expected_cm3=") and float(last.split("=")[1]) == pytest.approx(365, rel=0.06)
    assert "colour red" in r.stdout and "shape cylinder" in r.stdout
    # the rest: the script's main() in this process (the same code, without a torch import per call)
    from train.ask import main as ask_main
    code = ask_main([ask[2], "light blue cube"])
    out, err = capsys.readouterr()
    assert code == 0 and out.strip().splitlines()[-1] == "expected_cm3=unknown"
    code = ask_main([ask[2], "purple elephant"])
    out, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1 and "'elephant'" in err and not out
    code = ask_main([str(tmp_path / "nope.pt"), "red cube"])
    out, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1


# -- the goal in words --------------------------------------------------------------------------------------------

def _two_episodes(explored):
    """A fresh agent (the explored one's maps) that remembers two drops: a 300 cm^3 one that made the ball reachable
    and a 100 cm^3 one that did not (two different objects, so each has its own assembly)."""
    exp, _, outcomes = explored
    agent = Agent(exp.config, batch=1, develop=False)
    agent.maps = exp.agent.maps
    for name, cm3, reached in (("red_heavy_cylinder", 300.0, True), ("green_heavy_box", 100.0, False)):
        agent.remember(stack_measurements([outcomes[name]["measurement"]]), torch.tensor([cm3]),
                       torch.tensor([False]), torch.tensor([reached]), sank=torch.tensor([True]))
    return agent


def test_the_goal_phrase_drives_the_goal_state_word_by_word(explored):
    agent = explored[0].agent
    # the drive is the fraction of the goal's two words heard (each word's pattern has unit length on the word map,
    # and two words' patterns barely overlap: 0.002 on a fully developed map, a few hundredths on this test's
    # quickly trained one): both 1, one 1/2, none 0; other and function words take nothing away
    drive = lambda p: float(agent.hear_goal(p).drive[0])
    assert drive("reach the green ball") == pytest.approx(1.0, abs=1e-6)
    assert drive("ball reach") == pytest.approx(1.0, abs=1e-6)
    assert drive("reach the cube") == pytest.approx(0.5, abs=0.05)
    assert drive("green box") == pytest.approx(0.0, abs=0.05)
    goal = agent.hear_goal("reach the green ball")
    assert bool(goal.known[0]) and not bool(agent.hear_goal("reach the cube").known[0])
    # the cue: the present state (ball out of reach) on the first body row, the goal state x drive on the last
    assert torch.equal(goal.cue[0].bool(), torch.stack([agent.body.encode("goal_unreachable"),
                                                        agent.body.encode("goal_reached")]))
    with pytest.raises(ValueError, match="unknown word.*'fetch'.*the words I know: red .* reach ball the a"):
        agent.hear_goal("fetch the green ball")


def test_the_goal_recalls_the_episodes_that_reached_it_and_the_need_lies_between(explored):
    agent = _two_episodes(explored)
    recall = agent.goal_recall(agent.hear_goal("reach the green ball"))
    rewards = agent.reward.decode(agent._reward_row(recall.episodes))[0]
    # by hand: the episode that reached the goal holds the whole cue (4 of 4 neurons), the other only the start
    # state (2 of 4); both are brought back, exactly as stored, strongest first
    assert recall.valid[0].tolist()[:2] == [True, True] and recall.strength[0, :2].tolist() == [1.0, 0.5]
    assert rewards[:2].tolist() == pytest.approx([300.0, 100.0], rel=0.007)      # the reward code's 0.7 %
    assert torch.equal(recall.episodes[0, :2].sort(0).values, agent.memory.patterns[0, :2].sort(0).values)
    # the need: midway between the recalled miss and the recalled reach, (100 + 300) / 2
    assert float(needed_cm3(agent)[0]) == pytest.approx(200.0, rel=0.007)
    # a phrase without the goal's words recalls nothing and is answered, not guessed
    assert not bool(agent.goal_recall(agent.hear_goal("red heavy cylinder")).any[0])
    with pytest.raises(ValueError, match="'green box' is no goal I know"):
        needed_cm3(agent, "green box")


def test_only_the_goal_reached_sets_the_need(explored):
    # one drop that reached the goal (300) and none that missed below it: the need is that reward itself
    exp, _, outcomes = explored
    agent = Agent(exp.config, batch=1, develop=False)
    agent.maps = exp.agent.maps
    agent.remember(stack_measurements([outcomes["red_heavy_cylinder"]["measurement"]]), torch.tensor([300.0]),
                   torch.tensor([False]), torch.tensor([True]))
    assert float(needed_cm3(agent)[0]) == pytest.approx(300.0, rel=0.007)
    assert math.isinf(float(needed_cm3(Agent(exp.config, batch=1, develop=False))[0]))   # nothing recalled


def test_objects_file_goal():
    trial = {"stand": ["blue_light_cylinder", "blue_heavy_cylinder"]}
    objs = parse_objects({**OBJECTS, "trials": [trial, {**trial, "goal": "Reach the  BALL"},
                                                {**trial, "goal": "reach the green ball"}]})
    # lower case, one space; the default goal is no goal given (the same experiment)
    assert objs.goals == [None, "reach the ball", None]
    assert objs.canonical()["trials"][1] == {**trial, "goal": "reach the ball"} and "goal" not in \
        objs.canonical()["trials"][2]
    for goal, words in [("fetch the ball", "unknown word(s) 'fetch' (the words I know: red green"),
                        ("green box", '"green box" is no goal I know'), ("reach the cube", "no goal I know"),
                        (3, "must be a phrase"), ("  ", "must be a phrase")]:
        with pytest.raises(ObjectsFileError, match=re.escape("trials[0] field 'goal': ") + ".*" + re.escape(words)):
            parse_objects({**OBJECTS, "trials": [{**trial, "goal": goal}]})


def test_run_trials_records_the_goal_and_refuses_one_it_does_not_know(explored):
    exp, objs, outcomes = explored
    stand = objs.trials[0]
    arch = {n: archimedes_cm3(objs.get(n), objs.jar) for n in stand}
    meas = {n: outcomes[n]["measurement"] for n in stand}
    drop = closed_form_drop(outcomes, reach_cm3(objs.jar))
    (rec,), = run_trials(roomy_copy(exp.agent, 2), [stand], meas, drop, objs.jar, arch, goals=["reach the ball"])
    assert rec["goal"] == "reach the ball" and rec["chosen"] == ["blue_heavy_cylinder"]
    with pytest.raises(ValueError, match="'red cube' is no goal I know"):
        run_trials(roomy_copy(exp.agent, 2), [stand], meas, drop, objs.jar, arch, goals=["red cube"])


def test_run_cli_refuses_an_unknown_goal_word_and_writes_nothing(tmp_path):
    import json
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    data = {**OBJECTS, "trials": [{"stand": ["blue_light_cylinder"], "goal": "fetch the green ball"}]}
    f, out = tmp_path / "objects.json", tmp_path / "out"
    f.write_text(json.dumps(data))
    r = subprocess.run([sys.executable, str(root / "train" / "run.py"), "--objects", str(f), "--out", str(out)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and not r.stdout, r.stderr
    assert "trials[0] field 'goal': unknown word(s) 'fetch'" in r.stderr and "reach ball the a" in r.stderr
    assert not out.exists()


def test_a_goal_trial_drop_not_delivered_or_negative_is_never_kept():
    """A goal trial's drop is checked as an episode's: not delivered into the jar, or a negative or non-finite
    volume read, ends the run (BadOutcome) instead of entering the trial's records."""
    from types import SimpleNamespace

    from train.learning.experiment import BadOutcome
    from train.learning.goal_trials import outcome_dict
    ok = dict(observed_cm3=10.0, goal_reachable_before=False, goal_reached_after=False, sank=True,
              measurement={"rgb": [0.5, 0.5, 0.5], "extent_cm": [3.0, 3.0, 3.0], "fill": 1.0, "mass_g": 50.0})
    assert outcome_dict(SimpleNamespace(**ok))["observed_cm3"] == 10.0
    for bad in ({"delivered": False}, {"observed_cm3": -3.0}, {"observed_cm3": float("nan")}):
        with pytest.raises(BadOutcome):
            outcome_dict(SimpleNamespace(**{**ok, **bad}))
