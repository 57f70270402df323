"""The objects file: the default set parses, every bad file is refused in one line naming object and field,
and the Archimedes yardstick matches hand calculations."""

import json
import math

import numpy as np
import pytest

from sim.objects import (ObjectsConfig, ObjectsFileError, ObjectSpec, JarSpec, archimedes_cm3, load_objects,
                         min_mass_g_for, parse_objects, DEFAULT_OBJECTS_FILE)

GOOD = {"name": "red_heavy_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 420}
JAR = {"inner_diameter_cm": 12.0, "height_cm": 20.0, "water_depth_cm": 14.0}


def obj(**kw):
    return {**GOOD, **kw}


def refused(data, *words):
    with pytest.raises(ObjectsFileError) as e:
        parse_objects(data)
    msg = str(e.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg
    return msg


def test_default_file_parses_with_the_papers_objects():
    s = load_objects(DEFAULT_OBJECTS_FILE)
    names = [o.name for o in s.train]
    assert len(s.train) == 8 and len(s.probe) >= 3
    assert {"red_heavy_cylinder", "blue_heavy_cylinder", "red_light_cylinder"} <= set(names)
    red, blue, light = s.get("red_heavy_cylinder"), s.get("blue_heavy_cylinder"), s.get("red_light_cylinder")
    assert red.dims_cm == blue.dims_cm == light.dims_cm == (6.36, 11.5)
    assert red.mass_g == blue.mass_g == 420 and light.mass_g == 14
    assert red.rgb != blue.rgb and red.rgb == light.rgb
    assert red.sinks and not light.sinks
    assert archimedes_cm3(red, s.jar) == pytest.approx(365.3, abs=0.1)   # the paper's ~365 cm^3
    assert archimedes_cm3(light, s.jar) == pytest.approx(14.0, abs=1e-9)
    kinds = {(o.shape, o.sinks) for o in s.train}
    assert len({o.shape for o in s.train}) == 4 and {True, False} == {k[1] for k in kinds}
    train_kinds = {(o.shape, o.mass_g) for o in s.train}
    assert all((o.shape, o.mass_g) not in train_kinds for o in s.probe)


@pytest.mark.parametrize("bad, words", [
    (obj(shape="pyramid"), ["red_heavy_cylinder", "'shape'"]),
    (obj(dims_cm=[6.36]), ["red_heavy_cylinder", "'dims_cm'"]),
    (obj(dims_cm=[6.36, 11.5, 2.0]), ["red_heavy_cylinder", "'dims_cm'"]),
    (obj(dims_cm="6.36 11.5"), ["red_heavy_cylinder", "'dims_cm'"]),
    (obj(dims_cm=[0.0, 11.5]), ["red_heavy_cylinder", "'dims_cm'", "> 0"]),
    (obj(dims_cm=[-1.0, 11.5]), ["red_heavy_cylinder", "'dims_cm'"]),
    (obj(dims_cm=[float("inf"), 11.5]), ["red_heavy_cylinder", "'dims_cm'", "finite"]),
    (obj(dims_cm=[float("nan"), 11.5]), ["red_heavy_cylinder", "'dims_cm'", "finite"]),
    (obj(dims_cm=[0.5, 11.5]), ["red_heavy_cylinder", "'dims_cm'"]),               # too small to see or hold
    (obj(mass_g=0), ["red_heavy_cylinder", "'mass_g'"]),
    (obj(mass_g=-3), ["red_heavy_cylinder", "'mass_g'"]),
    (obj(mass_g=float("nan")), ["red_heavy_cylinder", "'mass_g'"]),
    (obj(mass_g=True), ["red_heavy_cylinder", "'mass_g'"]),
    (obj(mass_g="420"), ["red_heavy_cylinder", "'mass_g'"]),
    (obj(mass_g=5000), ["red_heavy_cylinder", "'mass_g'"]),                          # more than the arm carries
    (obj(color="octarine"), ["red_heavy_cylinder", "'color'"]),
    (obj(color=[1.2, 0, 0]), ["red_heavy_cylinder", "'color'"]),
    (obj(color=[0.5, 0.5]), ["red_heavy_cylinder", "'color'"]),
    (obj(dims_cm=[20.0, 5.0]), ["red_heavy_cylinder", "'dims_cm'", "beside"]),      # wider than the jar
    (obj(dims_cm=[8.0, 5.0]), ["red_heavy_cylinder", "'dims_cm'", "beside"]),       # passes the mouth, not the ball
    (obj(dims_cm=[5.0, 25.0]), ["red_heavy_cylinder", "'dims_cm'", "taller"]),
    (obj(shape="box", dims_cm=[9.0, 3.0, 2.0]), ["red_heavy_cylinder", "'dims_cm'", "longest side last"]),
    (obj(shape="cube", dims_cm=[6.0]), ["red_heavy_cylinder", "'dims_cm'"]),         # face diagonal 8.5 cm
    (obj(dims_cm=[7.0, 19.0], mass_g=900), ["red_heavy_cylinder", "'dims_cm'", "rim"]),  # 731 cm^3: overflows
    (obj(mass_g=999, dims_cm=[7.4, 19.5]), ["red_heavy_cylinder", "rim"]),
    ({k: v for k, v in GOOD.items() if k != "mass_g"}, ["red_heavy_cylinder", "'mass_g'", "missing"]),
    ({k: v for k, v in GOOD.items() if k != "color"}, ["red_heavy_cylinder", "'color'", "missing"]),
    (obj(mass=420), ["red_heavy_cylinder", "'mass'", "unknown key"]),
    (obj(name="../evil"), ["train[0]", "'name'"]),
    (obj(name=""), ["train[0]", "'name'"]),
    ({"shape": "cube"}, ["train[0]", "'name'"]),
])
def test_bad_object_is_refused_naming_object_and_field(bad, words):
    refused({"jar": JAR, "train": [bad]}, *words)


def test_floater_that_would_overflow_names_its_mass():
    # a light, big object floats: what it displaces is its mass, so the mass is what overflows
    jar = {"inner_diameter_cm": 12.0, "height_cm": 15.0, "water_depth_cm": 14.5}
    refused({"jar": jar, "train": [obj(dims_cm=[7.0, 14.0], mass_g=200)]}, "red_heavy_cylinder", "'mass_g'", "rim")


def test_duplicate_names_are_refused_across_train_and_probe():
    refused({"train": [obj()], "probe": [obj(color="blue")]}, "red_heavy_cylinder", "'name'", "duplicate")
    refused({"train": [obj(), obj()]}, "red_heavy_cylinder", "'name'", "duplicate")


@pytest.mark.parametrize("jar, field", [
    ({**JAR, "inner_diameter_cm": -12.0}, "inner_diameter_cm"),
    ({**JAR, "height_cm": 0}, "height_cm"),
    ({**JAR, "water_depth_cm": float("inf")}, "water_depth_cm"),
    ({**JAR, "water_depth_cm": 25.0}, "water_depth_cm"),      # deeper than the jar
    ({**JAR, "water_depth_cm": 20.0}, "water_depth_cm"),      # brim-full: no room for anything
    ({**JAR, "lid": True}, "lid"),
    ("big", "jar"),
])
def test_impossible_jar_is_refused(jar, field):
    refused({"jar": jar, "train": [obj()]}, "jar", field)


def test_file_level_problems_are_refused():
    refused({"train": []}, "train", "empty")
    refused({"jar": JAR}, "train")
    refused({"train": [obj()], "tarin": []}, "'tarin'", "unknown key")
    refused({"train": {"a": 1}}, "train", "list")
    refused([obj()], "JSON object")


def test_comment_keys_are_ignored_and_jar_is_optional():
    s = parse_objects({"_comment": "hi", "train": [{**obj(), "_note": "the paper's object 1"}]})
    assert s.jar.inner_diameter_cm > 0 and s.train[0].name == "red_heavy_cylinder"


def test_malformed_json_and_missing_file_are_refused_and_nothing_is_written(tmp_path):
    f = tmp_path / "objects.json"
    f.write_text('{"train": [')
    before = sorted(tmp_path.iterdir())
    with pytest.raises(ObjectsFileError, match="malformed JSON at line 1"):
        load_objects(f)
    with pytest.raises(ObjectsFileError, match="cannot read"):
        load_objects(tmp_path / "nope.json")
    assert sorted(tmp_path.iterdir()) == before and f.read_text() == '{"train": ['


def test_colours_names_and_rgb():
    s = parse_objects({"train": [obj(color="grey"), obj(name="b", color=[0.25, 0.5, 1.0])]})
    assert s.train[0].rgb == (0.5, 0.5, 0.5)
    assert s.train[1].rgb == (0.25, 0.5, 1.0)
    for name in ("red", "green", "blue", "yellow", "orange", "purple", "white", "black", "grey"):
        parse_objects({"train": [obj(color=name)]})


def test_geometry_of_each_shape():
    cyl = ObjectSpec("c", "cylinder", (4.0, 10.0), 100.0, (1, 0, 0))
    assert cyl.volume_cm3 == pytest.approx(math.pi * 4 * 10)
    assert list(cyl.extent_cm) == [10.0, 4.0, 4.0] and cyl.fill == pytest.approx(math.pi / 4)
    box = ObjectSpec("b", "box", (3.0, 5.0, 2.0), 10.0, (1, 0, 0))
    assert box.volume_cm3 == 30.0 and list(box.extent_cm) == [5.0, 3.0, 2.0] and box.fill == 1.0
    assert box.footprint_cm == pytest.approx(math.hypot(3, 5)) and box.height_cm == 2.0
    sph = ObjectSpec("s", "sphere", (6.0,), 10.0, (1, 0, 0))
    assert sph.volume_cm3 == pytest.approx(36 * math.pi) and sph.fill == pytest.approx(math.pi / 6)
    assert sph.density_g_cm3 == pytest.approx(10 / (36 * math.pi))
    cube = ObjectSpec("k", "cube", (2.0,), 10.0, (1, 0, 0))
    assert cube.volume_cm3 == 8.0 and cube.sinks and not sph.sinks


def test_archimedes_by_hand():
    jar = JarSpec(12.0, 20.0, 14.0)
    # a sinker under water displaces its volume
    sinker = ObjectSpec("s", "cylinder", (6.36, 11.5), 420.0, (1, 0, 0))
    assert archimedes_cm3(sinker, jar) == pytest.approx(math.pi * 3.18 ** 2 * 11.5, rel=1e-9)
    sphere = ObjectSpec("b", "sphere", (5.0,), 330.0, (0, 0, 0))
    assert archimedes_cm3(sphere, jar) == pytest.approx(math.pi * 125 / 6, rel=1e-9)
    # a floater displaces its mass
    for shape, dims in (("cylinder", (6.36, 11.5)), ("sphere", (7.0,)), ("box", (4.0, 5.0, 6.0))):
        assert archimedes_cm3(ObjectSpec("f", shape, dims, 14.0, (1, 0, 0)), jar) == pytest.approx(14.0, rel=1e-9)
    # a tall sinker standing on the bottom sticks out: the level L solves L = L0 + a L / A, so L = L0 A / (A - a).
    # cross-section a = 4 pi (d = 4), jar A = 36 pi (D = 12), L0 = 10: L = 10 * 36 / 32 = 11.25, V = a L = 45 pi.
    tall = ObjectSpec("t", "cylinder", (4.0, 19.0), 600.0, (1, 0, 0))
    assert archimedes_cm3(tall, JarSpec(12.0, 20.0, 10.0)) == pytest.approx(45 * math.pi, rel=1e-9)
    # the same with a 4 x 4 box: a = 16, A = 36 pi, L = 10 A / (A - 16)
    post = ObjectSpec("p", "box", (4.0, 4.0, 19.0), 600.0, (1, 0, 0))
    A = 36 * math.pi
    assert archimedes_cm3(post, JarSpec(12.0, 20.0, 10.0)) == pytest.approx(16 * 10 * A / (A - 16), rel=1e-9)
    # just covered: the same post in deeper water displaces all of its volume
    assert archimedes_cm3(post, JarSpec(12.0, 25.0, 18.0)) == pytest.approx(16 * 19, rel=1e-9)


def test_canonical_is_plain_and_stable():
    s = load_objects(DEFAULT_OBJECTS_FILE)
    c = s.canonical()
    assert json.loads(json.dumps(c)) == c
    assert c == load_objects(DEFAULT_OBJECTS_FILE).canonical()
    assert c["train"][0]["color"] == list(s.train[0].rgb)
    assert isinstance(s.train[0].extent_cm, np.ndarray)


# -- what the format admits, a run must finish: limits, wrong types, escaped messages ---------------------------------

CFG = ObjectsConfig()


def test_objects_lighter_than_the_hand_can_feel_are_refused():
    # 1e-300 g was felt as 22,707 g: pybullet takes a body under 2.2e-16 kg as static, and the hand fought it
    for mass in (1e-300, 5e-324, 1e-30, 0.05, 0.099):
        msg = refused({"train": [obj(shape="cube", dims_cm=[1.0], mass_g=mass)]}, "red_heavy_cylinder", "'mass_g'",
                      f"{CFG.min_mass_g:g} g")
        assert "feel" in msg
    assert parse_objects({"train": [obj(shape="cube", dims_cm=[1.0], mass_g=CFG.min_mass_g)]}).train[0].mass_g == 0.1


def test_light_wide_floaters_the_water_cannot_simulate_are_refused():
    # a 7 x 1 cm disc of 0.3 g jumped out of the simulated jar; the limit grows with the cross-section
    disc = obj(dims_cm=[7.0, 1.0])
    least = min_mass_g_for(ObjectSpec("d", "cylinder", (7.0, 1.0), 1.0, (1, 0, 0)), JarSpec(12.0, 20.0, 14.0))
    assert 1.5 < least < 2.5
    refused({"jar": JAR, "train": [{**disc, "mass_g": 0.5}]}, "red_heavy_cylinder", "'mass_g'", "too light",
            f"{least:.2f} g")
    assert parse_objects({"jar": JAR, "train": [{**disc, "mass_g": round(least + 0.01, 2)}]}).train
    # a wider jar leaves more room: the same disc's limit is lower there (the level rises less as it sinks)
    wide = {**JAR, "inner_diameter_cm": 20.0}
    assert min_mass_g_for(ObjectSpec("d", "cylinder", (7.0, 1.0), 1.0, (1, 0, 0)), JarSpec(20.0, 20.0, 14.0)) < least
    assert parse_objects({"jar": wide, "train": [{**disc, "mass_g": round(least, 2)}]}).train


@pytest.mark.parametrize("jar, field, words", [
    ({"inner_diameter_cm": 200.0, "height_cm": 300.0}, "inner_diameter_cm", ["29 cm", "table"]),
    ({"inner_diameter_cm": 1e31}, "inner_diameter_cm", ["29 cm"]),
    ({"inner_diameter_cm": 1e200}, "inner_diameter_cm", ["29 cm"]),          # was an OverflowError traceback
    ({"inner_diameter_cm": 29.01}, "inner_diameter_cm", ["29 cm"]),
    ({"inner_diameter_cm": 5.0}, "inner_diameter_cm", ["5.5 cm", "ball"]),
    ({"height_cm": 1000.0}, "height_cm", ["44 cm", "carry"]),
    ({"height_cm": 1e31, "water_depth_cm": 1e30}, "height_cm", ["44 cm"]),
    ({"height_cm": 1e200}, "height_cm", ["44 cm"]),
    ({"water_depth_cm": 0.01}, "water_depth_cm", ["2 cm", "float"]),
    ({"water_depth_cm": 1.99}, "water_depth_cm", ["2 cm"]),
])
def test_a_jar_the_world_cannot_hold_is_refused_naming_the_limit(jar, field, words):
    refused({"jar": jar, "train": [obj(dims_cm=[1.0, 1.0], mass_g=1.0)]}, "jar", f"'{field}'", *words)


def test_the_largest_jar_and_the_shallowest_water_are_admitted():
    tiny = obj(shape="cube", dims_cm=[1.0], mass_g=1.0)
    for jar in ({"inner_diameter_cm": 29.0}, {"height_cm": 44.0, "water_depth_cm": 30.0},
                {"inner_diameter_cm": 5.5, "water_depth_cm": 2.0}):
        assert parse_objects({"jar": jar, "train": [tiny if jar.get("inner_diameter_cm") != 5.5 else
                                                    obj(dims_cm=[1.0, 1.0], mass_g=1.0)]}).jar


def test_an_object_too_tall_to_carry_over_the_rim_is_refused():
    jar = {"inner_diameter_cm": 12.0, "height_cm": 40.0, "water_depth_cm": 30.0}
    assert parse_objects({"jar": jar, "train": [obj(dims_cm=[5.0, 5.0], mass_g=300)]}).train   # 40 + 5 = 45 cm
    refused({"jar": jar, "train": [obj(dims_cm=[5.0, 5.5], mass_g=300)]}, "red_heavy_cylinder", "'dims_cm'",
            "carry", "45 cm")


FIELD_VALUES = [None, True, False, 0, -1, 10 ** 31, 10 ** 40, 1e308, 1e-308, 5e-324, 1e200, -1e200, float("nan"),
                float("inf"), float("-inf"), "", "cube", "5", "a\n\x1b[31m", [], [None], ["cube"], [[1.0]], {},
                {"a": 1}, [1e200] * 3, [float("nan")] * 3, list(range(500)), "x" * 5000]
FULL = {"jar": {"inner_diameter_cm": 12.0, "height_cm": 19.5, "water_depth_cm": 14.0},
        "train": [{"name": "a", "shape": "cube", "color": "red", "dims_cm": [5.0], "mass_g": 300}],
        "probe": [{"name": "b", "shape": "cylinder", "color": [0.1, 0.2, 0.3], "dims_cm": [4.0, 6.0], "mass_g": 30}],
        "pool": [{"name": "c", "shape": "box", "color": "blue", "dims_cm": [2.0, 3.0, 4.0], "mass_g": 20}],
        "trials": [{"stand": ["a", "c"], "goal": "reach the green ball"}]}
FIELDS = [("jar",), ("jar", "inner_diameter_cm"), ("jar", "height_cm"), ("jar", "water_depth_cm"), ("train",),
          ("probe",), ("pool",), ("trials",), ("train", 0), ("trials", 0), ("trials", 0, "stand"),
          ("trials", 0, "stand", 0), ("trials", 0, "goal")] + [
    (group, 0, key) for group in ("train", "probe", "pool") for key in ("name", "shape", "color", "dims_cm", "mass_g")
] + [("train", 0, "dims_cm", 0), ("probe", 0, "dims_cm", 1), ("probe", 0, "color", 0), ("pool", 0, "dims_cm", 2)]


def _with(data, path, value):
    data = json.loads(json.dumps(data))
    at = data
    for k in path[:-1]:
        at = at[k]
    at[path[-1]] = value
    return data


@pytest.mark.parametrize("path", FIELDS, ids=["/".join(map(str, f)) for f in FIELDS])
def test_any_value_in_any_field_is_refused_in_one_line_naming_the_field(path):
    """Fuzz: a wrong type (list, dict, bool, null, string for a number and the reverse), huge and tiny numbers,
    NaN and inf in every field give an ObjectsFileError naming the field, or load; never another exception (a list
    as the shape was a TypeError, a 1e200 cm jar an OverflowError)."""
    named = [k for k in path if isinstance(k, str)]
    for value in FIELD_VALUES:
        try:
            parse_objects(_with(FULL, path, value))
        except ObjectsFileError as e:
            msg = str(e)
            assert "\n" not in msg and "\x1b" not in msg and len(msg) < 400, msg
            if named[-1] in ("train", "probe", "pool", "trials") and len(path) <= 2:
                assert named[-1] in msg, (path, value, msg)
            elif path[0] in ("train", "probe", "pool") and named[-1] != "name" and len(path) == 3:
                # object 'a' field 'shape': ... (another valid shape: its dims no longer match)
                assert f"'{named[-1]}'" in msg or (named[-1] == "shape" and "'dims_cm'" in msg), (path, value, msg)
            else:
                assert any(k in msg for k in named), (path, value, msg)


def test_nan_and_infinity_spelled_in_json_are_refused_naming_the_field(tmp_path):
    f = tmp_path / "o.json"
    for field, literal in [("mass_g", "NaN"), ("mass_g", "Infinity"), ("mass_g", "-Infinity"), ("mass_g", "1e999"),
                           ("mass_g", "-0"), ("mass_g", "1e-400"), ("dims_cm", "[NaN]"), ("dims_cm", "[1e400]"),
                           ("color", "[NaN, 0, 0]"), ("color", "[Infinity, 0, 0]"), ("shape", "NaN"),
                           ("name", "Infinity")]:
        fields = {"name": '"a"', "shape": '"cube"', "color": '"red"', "dims_cm": "[5]", "mass_g": "300", field: literal}
        f.write_text('{"train": [{' + ", ".join(f'"{k}": {v}' for k, v in fields.items()) + "}]}")
        with pytest.raises(ObjectsFileError, match=f"'{field}'"):
            load_objects(f)
    for key, literal in [("inner_diameter_cm", "NaN"), ("height_cm", "Infinity"), ("water_depth_cm", "-Infinity")]:
        f.write_text('{"jar": {"' + key + '": ' + literal + '}, "train": [{"name": "a", "shape": "cube", '
                     '"color": "red", "dims_cm": [5], "mass_g": 300}]}')
        with pytest.raises(ObjectsFileError, match=f"jar field '{key}'"):
            load_objects(f)


def test_a_null_jar_is_refused_not_taken_as_the_default():
    refused({"jar": None, "train": [obj()]}, "jar", "null")


def test_names_keys_and_words_with_control_characters_are_shown_escaped():
    """A name is 1 to 64 plain ASCII characters; one with a newline or an ANSI escape is refused, and no message
    prints it raw (it could fake a second line or recolour the terminal)."""
    evil = "red\x1b[2J\x1b[31m\nFAKE: ok\r\x07\u202e"
    cases = [({"train": [obj(name=evil)]}, "'name'"),
             ({"train": [obj(name="a\n")]}, "'name'"),
             ({"train": [{**obj(), evil: 1}]}, "unknown key"),
             ({"train": [obj()], evil: 1}, "unknown key"),
             ({"train": [obj(color=evil)]}, "'color'"),
             ({"train": [obj(shape=evil)]}, "'shape'"),
             ({"train": [obj()], "trials": [{"stand": [evil]}]}, "'stand'"),
             ({"train": [obj()], "trials": [{"stand": ["red_heavy_cylinder"], "goal": "reach the ball " + evil}]},
              "'goal'"),
             ({"jar": {"inner_diameter_cm": evil}, "train": [obj()]}, "'inner_diameter_cm'")]
    for data, words in cases:
        msg = refused(data, words)
        assert msg.isprintable(), repr(msg)
        assert "\\n" in msg or "\\u001b" in msg or "\\x1b" in msg, msg


def test_cannot_read_messages_escape_the_path(tmp_path):
    with pytest.raises(ObjectsFileError) as e:
        load_objects(tmp_path / "no\nsuch\x1b[31m.json")
    assert str(e.value).isprintable() and "\\n" in str(e.value)
