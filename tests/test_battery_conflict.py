"""The battery's size-and-weight conflict tasks (sim/tasks/, benches/battery.py CONFLICT): their right answer in
closed form by hand and against physics on a sample, and the conflict they are there for (the pre-training's stones
grow heavier and larger together; in these tasks size and weight point to different objects).

Oracles by hand, one 5 cm tube (area pi * 25 / 4 cm^2): a floater of m g displaces m cm^3, a rise of
4 m / (25 pi) cm; a sinking sphere of diameter d displaces pi d^3 / 6 cm^3, a rise of (2 / 3) d^3 / 25 cm.
"""

import math
from dataclasses import replace
from pathlib import Path

import pytest

from sim.apparatus import load_task, outcome
from train.battery.tasks import PRETRAIN_STONES, Protocol, trial_levels

TASKS = Path(__file__).resolve().parents[1] / "sim" / "tasks"
PHYSICS_TOL_CM = 0.01   # as tests/test_apparatus.py: 0.2 cm^3 in a 5 cm tube


def floater_rise(mass_g):
    return 4 * mass_g / (25 * math.pi)


def sinker_rise(d_cm):
    return 2 / 3 * d_cm ** 3 / 25


# task: (right object, its rise, wrong object, its rise, which cue is right)
CONFLICT = {
    "floater_large_light_vs_sinker_small_heavy": ("large_light_floater", floater_rise(24),    # 1.2223 cm
                                                  "small_heavy_sinker", sinker_rise(2.2), "size"),   # 0.2840 cm
    "floaters_large_light_vs_small_heavy": ("small_heavy_floater", floater_rise(21),           # 1.0695 cm
                                            "large_light_floater", floater_rise(8), "weight"),   # 0.4074 cm
    "sinker_small_vs_floater_large_light": ("small_sinker", sinker_rise(3.5),                  # 1.1433 cm
                                            "large_light_floater", floater_rise(8), "weight"),
    "stones_size_vs_weight_floater": ("large_light", floater_rise(11),                         # 0.5602 cm
                                      "small_heavy", sinker_rise(2.0), "size"),                  # 0.2133 cm
    "stones_size_vs_weight_sinkers": ("large_light", sinker_rise(3.2),                         # 0.8738 cm
                                      "small_heavy", sinker_rise(2.6), "size"),                  # 0.4687 cm
    "large_light_vs_small_heavy": ("large_light", 4 * 45 * math.pi / 4 / (25 * math.pi),     # 3 x 5 cm cylinder: 1.8
                                   "small_heavy", 4 * (1.8 ** 2 * 2.5 * math.pi / 4) / (25 * math.pi), "size"),
}


def test_pretraining_stones_grow_heavier_and_larger_together():
    """What makes these tasks conflicts: in the pre-training the larger stone is always the heavier, and the one
    that raises the water more (all sink: volume)."""
    by_size = sorted(PRETRAIN_STONES, key=lambda s: s[2][0])
    assert [s[3] for s in by_size] == sorted(s[3] for s in by_size)
    assert len({s[3] for s in by_size}) == len(by_size)


@pytest.mark.parametrize("name", sorted(CONFLICT))
def test_conflict_task_right_answer_in_closed_form(name):
    right, r_rise, wrong, w_rise, cue = CONFLICT[name]
    t = load_task(TASKS / f"{name}.json")
    assert t.correct == (("tube", right),)
    objs = {o.name: o for o in t.objects}
    lv = t.start_levels()
    assert outcome(t, lv, t.tube("tube"), objs[right])["rise_cm"]["tube"] == pytest.approx(r_rise, abs=1e-9)
    assert outcome(t, lv, t.tube("tube"), objs[wrong])["rise_cm"]["tube"] == pytest.approx(w_rise, abs=1e-9)
    # size and weight disagree, and `cue` is the one that names the right object
    a, b = objs[right], objs[wrong]
    larger_right, heavier_right = a.volume_cm3 > b.volume_cm3, a.mass_g > b.mass_g
    assert larger_right != heavier_right
    assert (larger_right if cue == "size" else heavier_right)
    # nothing else tells them apart: one colour, one shape
    assert a.rgb == b.rgb and a.shape == b.shape


