"""The battery's analysis (train/battery/tasks.py, the studies' statistics) on hand-made choices whose answers are computed
by hand: trial-1 intervals, the learning slope with a per-subject intercept (separation included), each subject's
exact binomial test, P(right | previous right) vs P(right | previous wrong), and the agreement with the animals."""

import math

import pytest

from train.battery.tasks import after_outcome, agreement, analyse, learning_slope, proportion, subject_test

Z = 1.959964


def wilson(k, n):
    p = k / n
    centre = (p + Z * Z / (2 * n)) / (1 + Z * Z / n)
    half = Z * math.sqrt(p * (1 - p) / n + Z * Z / (4 * n * n)) / (1 + Z * Z / n)
    return centre - half, centre + half


def test_trial1_rate_and_its_wilson_interval():
    got = proportion(8, 10)
    assert got["rate"] == 0.8 and got["ci"] == pytest.approx(wilson(8, 10), abs=1e-6)
    assert proportion(10, 10)["ci"][1] == pytest.approx(1.0) and proportion(10, 10)["ci"][0] == pytest.approx(
        wilson(10, 10)[0], abs=1e-6)


def test_a_subjects_exact_binomial_test():
    # sum_{i>=15} C(20, i) / 2^20 = 21700 / 2^20
    s = subject_test([True] * 15 + [False] * 5, 0.5)
    assert s["p"] == pytest.approx(21700 / 2 ** 20, abs=1e-12) and s["passed"]
    assert not subject_test([True] * 14 + [False] * 6, 0.5)["passed"]            # p = 0.0577
    assert subject_test([True] * 20, 0.5)["p"] == pytest.approx(0.5 ** 20)


def test_subjects_right_on_every_trial_have_no_slope_to_estimate():
    a = analyse([[True] * 20] * 3, 0.5)
    assert a["trial1"]["k"] == 3 and a["trial1"]["p"] == pytest.approx(1 / 8)
    assert a["slope"]["slope"] == 0.0 and not a["slope"]["learned"] and "not estimable" in a["slope"]["note"]
    assert a["subjects_passed"] == 3 and a["passed"] and a["spread"] == {"min": 1.0, "median": 1.0, "max": 1.0}
    assert a["after"]["after_right"] == 1.0 and math.isnan(a["after"]["after_wrong"])


def test_a_subject_learning_from_trial_10_is_separated_and_tested_exactly():
    """Wrong on 1-9, right on 10-20: the slope is infinite; with no learning, the chance that all 11 right choices
    come last is 1 / C(20, 11)."""
    s = learning_slope([[False] * 9 + [True] * 11])
    assert s["slope"] == math.inf and s["ci"] is None and "separation" in s["note"]
    assert s["p"] == pytest.approx(1 / math.comb(20, 11)) and s["learned"]
    # two subjects, both in order, and one always right (it tells nothing about the slope): the product
    s2 = learning_slope([[False] * 2 + [True] * 3, [False, True, True], [True] * 5])
    assert s2["p"] == pytest.approx(1 / math.comb(5, 3) / math.comb(3, 2)) and s2["subjects"] == 2
    assert s2["learned"]                                                         # 1/30 = 0.033 < 0.05
    one = learning_slope([[False, True]])                                       # 1/2: no evidence
    assert one["p"] == pytest.approx(0.5) and not one["learned"]
    down = learning_slope([[True] * 5 + [False] * 5])
    assert down["slope"] == -math.inf and not down["learned"]


def test_the_slope_is_the_maximum_likelihood_of_a_logit_with_a_subjects_intercept():
    """Oracle: the same likelihood maximised directly (scipy.optimize), not through statsmodels."""
    import numpy as np
    from scipy.optimize import minimize
    right = [[False, True, False, False, True, True, False, True, True, True],
             [True, False, False, True, False, True, True, True, False, True, True, True]]

    def nll(theta):
        total = 0.0
        for j, r in enumerate(right):
            for t, y in enumerate(r, 1):
                eta = theta[0] * t + theta[1 + j]
                total += np.logaddexp(0.0, eta) - y * eta
        return total
    best = minimize(nll, np.zeros(3), method="BFGS", options={"gtol": 1e-8})
    s = learning_slope(right)
    assert s["slope"] == pytest.approx(best.x[0], abs=1e-4) and s["slope"] > 0
    lo, hi = s["ci"]
    assert lo < s["slope"] < hi and s["learned"] == (lo > 0) and s["note"] == ""


def test_right_after_right_against_right_after_wrong():
    # transitions of 1101 and 0011: (1->1), (1->0), (0->1); (0->0), (0->1), (1->1)
    a = after_outcome([[True, True, False, True], [False, False, True, True]])
    assert (a["n_after_right"], a["n_after_wrong"]) == (3, 3)
    assert a["after_right"] == pytest.approx(2 / 3) and a["after_wrong"] == pytest.approx(2 / 3)
    # Fisher's one-sided p for [[2, 1], [2, 1]]: P(X >= 2), X ~ hypergeom(6, 4, 3): (C(4,2)C(2,1) + C(4,3)) / C(6,3)
    assert a["p"] == pytest.approx((6 * 2 + 4) / 20)


def test_agreement_counts_the_tasks_both_did():
    model = {"a": True, "b": False, "c": True, "d": True}
    published = {"a": "passed", "b": "passed", "c": "not tested", "d": "failed"}
    assert agreement(model, published) == (1, 3)
