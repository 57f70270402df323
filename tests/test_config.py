"""train/common/config.py: one config for a run (the agent's and the world's), from a TOML file and --set, every refusal one
line naming the key; and summary.json's commit and versions (train/runner/summary.py). In-process: the runner's own
refusals and a full run are in tests/test_run_cli.py."""

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from aesop_torch.agent import AgentConfig
from sim.objects import parse_objects
from sim.world import WorldConfig
from train.common.config import (RANGES, ConfigError, RunConfig, apply_overrides, apply_world_overrides, check_world,
                          config_dict, first_difference, flatten, load_toml, parse_set, resolve)

ROOT = Path(__file__).resolve().parents[1]


def sets(*texts) -> dict:
    return dict(parse_set(t) for t in texts)


def refusal(fn, *args) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        fn(*args)
    assert "\n" not in str(info.value)
    return info.value


# -- --set -------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("text, key, value", [
    ("rules.uncertain_decay=1.0", "rules.uncertain_decay", 1.0),
    ("memory.max_episodes=100", "memory.max_episodes", 100),
    ("recall_sharpness=8", "recall_sharpness", 8),
    ("model=extended", "model", "extended"),                     # a bare word is a string
    ("memory.max_recalls=none", "memory.max_recalls", "none"),
    ("hub.when_full=forget_oldest", "hub.when_full", "forget_oldest"),
    ('hub.word_map="a b"', "hub.word_map", "a b"),
    ("names_in_cue=true", "names_in_cue", True),
    ('ablate=["rules", "gating"]', "ablate", ["rules", "gating"]),
    ("delta_p_band=[[0.1, 0.2], [0.1, 0.2], [0.03, 0.08], [0.05, 0.2]]", "delta_p_band",
     [[0.1, 0.2], [0.1, 0.2], [0.03, 0.08], [0.05, 0.2]]),
    ("world.mass_noise_g = 5", "world.mass_noise_g", 5),
    ("rules.uncertain_decay=abc", "rules.uncertain_decay", "abc"),   # refused by the field, not by the syntax
])
def test_set_reads_a_toml_value_or_a_bare_word(text, key, value):
    assert parse_set(text) == (key, value)


@pytest.mark.parametrize("text, words", [
    ("rules.uncertain_decay", ["KEY=VALUE"]),
    ("=1", ["not a key"]),
    ("rules..x=1", ["not a key"]),
    ("rules.uncertain_decay=", ["no value"]),
    ("hub.word_map=a b", ["not a TOML value", "quoted"]),
    ("x=1\ny=2", ["one line"]),
    ("x=" + "[" * 5000, ["x"]),
])
def test_malformed_set_is_refused_in_one_line(text, words):
    e = refusal(parse_set, text)
    assert all(w in str(e) for w in words), str(e)


# -- the agent's keys --------------------------------------------------------------------------------------------------

def test_every_part_of_the_agents_config_is_reached_and_the_input_left_alone():
    base = AgentConfig.paper()
    c = apply_overrides(base, sets("rules.uncertain_decay=1.0", "memory.max_episodes=100", "recall_sharpness=8",
                                   "hub.match_threshold=0.9", "encoder.max_aspect=3", "som_epochs=5",
                                   "memory.max_recalls=7", "compare_with=none"))
    assert (c.rules.uncertain_decay, c.memory.max_episodes, c.recall_sharpness, c.hub.match_threshold) == \
        (1.0, 100, 8.0, 0.9)
    assert (c.encoder.max_aspect, c.som_epochs, c.memory.max_recalls, c.compare_with) == (3.0, 5, 7, None)
    assert isinstance(c.recall_sharpness, float) and isinstance(c, AgentConfig)
    assert config_dict(base) == config_dict(AgentConfig.paper())          # a new config; the given one unchanged
    assert c.memory is not base.memory and c.hub is not base.hub          # nothing shared to be mutated later


def test_the_sweep_runners_call():
    c = apply_overrides(AgentConfig.named("extended", ablate=("rules",)), {"rules.uncertain_decay": 1.0})
    assert (c.model, c.ablate, c.compare_with, c.rules.uncertain_decay) == ("extended", ("rules",), None, 1.0)
    # lists for tuples, as a TOML (or JSON) reader gives them; a nested dict reads as a table
    c = apply_overrides(AgentConfig.paper(), {"memory": {"max_recalls": None, "cue_power": 8},
                                              "delta_p_band": [[0, 0.1]] * 4})
    assert (c.memory.max_recalls, c.memory.cue_power, c.delta_p_band) == (None, 8.0, ((0.0, 0.1),) * 4)


