"""The battery's scoring (exact binomial test), its agent side (context maps, a hand-made 2-option task) and the
context option's default (off: the default agent's maps and output unchanged)."""

import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from aesop_torch.encoders import (MAP_NAMES, EncoderConfig, SensoryEncoder, default_map_configs,
                                  developmental_samples)
from train.battery import CONTEXT, binomial_tail, context_agent, make_config, play, score

ROOT = Path(__file__).resolve().parents[1]


def test_binomial_tail_known_values():
    # by hand: sum_{i>=15} C(20, i) / 2^20 = (15504 + 4845 + 1140 + 190 + 20 + 1) / 1048576
    assert binomial_tail(15, 20, 0.5) == pytest.approx(21700 / 2 ** 20, abs=1e-12)
    assert binomial_tail(15, 20, 0.5) == pytest.approx(0.020694, abs=1e-6)
    assert binomial_tail(14, 20, 0.5) == pytest.approx(0.057659, abs=1e-6)
    assert binomial_tail(0, 20, 0.5) == pytest.approx(1.0)
    assert binomial_tail(1, 1, 1 / 3) == pytest.approx(1 / 3)
    assert binomial_tail(2, 2, 1 / 3) == pytest.approx(1 / 9)
    with pytest.raises(ValueError):
        binomial_tail(21, 20, 0.5)


def test_score_pools_subjects_per_window():
    right = [[True] * 20, [False] + [True] * 14 + [False] * 5]
    s = score(right, 0.5)
    assert (s["trial 1"].correct, s["trial 1"].n) == (1, 2)
    assert (s["1-5"].correct, s["1-5"].n) == (9, 10)
    assert (s["1-20"].correct, s["1-20"].n) == (34, 40)
    one = score([[True] * 15 + [False] * 5], 0.5)["1-20"]
    assert one.passed and not score([[True] * 14 + [False] * 6], 0.5)["1-20"].passed


def test_context_off_by_default():
    assert EncoderConfig().context == ()
    assert tuple(default_map_configs()) == MAP_NAMES
    assert tuple(default_map_configs(EncoderConfig())) == MAP_NAMES
    g0, g1 = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    plain = developmental_samples(50, g0)
    ctx = developmental_samples(50, g1, EncoderConfig(context=("width",)))
    assert set(plain) == set(MAP_NAMES) and set(ctx) == set(MAP_NAMES) | {"width"}
    for name in MAP_NAMES:   # the context's draws come last: the maps' own samples are unchanged
        assert torch.equal(plain[name], ctx[name])
    m = {"rgb": [0.5, 0.5, 0.5], "context": {"width": 0.3}}
    with pytest.raises(ValueError, match="context"):
        SensoryEncoder()(m)                       # a default encoder perceives no context
    out = SensoryEncoder(EncoderConfig(context=("width",)))(m)
    assert out["width"].tolist() == [[pytest.approx(0.3)]]
    with pytest.raises(ValueError, match="0..1"):
        SensoryEncoder(EncoderConfig(context=("width",)))({"context": {"width": 1.5}})


def _small(model):
    c = make_config(model, seed=1)
    return replace(c, som_samples=800, som_epochs=5)


@pytest.mark.parametrize("model", ["paper", "extended"])
def test_two_options_one_episode_each_chooses_the_better(model):
    """Same object, two tubes differing only in their contents' look: option 0 raises the reward 2 cm (in reach),
    option 1 not at all. Each agent stores one episode per option (in either order); the oracle: option 0."""
    obj = {"rgb": [0.8, 0.1, 0.1], "extent_cm": [4.0, 4.0, 4.0], "fill": 1.0, "mass_g": 150.0}
    ctx = lambda s, place: {"surface": s, "width": 0.3, "level": 0.5, "place": place}
    options = [dict(obj, context=ctx(0.15, 0.0)), dict(obj, context=ctx(0.6, 1.0))]
    world = lambda i: (2.0, True) if i == 0 else (0.0, False)
    agent = context_agent(_small(model), 2)
    assert tuple(agent.maps)[-len(CONTEXT):] == CONTEXT
    right, chosen = play(agent, options, world, {0}, [[0, 1], [1, 0]], trials=3, seed=1)
    assert chosen == [[0, 0, 0], [0, 0, 0]] and right == [[True] * 3] * 2


def test_bench_help():
    r = subprocess.run([sys.executable, str(ROOT / "benches" / "battery.py"), "--help"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and "--ablate" in r.stdout and "--record" in r.stdout


def test_score_of_fewer_trials_counts_what_was_played():
    s = score([[True] * 10, [False] * 10], 0.5)["1-20"]
    assert (s.correct, s.n) == (10, 20)


def test_a_choice_aims_at_the_rewards_gap_and_equal_gaps_choose_as_the_rise():
    """Two tubes alike but for their level: each option raises its own reward 1.8 cm; only the high tube's (seen
    1.5 cm below reach, the low one's 5 cm) comes in reach. The predicted rises tie, so aiming at the gap chooses
    the high tube on every trial (the oracle: 18 - 10 x 0 > 18 - 10 x 3.5); aiming at the rise is left to the
    tie-break. With the gaps equal the two aims make the same choices."""
    obj = {"rgb": [0.5, 0.5, 0.5], "extent_cm": [3.0, 3.0, 5.0], "fill": 0.785, "mass_g": 100.0}
    ctx = lambda level, place: {"surface": 0.15, "width": 0.3, "level": level, "place": place}
    options = [dict(obj, context=ctx(0.775, 0.0), gap_cm=1.5), dict(obj, context=ctx(0.6, 1.0), gap_cm=5.0)]
    world = lambda i: (1.8, i == 0)
    explore = [[0, 1], [1, 0]]
    agent = context_agent(_small("paper"), 2)
    right, chosen = play(agent, options, world, {0}, explore, trials=4, seed=1, aim="gap")
    assert chosen == [[0] * 4, [0] * 4] and right == [[True] * 4] * 2
    same = [dict(o, gap_cm=2.0) for o in options]
    runs = [play(context_agent(_small("paper"), 2), same, world, {0}, explore, trials=4, seed=1, aim=aim)
            for aim in ("gap", "rise")]
    assert runs[0] == runs[1]
    with pytest.raises(ValueError, match="aim"):
        play(agent, options, world, {0}, explore, trials=1, aim="nearest")


def test_bench_ablates_the_prior_in_the_extended_model_alone(tmp_path):
    """--ablate prior switches the extended model's priors off; the paper model has none and plays as without it."""
    def bench(*extra):
        r = subprocess.run([sys.executable, str(ROOT / "benches" / "battery.py"), "--seeds", "1", "--orders", "1",
                            "--trials", "5", "--tasks", "solid_vs_hollow", "--out", str(tmp_path), *extra],
                           capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert r.returncode == 0, r.stderr
        lines = r.stdout.splitlines()
        row = next(line for line in lines if line.startswith("solid_vs_hollow")).split()
        return lines[0], row[2:8], row[8:]   # the header, the paper model's columns, the extended model's

    head, paper, extended = bench()
    head_off, paper_off, extended_off = bench("--ablate", "prior")
    assert "prior off (extended)" in head_off and "prior" not in head
    assert paper_off == paper                      # the paper model ran as it is
    assert extended_off != extended, (extended, extended_off)   # the extended model without its priors chose otherwise
