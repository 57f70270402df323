"""The battery's field statistics (train/battery/analysis.py) on hand-made choices: the conditional logit's slope
against statsmodels' ConditionalLogit, its likelihood-ratio interval under separation, Holm's correction, the paired
transfer gain and the project's learned rule."""

import math
import random

import numpy as np
import pytest

from train.battery.analysis import (CHI2_95, conditional_logit_slope, conditional_loglik, holm, learned_tasks,
                                 mean_interval, paired_gain)


def test_the_slope_is_statsmodels_conditional_logit():
    from statsmodels.discrete.conditional_models import ConditionalLogit
    rng = random.Random(3)
    right = [[rng.random() < 0.3 + 0.03 * t for t in range(20)] for _ in range(8)]
    s = conditional_logit_slope(right)
    y = np.array([x for r in right for x in r], float)
    t = np.array([i + 1 for r in right for i in range(len(r))], float)[:, None]
    g = np.array([j for j, r in enumerate(right) for _ in r])
    fit = ConditionalLogit(y, t, groups=g).fit(disp=0)
    assert s["slope"] == pytest.approx(float(fit.params[0]), abs=1e-5)
    lo, hi = s["ci"]
    assert lo < s["slope"] < hi and s["subjects"] == s["n"] == 8
    # the interval's ends are where the likelihood ratio reaches the chi-square's 95 % point
    top = conditional_loglik(right, s["slope"])
    for end in (lo, hi):
        assert 2 * (top - conditional_loglik(right, end)) == pytest.approx(CHI2_95, abs=1e-4)


def test_one_subjects_conditional_likelihood_by_hand():
    """One subject right on trials 2 and 3 of 3: P = e^{5b} / (e^{3b} + e^{4b} + e^{5b})."""
    b = 0.7
    want = 5 * b - math.log(math.exp(3 * b) + math.exp(4 * b) + math.exp(5 * b))
    assert conditional_loglik([[False, True, True]], b) == pytest.approx(want, abs=1e-12)


def test_under_separation_the_interval_is_bounded_below_only():
    """Wrong on 1-9, right on 10-20: the slope is infinite, the interval [lo, inf) with lo > 0 where the ratio to
    the supremum (every right trial last: conditional probability 1) is the chi-square point."""
    s = conditional_logit_slope([[False] * 9 + [True] * 11])
    assert s["slope"] == math.inf and s["separated"] == 1
    lo, hi = s["ci"]
    assert hi == math.inf and lo > 0
    assert -2 * conditional_loglik([[False] * 9 + [True] * 11], lo) == pytest.approx(CHI2_95, abs=1e-4)
    assert s["p"] < 1e-4
    flat = conditional_logit_slope([[True] * 20] * 3)
    assert flat["subjects"] == 0 and flat["n"] == 3 and flat["p"] == 1.0


def test_holm_and_the_learned_rule():
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    t1 = {"a": {"ci": (0.3, 0.6)}, "b": {"ci": (0.55, 0.9)}, "c": {"ci": (0.2, 0.5)}}
    slopes = {"a": {"p": 0.001, "slope": 0.5}, "b": {"p": 0.001, "slope": 0.5}, "c": {"p": 0.03, "slope": 0.2}}
    got = learned_tasks(t1, slopes, {"a": 0.5, "b": 0.5, "c": 0.5})
    # a: at chance and p 0.003 after Holm; b: above chance on trial 1; c: Holm p 0.03 x 1 = 0.03 (last step)
    assert got["a"] == (True, pytest.approx(0.003)) and not got["b"][0] and got["c"][0]


def test_the_paired_gain():
    treated, control = {1: 0.9, 2: 0.8, 3: 1.0}, {1: 0.5, 2: 0.6, 3: 0.5, 4: 0.1}
    g = paired_gain(treated, control)
    d = [0.4, 0.2, 0.5]
    m = sum(d) / 3
    sd = math.sqrt(sum((x - m) ** 2 for x in d) / 2)
    assert g["n"] == 3 and g["mean"] == pytest.approx(m)
    assert g["ci"][1] - m == pytest.approx(4.302653 * sd / math.sqrt(3), abs=1e-5)    # t(0.975, 2)
    assert paired_gain({1: 0.5}, {1: 0.5})["p"] == 1.0
    assert mean_interval([0.7])["ci"] == (0.7, 0.7)
