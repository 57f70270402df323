"""Nothing silent, nothing unbounded, no traceback from a config: settings that cannot work together are refused
before anything is written (train/runner/config_checks.py), a drop that measured nothing true ends the run in one line
(train.learning.experiment.check_outcome), and every JSON input is read bounded and strict (sim/input_files.py)."""

import json
import math
import os
import random
import types
from pathlib import Path

import pytest

from in_process import run_main
from sim.input_files import InputFileError, loads, read_json
from sim.objects import ObjectsFileError, load_objects
from train.common.config import ConfigError, load_toml, resolve
from train.runner.config_checks import LEVERS_M, check_run

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = load_objects(ROOT / "sim" / "default_objects.json")
HEAVY = {"name": "red_heavy_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 420}
TINY = {"train": [HEAVY], "probe": [{**HEAVY, "name": "green_light_cylinder", "color": "green", "mass_g": 20}]}


def refusal(overrides: dict, objects=DEFAULT, given=None) -> ConfigError:
    with pytest.raises(ConfigError) as e:
        check_run(resolve(overrides), objects, overrides if given is None else given)
    assert "\n" not in str(e.value)
    return e.value


def run_cli(*args):
    """train/run.py's main() in this process (tests/in_process.py): the run through the CLI without an interpreter."""
    return run_main(*args)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    f = tmp_path_factory.mktemp("tiny") / "tiny.json"
    f.write_text(json.dumps(TINY))
    return f


# -- settings that cannot work together --------------------------------------------------------------------------

def test_the_default_config_passes_every_check():
    check_run(resolve({}), DEFAULT)


@pytest.mark.parametrize("overrides, key, words", [
    # the brief's reproducers: each in range alone
    ({"world.move_timeout_s": 1e-9}, "world.move_timeout_s", ["less than one step", "never move"]),
    ({"world.mass_noise_g": 1e6}, "world.mass_noise_g", ["swamps", "red_heavy_cylinder", "420 g", "at most 105 g"]),
    ({"world.mass_noise_g": 1e308}, "world.mass_noise_g", ["swamps"]),
    ({"encoder.size_min_cm": 50}, "encoder.size_min_cm", ["not below encoder.size_max_cm 30"]),
    ({"world.jar_xy": [100, 100]}, "world.jar_xy", ["cannot reach", "over the jar"]),
    ({"world.stand_height": 100}, "world.stand_height", ["cannot reach", "above the stand"]),
    ({"world.camera.near": 10, "world.camera.far": 0.001}, "world.camera.near", ["not nearer than world.camera.far"]),
    ({"world.camera.near": 10}, "world.camera.near", ["not nearer"]),
    ({"world.tank.timestep_s": 1e-12}, "world.tank.timestep_s", ["steps, more than the 240,000"]),
    ({"world.tank.settle_timeout_s": 1e12}, "world.tank.settle_timeout_s", ["steps, more than the 240,000"]),
    ({"world.tank.water.density": 1e5}, "world.tank.water.density", ["w dt = 8.30", "below 1.5"]),
    # the smallest object of the default file: 'red_light_cylinder', 14 g afloat, 14 cm^3 over the jar's 113.1 cm^2
    ({"world.level_noise_cm": 100}, "world.level_noise_cm", ["'red_light_cylinder'", "0.124 cm rise", "0.0219 cm"]),
    # the encoder's range ends where an object starts: a 420 g object on a range of 1 .. 2 g is far beyond it
    ({"encoder.mass_max_g": 2.0}, "encoder.mass_max_g", ["exclude object", "g)"]),
    # the depth range holds the stand's view, but not the objects seen from above
    ({"world.camera.far": 0.4}, "world.camera.far", ["outside world.camera.near"]),
    # an IK of one iteration reaches nothing: named by the table of settings given
    ({"world.ik.max_iters": 1}, "world.ik", ["cannot reach", "the world.ik settings given"]),
    # the jar through the stand, the stand off the table
    ({"world.jar_xy": [0.2, -0.2]}, "world.jar_xy", ["overlap", "world.stand_xy [0.2, -0.25]"]),
    ({"world.table_y": [-0.25, 0.3]}, "world.table_y", ["world.stand_xy [0.2, -0.25] puts a footprint of radius "
                                                         "4.5 cm off the table"]),
    # the settle's windows outlast its timeout
    ({"world.tank.settle_windows": 1000}, "world.tank.settle_windows", ["nothing could be seen to settle"]),
])
def test_settings_that_cannot_work_together_are_refused_naming_them(overrides, key, words):
    e = refusal(overrides)
    assert e.key == key and str(e).startswith(f"{key}: "), str(e)
    for w in words:
        assert w in str(e), str(e)


@pytest.mark.parametrize("overrides, key, words", [
    # the red-team's (issue 47): each ran, wrongly or into a late failure, or a traceback
    ({"rules.eliminated_strength": 5, "rules.dominant_strength": 0.01}, "rules.eliminated_strength",
     ["rules.eliminated_strength 5 is not <= retro_floor 0.1"]),
    ({"encoder.context": ["width"]}, "encoder.context", ["['width']", "a jar run perceives no context"]),
    ({"world.level_resolution_cm": 50}, "world.level_resolution_cm", ["steps of 50 cm", "0.124 cm rise",
                                                                      "at most 0.0309 cm"]),
    ({"world.min_felt_mass_g": 900}, "world.min_felt_mass_g", ["'red_light_cylinder'", "14 g", "at most 14 g"]),
    ({"memory.cue_rows": [0]}, "memory.cue_rows", ["cues recall with its object hub", "got [0]"]),
    # the rest of each class: strengths and tolerances in the wrong order
    ({"rules.dominant_strength": 1.0}, "rules.dominant_strength", ["1 is not < rules.dominant_strength 1"]),
    ({"rules.uncertain_floor": 0.05}, "rules.uncertain_floor", ["retro_floor 0.1 is not < rules.uncertain_floor"]),
    ({"rules.uncertain_floor": 1.5}, "rules.uncertain_floor", ["rules.uncertain_floor 1.5 is not <= 1"]),
    ({"retro_floor": 0.01}, "retro_floor", ["rules.eliminated_strength 0.05 is not <= retro_floor 0.01"]),
    ({"rules.same_abs_cm3": 5}, "rules.same_abs_cm3", ["above rules.contradiction_abs_cm3 3"]),
    ({"rules.same_rel": 0.5}, "rules.same_rel", ["above rules.contradiction_rel 0.2"]),
    # the sheet's layout: a row's k that refuses the first episode stored, names on another map
    ({"hub.assembly_size": 3}, "hub.assembly_size", ["row 1", "holds 3", "memory.row_k gives it 2"]),
    ({"memory.row_k": [2] * 5 + [2] + [2] * 14}, "memory.row_k", ["row 5", "holds 1", "gives it 2"]),
    ({"hub.word_map": "color"}, "hub.word_map", ["map 'word'"]),
    # the world: gravity the water does not share, water that floats no ball, the arm's posture and links
    ({"world.tank.water.gravity": 3}, "world.tank.water.gravity", ["is not world.tank.gravity 9.81"]),
    ({"world.tank.gravity": 3}, "world.tank.gravity", ["world.tank.gravity 3 m/s^2"]),
    ({"world.tank.water.density": 50}, "world.tank.water.density", ["cannot float the green ball"]),
    ({"world.robot.home_arm": [9] * 10}, "world.robot.home_arm", ["torso_pitch=9 rad is outside"]),
    ({"world.robot.colliding_links": ["nope"]}, "world.robot.colliding_links", ["'nope' is not a link of the iCub"]),
])
def test_settings_that_make_the_readings_or_the_knowledge_meaningless_are_refused(overrides, key, words):
    e = refusal(overrides)
    assert e.key == key and str(e).startswith(f"{key}: "), str(e)
    for w in words:
        assert w in str(e), str(e)


@pytest.mark.parametrize("text, words", [
    ("world.ik.seed=99999999999999999999", "world.ik.seed takes an integer (int) from 0 to 9,223,372,036,854,775,807"),
    ("fate_recalls=99999999999999999999", "fate_recalls takes an integer (int) from 1 to 2000"),
    ("memory.misses=-1", "memory.misses takes an integer (int) from 0 to 1000"),
    ("hub.match_threshold=-5", "hub.match_threshold takes a number (float) from 0 to 1"),
    ("goal_floor=5", "goal_floor takes a number (float) from 0 to 1"),
    ("imagine_floor=0", "imagine_floor takes a number (float) from 0 to 1"),
    ("rules.uncertain_decay=1.5", "rules.uncertain_decay takes a number (float) from 0 to 1"),
    ("rules.contradiction_rel=1", "rules.contradiction_rel takes a number (float) from 0 to below 1"),
    ("memory.threshold=5", "memory.threshold takes a number (float) from 0 to below 1"),
    ("compare_with=0", "compare_with takes an integer (int) from 1 to 2000 or none"),
    ("world.tank.gravity=0", "world.tank.gravity takes a number (float) > 0"),
    ("world.tank.water.gravity=-9.81", "world.tank.water.gravity takes a number (float) > 0"),
    ("world.tank.ball_rgb=[5, 0, 0]", "world.tank.ball_rgb takes an array of 3 numbers, each from 0 to 1"),
    ("world.robot.arm_max_force=[0, 1, 1, 1, 1, 1, 1, 1, 1, 1]", "each > 0, got world.robot.arm_max_force[0] = 0.0"),
])
def test_a_value_out_of_its_meaning_is_refused_by_its_range(text, words):
    from train.common.config import parse_set
    key, value = parse_set(text)
    with pytest.raises(ConfigError) as e:
        resolve({key: value})
    assert words in str(e.value) and e.value.key == key, str(e.value)


def test_every_int_field_is_bounded_by_what_64_bits_hold():
    """No int field of the agent or the world takes an integer a tensor or a generator would overflow on."""
    from train.common.config import RunConfig, _leaves
    c = RunConfig.default()
    leaves = {**_leaves(c.agent), **{f"world.{k}": v for k, v in _leaves(c.world).items()}}
    ints = [k for k, v in leaves.items() if isinstance(v, int) and not isinstance(v, bool)]
    assert "world.ik.seed" in ints and "fate_recalls" in ints
    for k in ints:
        with pytest.raises(ConfigError):
            resolve({k: 2 ** 63})


def test_the_level_resolution_and_felt_mass_floor_bounds_by_hand():
    """The smallest rise of the default file: 14 cm^3 over pi 6^2 cm^2, 0.1238 cm; a level read in steps of r
    misreads it by up to r: refused above 0.1238 / 4 = 0.03095 cm. The felt-mass floor: at most the lightest
    object's 14 g."""
    bound = 14.0 / (math.pi * 36.0) / 4
    check_run(resolve({"world.level_resolution_cm": bound * 0.99}), DEFAULT)
    refusal({"world.level_resolution_cm": bound * 1.01})
    check_run(resolve({"world.min_felt_mass_g": 14.0}), DEFAULT)
    refusal({"world.min_felt_mass_g": 14.01})


def test_in_lighter_water_archimedes_follows_and_an_overflow_is_refused():
    """Archimedes' figure in water of 0.5 g/cm^3: a floater displaces twice its mass, a sinker its volume as
    before; a 500 g float of 7 x 18 cm that fresh water holds 4.4 cm under the rim sinks there and overflows."""
    from sim.objects import archimedes_cm3, parse_objects
    light, heavy = DEFAULT.get("red_light_cylinder"), DEFAULT.get("red_heavy_cylinder")
    assert archimedes_cm3(light, DEFAULT.jar, 0.5) == pytest.approx(28.0, rel=1e-9)
    assert archimedes_cm3(heavy, DEFAULT.jar, 0.5) == archimedes_cm3(heavy, DEFAULT.jar)
    check_run(resolve({"world.tank.water.density": 500}), DEFAULT)
    big = parse_objects({"train": [{"name": "log", "shape": "cylinder", "color": "red", "dims_cm": [7.0, 18.0],
                                    "mass_g": 500}]})
    check_run(resolve({}), big)
    e = refusal({"world.tank.water.density": 500}, big)
    assert e.key == "world.tank.water.density" and "object 'log'" in str(e) and "over the jar's" in str(e), str(e)


def test_the_level_noise_bound_is_the_smallest_rise_over_four_sigmas_of_a_difference():
    """The oracle by hand: 14 g afloat displaces 14 cm^3, over pi 6^2 cm^2 a rise of 0.1238 cm; a difference of two
    readings has noise sqrt(2) s: refused above 0.1238 / 4 / sqrt(2) = 0.02189 cm, taken below."""
    rise = 14.0 / (math.pi * 36.0)
    bound = rise / 4 / math.sqrt(2)
    assert abs(bound - 0.02189) < 1e-5
    check_run(resolve({"world.level_noise_cm": bound * 0.99}), DEFAULT)
    refusal({"world.level_noise_cm": bound * 1.01})


def test_a_joint_refusal_names_the_setting_that_was_given():
    """Time step and density together: the one the run set is named first, so the runner says where it came from."""
    assert refusal({"world.tank.water.density": 1e5}).key == "world.tank.water.density"
    assert refusal({"world.tank.timestep_s": 0.05}).key == "world.tank.timestep_s"
    assert refusal({"world.tank.water.density": 1e5}, given={}).key == "world.tank.timestep_s"


def test_the_arms_levers_bound_the_palms_speed():
    """LEVERS_M is a constant (the check must not import the kinematics); it is at least the URDF's."""
    from sim.kinematics import ArmKinematics
    from train.runner.config_checks import arm_levers
    levers = arm_levers(ArmKinematics())
    assert 4.0 < levers <= LEVERS_M


@pytest.mark.parametrize("text, words", [
    ("som_samples=100000000", "som_samples takes an integer (int) from 1 to 1000000"),
    ("som_epochs=10000000", "som_epochs takes an integer (int) from 1 to 10000"),
    ("world.weigh_wait_steps=1000000000", "world.weigh_wait_steps takes an integer (int) from 0 to 240000"),
    ("world.waypoints=100000", "world.waypoints takes an integer (int) from 1 to 1000"),
])
def test_every_amount_of_work_has_an_upper_bound(text, words):
    from train.common.config import parse_set
    key, value = parse_set(text)
    with pytest.raises(ConfigError) as e:
        resolve({key: value})
    assert words in str(e.value), str(e.value)


def test_a_fuzz_of_in_range_settings_is_refused_in_one_line_or_passes():
    """Random combinations of values each in range (a fixed seed): check_run either passes or refuses in one line
    naming one of the keys drawn (never another exception)."""
    rng = random.Random(20261206)
    draws = {
        "world.move_timeout_s": lambda: 10 ** rng.uniform(-4, 2),
        "world.tank.timestep_s": lambda: 10 ** rng.uniform(-6, -1),
        "world.tank.settle_timeout_s": lambda: 10 ** rng.uniform(-2, 4),
        "world.tank.water.density": lambda: 10 ** rng.uniform(1, 5),
        "world.mass_noise_g": lambda: 10 ** rng.uniform(-3, 4),
        "world.level_noise_cm": lambda: 10 ** rng.uniform(-5, 1),
        "world.camera.near": lambda: 10 ** rng.uniform(-3, 0.5),
        "world.camera.far": lambda: 10 ** rng.uniform(-1, 1),
        "world.stand_height": lambda: rng.uniform(0.01, 0.4),
        "world.jar_xy": lambda: [rng.uniform(0.1, 0.5), rng.uniform(-0.4, 0.3)],
        "world.stand_xy": lambda: [rng.uniform(0.1, 0.5), rng.uniform(-0.4, 0.3)],
        "world.robot.max_velocity": lambda: 10 ** rng.uniform(-3, 1),
        "world.waypoints": lambda: rng.randint(1, 50),
        "world.tank.settle_windows": lambda: rng.randint(1, 50),
        "encoder.size_min_cm": lambda: 10 ** rng.uniform(-1, 2),
        "encoder.mass_max_g": lambda: 10 ** rng.uniform(0, 4),
    }
    outcomes = {"passed": 0, "refused": 0}
    for _ in range(30):
        overrides = {k: f() for k, f in rng.sample(sorted(draws.items()), rng.randint(1, 3))}
        try:
            check_run(resolve(overrides), DEFAULT, overrides)
            outcomes["passed"] += 1
        except ConfigError as e:
            assert "\n" not in str(e) and e.key and str(e).startswith(e.key), str(e)
            outcomes["refused"] += 1
    assert outcomes["passed"] and outcomes["refused"], outcomes   # the draws reach both sides


@pytest.mark.timeout(60)
@pytest.mark.parametrize("sets", [["world.move_timeout_s=1e-9"], ["world.level_noise_cm=100"],
                                  ["world.camera.far=0.001", "world.camera.near=10"],
                                  ["hub.match_threshold=-5"], ["world.ik.seed=99999999999999999999"],
                                  ["rules.dominant_strength=0.01", "rules.eliminated_strength=5"]])
def test_the_runner_refuses_up_front_in_one_line_and_writes_nothing(tiny, tmp_path, capsys, sets):
    from train import run as runner
    out = tmp_path / "out"
    assert runner.main(["--objects", str(tiny), "--orders", "1", "--out", str(out),
                        *[x for s in sets for x in ("--set", s)]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"train/run.py: error: --set {sets[-1]}: "), err
    assert not out.exists()


@pytest.mark.timeout(120)
def test_settings_the_checks_pass_finish_a_run(tiny, tmp_path):
    """A draw the checks pass (less noise on the hand, a longer settle) runs to its summary through the CLI, with
    the simulator: the heavy cylinder displaces its 365 cm^3."""
    out = tmp_path / "out"
    r = run_cli("--objects", str(tiny), "--orders", "1", "--out", str(out), "--set", "world.mass_noise_g=0.5",
                "--set", "world.tank.settle_windows=3")
    assert r.returncode == 0, r.stderr
    assert 355 < json.loads((out / "summary.json").read_text())["runs"][0]["episodes"][0]["observed_cm3"] < 375


# -- a drop that measured nothing true ---------------------------------------------------------------------------

def outcome(**kw):
    base = dict(name="red_heavy_cylinder", measurement={"rgb": [0.8, 0.1, 0.1], "extent_cm": [11.5, 6.36, 6.36],
                                                         "fill": 0.785, "mass_g": 420.0},
                observed_cm3=365.0, archimedes_cm3=365.3, goal_reachable_before=False, goal_reached_after=True,
                sank=True, true={}, delivered=True)
    return types.SimpleNamespace(**{**base, **kw})


@pytest.mark.parametrize("kw, words", [
    ({"delivered": False}, "was not delivered into the jar"),
    ({"observed_cm3": math.nan}, "non-finite"),
    ({"observed_cm3": math.inf}, "non-finite"),
    ({"measurement": {"rgb": [0.8, 0.1, 0.1], "extent_cm": [11.5, 6.36, 6.36], "fill": 0.785, "mass_g": math.nan}},
     "non-finite"),
    ({"observed_cm3": -11013.0}, "negative displaced volume (-11013.0 cm^3"),
])
def test_an_outcome_that_is_no_measurement_is_never_recorded(kw, words):
    from train.learning.experiment import BadOutcome, outcome_record
    from sim.errors import WorldBuildError
    assert outcome_record(outcome())["observed_cm3"] == 365.0
    with pytest.raises(BadOutcome) as e:
        outcome_record(outcome(**kw))
    assert isinstance(e.value, WorldBuildError) and words in str(e.value) and "\n" not in str(e.value)
    assert "red_heavy_cylinder" in str(e.value)


@pytest.mark.timeout(120)
def test_an_object_never_delivered_ends_the_run_in_one_line_with_its_checkpoint(tiny, tmp_path):
    """A move timeout that passes the up-front bound but is too short for the real arm (0.01 s per waypoint): the
    world reports the object not in the jar; exit 1, one line, the checkpoint of before the drops kept."""
    out = tmp_path / "out"
    r = run_cli("--objects", str(tiny), "--orders", "1", "--out", str(out), "--set", "world.move_timeout_s=0.01")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(lines) == 1, r.stderr
    assert "'red_heavy_cylinder' was not delivered into the jar" in lines[0] and "is intact" in lines[0]
    assert not (out / "summary.json").exists()
    from train.learning.checkpoint import load
    assert load(out / "checkpoints" / "latest.pt")["experiment"]["t"] == 0


# -- bounded, strict input files -----------------------------------------------------------------------------------

def test_a_repeated_key_in_an_objects_file_is_refused_naming_it(tmp_path):
    f = tmp_path / "o.json"
    f.write_text('{"train": [{"name": "a", "shape": "cube", "color": "red", "dims_cm": [5], "mass_g": 420, '
                 '"mass_g": 14}]}')
    with pytest.raises(ObjectsFileError, match="the key 'mass_g' appears twice"):
        load_objects(f)
    f.write_text(json.dumps(TINY)[:-1] + ', "train": [' + json.dumps(HEAVY) + "]}")   # a second "train"
    with pytest.raises(ObjectsFileError, match="the key 'train' appears twice"):
        load_objects(f)


def test_a_repeated_key_in_a_task_file_is_refused(tmp_path):
    from sim.apparatus import TaskFileError, load_task
    text = (ROOT / "sim" / "tasks" / "water_vs_sand.json").read_text()
    f = tmp_path / "t.json"
    f.write_text(text.replace("{", '{"_c": 1, "_c": 2, ', 1))
    with pytest.raises(TaskFileError, match="the key '_c' appears twice"):
        load_task(f)


@pytest.mark.parametrize("text, words", [
    ('{"a": NaN}', "NaN is not a JSON value"),
    ('{"a": -Infinity}', "-Infinity is not a JSON value"),
    ('{"a": 1' + "0" * 40 + "}", "an integer of 41 digits"),
    ("[" * 33 + "]" * 33, "nests 33 levels deep (at most 32)"),
    ('{"a\\u001b[31m": 1, "a\\u001b[31m": 2}', "the key 'a\\u001b[31m' appears twice"),
])
def test_the_reader_is_strict_and_bounded(text, words):
    with pytest.raises(InputFileError) as e:
        loads(text, "x.json")
    assert words in str(e.value) and str(e.value).isprintable(), str(e.value)


@pytest.mark.timeout(10)
def test_devices_and_pipes_are_not_read(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for path in ("/dev/zero", fifo, tmp_path):
        with pytest.raises(InputFileError, match="not a regular file|cannot read"):
            read_json(path, str(path))
        with pytest.raises(ConfigError, match="not a regular file"):
            load_toml(path)


@pytest.mark.parametrize("text, words", [
    ("[world]\nmass_noise_g = 2\nmass_noise_g = 3\n", "'mass_noise_g' is given twice (line 3)"),
    ("[rules]\ngrowth_step = 1.0\n[rules]\nuncertain_decay = 1.0\n", "'rules' is given twice (line 3)"),
])
def test_a_repeated_toml_key_is_refused_naming_it(tmp_path, text, words):
    f = tmp_path / "c.toml"
    f.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_toml(f)
    assert words in str(e.value) and str(f) in str(e.value), str(e.value)


@pytest.mark.timeout(60)
@pytest.mark.parametrize("text, words", [
    ('{"objects": {}, "orders": "1", "physics": "cached", "overrides": {}, "orders": "2"}', "'orders' appears twice"),
    ('{"objects": ' + "[" * 100_000 + "]" * 100_000 + "}", "nests 100001 levels deep"),
])
def test_a_damaged_run_json_is_refused_in_one_line(tmp_path, capsys, text, words):
    from train import run as runner
    out = tmp_path / "run"
    out.mkdir()
    (out / "run.json").write_text(text)
    assert runner.main(["--resume", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and "run.json is damaged" in err[0], err


@pytest.mark.timeout(60)
def test_a_device_as_config_or_objects_is_one_line(tmp_path, capsys):
    from train import run as runner
    for flag in ("--config", "--objects"):
        assert runner.main([flag, "/dev/zero", "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "not a regular file" in err[0], err
    assert not (tmp_path / "o").exists()


# -- summary.json ------------------------------------------------------------------------------------------------

def test_summary_json_has_null_for_non_finite_numbers():
    from train.runner.summary import json_safe
    data = json_safe({"a": [1.0, math.nan, (math.inf, -math.inf)], "b": {"c": "\x1b[31m"}, "d": 3})
    assert data == {"a": [1.0, None, [None, None]], "b": {"c": "\x1b[31m"}, "d": 3}
    text = json.dumps(data, allow_nan=False)
    assert "\\u001b" in text and "\x1b" not in text
