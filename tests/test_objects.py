"""The objects file: the default set parses, every bad file is refused in one line naming object and field,
and the Archimedes yardstick matches hand calculations."""

import json
import math

import numpy as np
import pytest

from sim.objects import (ObjectsFileError, ObjectSpec, JarSpec, archimedes_cm3, load_objects, parse_objects,
                         DEFAULT_OBJECTS_FILE)

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