def test_stones_tasks_cross_the_pretraining_stones_size_and_weight():
    """The stones_size_vs_weight tasks: each option has one pre-training stone's size and another stone's weight,
    crosswise, in the stones' colour and shape, so resembling a stone cannot decide between them."""
    from train.battery.tasks import STONE_RGB
    sizes = {s[2][0]: s[0] for s in PRETRAIN_STONES}
    masses = {s[3]: s[0] for s in PRETRAIN_STONES}
    for name in ("stones_size_vs_weight_floater", "stones_size_vs_weight_sinkers"):
        t = load_task(TASKS / f"{name}.json")
        a, b = t.objects
        like = [(sizes[o.dims_cm[0]], masses[o.mass_g]) for o in (a, b)]
        assert like[0] == like[1][::-1] and like[0][0] != like[0][1], (name, like)
        assert a.shape == b.shape == "sphere" and a.rgb == b.rgb == pytest.approx(STONE_RGB)


@pytest.mark.parametrize("name", ["floater_large_light_vs_sinker_small_heavy", "floaters_large_light_vs_small_heavy",
                                  "sinker_small_vs_floater_large_light", "stones_size_vs_weight_floater",
                                  "stones_size_vs_weight_sinkers"])
def test_conflict_task_against_physics(name):
    """Each option dropped once from the file's levels (the first drop of a trial, which transfer scores) rises in
    the physics as in the closed form; the right object dropped 3 times from a trial's start reaches in the physics
    too (after 2 drops not). Measured: every single drop within 0.001 cm; 3 large floaters (4.4 cm spheres) stacked
    in the 5 cm tube rise 3.48 cm against the closed form's 3.67 (the stack rests on the floor), still in reach."""
    import pybullet as p

    from sim.tubes import Apparatus, simulate_drop
    t = load_task(TASKS / f"{name}.json")
    right = CONFLICT[name][0]
    for o in t.objects:
        sim = simulate_drop(t, "tube", o)
        cf = outcome(t, t.start_levels(), t.tube("tube"), o)
        assert sim["settled"], o.name
        assert sim["levels"]["tube"] == pytest.approx(cf["levels"]["tube"], abs=PHYSICS_TOL_CM), o.name
    start = trial_levels(t, Protocol())
    t0 = replace(t, tubes=tuple(replace(x, level_cm=start[x.name]) for x in t.tubes))
    obj = next(o for o in t.objects if o.name == right)
    reach = t.tube("tube").height_cm - t.reach_cm
    cl = p.connect(p.DIRECT)
    try:
        ap = Apparatus(cl, t0)
        levels = [ap.drop("tube", obj)["levels"]["tube"] for _ in range(Protocol().drops_to_reach)]
    finally:
        p.disconnect(cl)
    assert levels[-2] < reach <= levels[-1], levels


def test_every_task_file_is_on_the_bench_once():
    """Each of sim/tasks (but crows.json, the goal trials' file) is a task of benches/battery.py: a study's, a
    conflict task of the last line's, or a size-and-weight task reported apart; none in two groups."""
    import importlib.util
    import sys
    root = TASKS.parents[1]
    spec = importlib.util.spec_from_file_location("battery_bench", root / "benches" / "battery.py")
    sys.path.insert(0, str(root / "benches"))
    try:
        bench = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(bench)
    finally:
        sys.path.remove(str(root / "benches"))
    files = {f.stem for f in TASKS.glob("*.json")} - {"crows"}
    groups = (bench.TASKS, bench.CONFLICT, bench.SIZE_WEIGHT)
    assert sorted(t for g in groups for t in g) == sorted(files)
    assert set(bench.ALL_TASKS) == files