def test_a_model_switch_takes_the_models_defaults_and_keeps_what_was_changed():
    c = apply_overrides(AgentConfig.paper(recall_sharpness=4.0), {"model": "extended"})
    assert (c.model, c.compare_with, c.recall_sharpness) == ("extended", None, 4.0)   # as AgentConfig.extended()
    c = apply_overrides(AgentConfig.paper(), {"compare_with": 3, "model": "extended"})
    assert c.compare_with == 3                                                       # given: kept, whatever order
    c = apply_overrides(AgentConfig.extended(), {"model": "paper"})
    assert config_dict(c) == config_dict(AgentConfig.paper())
    e = refusal(apply_overrides, AgentConfig.extended(ablate=("prior",)), {"model": "paper"})
    assert e.key == "ablate" and "prior" in str(e)


@pytest.mark.parametrize("text, message", [
    # wrong types: a string for a float, a float for an int, a list for a scalar, a bool for a number, and back
    ("rules.uncertain_decay=abc", "rules.uncertain_decay takes a number (float), got 'abc'"),
    ("memory.max_episodes=1.5", "memory.max_episodes takes an integer (int), got 1.5"),
    ("memory.max_episodes=1.0", "memory.max_episodes takes an integer (int), got 1.0"),
    ("recall_sharpness=[8]", "recall_sharpness takes a number (float), got [8]"),
    ("recall_sharpness=true", "recall_sharpness takes a number (float), got true"),
    ("names_in_cue=1", "names_in_cue takes true or false (bool), got 1"),
    ("model=1", "model takes a string (str), got 1"),
    ("delta_p_band=0.1", "delta_p_band takes an array of [number, number] arrays, got 0.1"),
    ('memory.row_k=["a"]', "memory.row_k takes an array of integers, finite numbers, got memory.row_k[0] = 'a'"),
    ("compare_with=2.5", "compare_with takes an integer (int) or none, got 2.5"),
    ("compare_with=nothing", "compare_with takes an integer (int) or none, got 'nothing'"),
    # out of range: numbers no field takes, bounds the field's meaning gives, and the dataclasses' own checks
    ("rules.uncertain_decay=nan", "rules.uncertain_decay takes a finite number, got nan"),
    ("readout_huber=inf", "readout_huber takes a finite number, got inf"),
    ("rules.same_rel=-0.1", "rules.same_rel takes a number (float) >= 0, got -0.1"),
    ("memory.max_episodes=-1", "memory.max_episodes takes an integer (int) from 0 to 2000, got -1"),
    ("rules.certainty_step=1.5", "rules.certainty_step takes a number (float) from 0 to 1, got 1.5"),
    ("recall_sharpness=0", "recall_sharpness: AgentConfig.recall_sharpness must be > 0"),
    ("memory.cue_rows=[25]", "memory.cue_rows: MemoryConfig.cue_rows must be distinct rows in 0..19"),
    ("hub.when_full=never", "hub.when_full: HubConfig.when_full must be one of refuse"),
    ('ablate=["prior"]', "ablate: 'prior' is no ablation of the paper model (it has: rules, gating)"),
    ("model=bayes", "model: unknown model 'bayes' (known: paper, contextual, extended)"),
    ("delta_p_band=[[0.2, 0.1], [0, 1], [0, 1], [0, 1]]", "delta_p_band: AgentConfig.delta_p_band needs 4"),
    ("hub.n_neurons=40", "hub.n_neurons: the agent's object hub is the sheet's 12 object rows"),
    ("seed=-1", "seed takes an integer (int) from 0 to"),
    # unknown keys, each naming what its table has
    ("rules.bogus=1", "unknown key rules.bogus (rules has: eliminated_strength, dominant_strength"),
    ("bogus=1", "unknown key bogus (the top level has: encoder, hub, memory, rules, som_samples"),
    ("uncertain_decay=1", "did you mean rules.uncertain_decay?"),
    ("rules=1", "rules is a table of settings, not a value"),
    ("rules.uncertain_decay.x=1", "unknown key rules.uncertain_decay.x (rules.uncertain_decay is a value"),
    ("world.mass_noise_g=5", "world.mass_noise_g is a key of the world's config, not the agent's"),
])
def test_a_bad_agent_key_or_value_is_refused_in_one_line_naming_the_key(text, message):
    key, value = parse_set(text)
    e = refusal(apply_overrides, AgentConfig.paper(), {key: value})
    assert message in str(e), str(e)
    assert e.key == key


def test_tuples_take_arrays_of_their_structure():
    c = apply_overrides(AgentConfig.paper(), sets('ablate=["rules", "rules"]', "memory.cue_rows=[1, 9]"))
    assert c.ablate == ("rules",) and c.memory.cue_rows == (1, 9)
    e = refusal(apply_overrides, AgentConfig.paper(), sets("delta_p_band=[[0.1], [0.1], [0.1], [0.1]]"))
    assert "delta_p_band[0] is [0.1]" in str(e)


