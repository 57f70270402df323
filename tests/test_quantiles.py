"""train.common.quantiles.weighted_quantiles: numpy's linear quantile of the values repeated by their counts."""

import numpy as np
import pytest

from train.common.quantiles import weighted_quantiles


def test_hand_computed_quantiles_of_counted_values():
    # values 3, 1, 2 held by 1, 1, 2 orders: the list 1, 2, 2, 3 (positions 0..3; q at position 3 q)
    got = weighted_quantiles([3.0, 1.0, 2.0], [1, 1, 2], [0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0])
    # 0.1: position 0.3, 1 + 0.3 (2 - 1); 0.25: 0.75 -> 1.75; 0.5: 1.5 -> 2; 0.75: 2.25 -> 2.25; 0.9: 2.7 -> 2.7
    assert np.allclose(got, [1.0, 1.3, 1.75, 2.0, 2.25, 2.7, 3.0], rtol=0, atol=1e-12)


def test_a_zero_count_is_no_order_and_unit_counts_are_plain_quantiles():
    assert np.allclose(weighted_quantiles([5.0, 100.0, 7.0], [1, 0, 1], [0.5]), [6.0])
    rng = np.random.default_rng(1)
    v, c = rng.uniform(size=7), rng.integers(0, 5, size=7)
    qs = [0.1, 0.25, 0.5, 0.75, 0.9]
    assert np.allclose(weighted_quantiles(v, c, qs), np.quantile(np.repeat(v, c), qs), rtol=0, atol=1e-12)
    assert np.allclose(weighted_quantiles(v, np.ones(7), qs), np.quantile(v, qs), rtol=0, atol=1e-12)


def test_no_orders_give_nan_and_bad_input_one_clear_error():
    assert np.isnan(weighted_quantiles([], [], [0.5, 0.9])).all()
    assert np.isnan(weighted_quantiles([1.0], [0], [0.5])).all()
    with pytest.raises(ValueError, match="2 values but 1 counts"):
        weighted_quantiles([1.0, 2.0], [1], [0.5])
    with pytest.raises(ValueError, match="whole numbers"):
        weighted_quantiles([1.0, 2.0], [1, 0.5], [0.5])
    with pytest.raises(ValueError, match="whole numbers"):
        weighted_quantiles([1.0, 2.0], [1, -1], [0.5])
    with pytest.raises(ValueError, match="0..1"):
        weighted_quantiles([1.0], [1], [1.5])