# -- the world's keys and the whole config -----------------------------------------------------------------------------

def test_the_worlds_config_is_reached_under_world():
    w = apply_world_overrides(WorldConfig(), sets("world.mass_noise_g=5", "world.tank.water.density=998",
                                                  "world.robot.max_velocity=0.5", "world.ik.restarts=3",
                                                  "world.camera.width=128", "world.jar_xy=[0.3, 0.05]",
                                                  'world.robot.body_posture=[["neck_pitch", -0.4]]'))
    assert (w.mass_noise_g, w.tank.water.density, w.robot.max_velocity, w.ik.restarts, w.camera.width) == \
        (5.0, 998.0, 0.5, 3, 128)
    assert w.jar_xy == (0.3, 0.05) and w.robot.body_posture == (("neck_pitch", -0.4),)
    assert WorldConfig().mass_noise_g == 1.0
    for text, message in (("world.level_noise_cm=-1", "world.level_noise_cm takes a number (float) >= 0"),
                          ("world.jar_xy=[0.3]", "world.jar_xy takes an array of 2 numbers, got [0.3]"),
                          ("world.tank.staves=2", "world.tank.staves takes an integer (int) from 3 to 256"),
                          ("world.bogus=1", "unknown key world.bogus (world has: tank, robot"),
                          ("world.tank=1", "world.tank is a table of settings"),
                          ("rules.uncertain_decay=1", "is not a key of the world's config")):
        e = refusal(apply_world_overrides, WorldConfig(), sets(text))
        assert message in str(e), str(e)


def test_resolve_takes_both_later_values_winning_and_gives_plain_data_that_resolves_back():
    rc = resolve({"rules.uncertain_decay": 0.5, "world.mass_noise_g": 5, "model": "extended",
                  "rules": {"uncertain_decay": 0.25}})
    assert isinstance(rc, RunConfig) and rc.agent.rules.uncertain_decay == 0.25 and rc.world.mass_noise_g == 5.0
    assert rc.agent.compare_with is None                      # the extended model's
    data = config_dict(rc)
    assert json.loads(json.dumps(data)) == data               # JSON as it is: lists, null, numbers, strings
    assert data["world"]["mass_noise_g"] == 5.0 and data["rules"]["uncertain_decay"] == 0.25
    assert data["compare_with"] is None and data["delta_p_band"][0] == [0.08, 0.15]
    assert config_dict(resolve(flatten(data))) == data        # a summary's config is a config
    assert first_difference(data, config_dict(resolve({}))) == "rules.uncertain_decay"
    e = refusal(resolve, {"sensor.mass_noise_g": 5})
    assert "did you mean world.mass_noise_g?" in str(e) and "world" in str(e).split("has: ")[1]


def test_every_range_names_a_field():
    leaves = flatten(config_dict(RunConfig.default()))
    assert sorted(k for k in RANGES if k not in leaves) == []


def test_a_world_the_workers_could_not_build_is_refused_first():
    objects = parse_objects({"train": [{"name": "a", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5],
                                        "mass_g": 420}]})
    check_world(WorldConfig(), objects)
    for text, key in (("world.tank.ball_diameter_cm=9", "world.tank.ball_diameter_cm"),
                      ("world.tank.ball_diameter_cm=12", "world.tank.ball_diameter_cm"),
                      ('world.robot.body_posture=[["r_elbow", 0.1]]', "world.robot.body_posture"),
                      ('world.robot.body_posture=[["neck_pitch", 9]]', "world.robot.body_posture")):
        world = resolve(sets(text)).world
        e = refusal(check_world, world, objects)
        assert e.key == key, str(e)
    # in 3 cm of water a 4 cm ball of 30 g would lie on the bottom (a draft of its whole diameter)
    shallow = parse_objects({"jar": {"water_depth_cm": 3.0}, "train": [
        {"name": "a", "shape": "cube", "color": "red", "dims_cm": [2.0], "mass_g": 20}]})
    check_world(WorldConfig(), shallow)
    e = refusal(check_world, resolve(sets("world.tank.ball_mass_g=30")).world, shallow)
    assert e.key == "world.tank" and "deep" in str(e), str(e)


# -- TOML files --------------------------------------------------------------------------------------------------------

def test_a_toml_file_mirrors_the_dataclasses(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text('model = "extended"\nablate = ["rules"]\nrecall_sharpness = 8\n\n[rules]\nuncertain_decay = 1.0\n\n'
                 '[memory]\nmax_recalls = "none"\n\n[world]\nmass_noise_g = 5\n\n[world.tank.water]\ndensity = 998\n')
    items = load_toml(f)
    assert items == {"model": "extended", "ablate": ["rules"], "recall_sharpness": 8, "rules.uncertain_decay": 1.0,
                     "memory.max_recalls": "none", "world.mass_noise_g": 5, "world.tank.water.density": 998}
    rc = resolve(items)
    assert (rc.agent.model, rc.agent.ablate, rc.agent.recall_sharpness, rc.agent.rules.uncertain_decay) == \
        ("extended", ("rules",), 8.0, 1.0)
    assert rc.agent.memory.max_recalls is None and rc.world.tank.water.density == 998.0


def test_bad_toml_files_are_refused_in_one_line(tmp_path):
    cases = {"malformed.toml": ("[rules\nuncertain_decay = 1\n", "not valid TOML"),
             "latin1.toml": (b"model = \"caf\xe9\"\n", "not UTF-8"),
             "deep.toml": ("x = " + "[" * 100_000 + "]" * 100_000 + "\n", "not a file this config reads"),
             "big.toml": ("# " + "x" * 1_000_001 + "\n", "larger than 1,000,000 bytes")}
    for name, (text, words) in cases.items():
        f = tmp_path / name
        f.write_bytes(text if isinstance(text, bytes) else text.encode())
        e = refusal(load_toml, f)
        assert str(e).startswith(str(f)) and words in str(e), str(e)
    assert "no such file" in str(refusal(load_toml, tmp_path / "missing.toml"))
    assert "not a regular file" in str(refusal(load_toml, tmp_path))
    os.mkfifo(tmp_path / "fifo")   # no writer: opening it would wait for ever
    assert "not a regular file" in str(refusal(load_toml, tmp_path / "fifo"))


def test_flags_win_over_the_file_and_sets_apply_in_order(tmp_path):
    from train import run
    f = tmp_path / "c.toml"
    f.write_text('model = "extended"\nseed = 3\nablate = ["prior"]\n[rules]\nuncertain_decay = 0.5\n')
    out = ["--out", str(tmp_path / "o")]
    a = run.parse_args(["--config", str(f), *out])
    assert (a.model, a.seed, a.ablate) == ("extended", 3, ["prior"])                     # the file's
    a = run.parse_args(["--config", str(f), "--set", "rules.uncertain_decay=0.9", "--set", "seed=4",
                        "--set", "rules.uncertain_decay=0.7", "--model", "paper", "--ablate", "rules", "--seed", "5",
                        *out])
    assert (a.model, a.seed, a.ablate) == ("paper", 5, ["rules"])                        # the flags'
    rc = resolve(a.overrides)
    assert rc.agent.rules.uncertain_decay == 0.7 and rc.agent.compare_with == 1          # the last --set; paper's
    assert (rc.agent.model, rc.agent.ablate, rc.agent.seed) == ("paper", ("rules",), 5)
    assert a.origins["rules.uncertain_decay"] == "--set rules.uncertain_decay=0.7" and a.origins["seed"] == "--seed"
    a = run.parse_args(["--config", str(f), "--set", "model=paper", "--set", "ablate=[]", *out])
    assert (a.model, a.ablate, a.seed) == ("paper", [], 3)                                # --set over the file
    a = run.parse_args(out)
    assert (a.model, a.ablate, a.seed, a.overrides) == ("paper", [], 0, {})               # no config: as before


# -- summary.json's provenance -----------------------------------------------------------------------------------------

def test_commit_is_unknown_outside_git(tmp_path, monkeypatch):
    from train.runner.summary import git_commit
    assert git_commit(tmp_path) == "unknown"
    monkeypatch.setenv("PATH", str(tmp_path))              # no git at all
    assert git_commit(ROOT) == "unknown"
    assert git_commit(tmp_path / "missing") == "unknown"


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="needs git and a checkout")
def test_commit_describes_the_repository():
    from train.runner.summary import git_commit
    want = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True,
                          text=True).stdout.strip()
    assert git_commit() == want != "unknown"


def test_versions_of_the_libraries():
    import numpy
    import torch

    from train.runner.summary import versions
    v = versions()
    assert set(v) == {"torch", "pybullet", "numpy"} and all(isinstance(x, str) and x for x in v.values())
    assert v["torch"] == str(torch.__version__) and v["numpy"] == numpy.__version__ and v["pybullet"] != "unknown"


def test_a_refused_long_value_is_quoted_cut_to_the_contracts_length():
    """CONTRACTS.md: a refused value is cut to 60 characters, in a --set value and a command-line word alike."""
    from sim.input_files import MAX_SHOWN
    from train.runner.settings import shown
    with pytest.raises(ConfigError) as e:
        parse_set("x" * 200)           # no "=": refused, the text quoted
    quoted = str(e.value).rsplit("got ", 1)[1]
    assert quoted == repr("x" * (MAX_SHOWN - 3) + "...") and MAX_SHOWN == 60
    assert shown("9" * 200) == repr("9" * 57 + "...") and shown("9" * 60) == repr("9" * 60)
