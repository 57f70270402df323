"""Figure 2's left panel shows knowledge states, so a dominant-to-irrelevant flip (certainty 1 both times) shows."""

import numpy as np

from aesop_torch.rules import PROPERTIES, STATES
from train.figures import MAX_CURVES, STATE_COLOURS, figure2, state_grid


def episode(**states):
    return {"knowledge": {p: {"state": states.get(p, "unknown"), "certainty": 1.0} for p in PROPERTIES},
            "probe_rel_error": 0.5}


def test_a_flip_between_states_of_equal_certainty_is_a_change_of_cell():
    run = [episode(), episode(color="dominant"), episode(color="irrelevant", weight="likely_irrelevant")]
    grid, labels = state_grid([run])
    assert grid.shape == (len(PROPERTIES) + 3, 3) and labels[0].startswith("color")   # 3 gaps between 4
    assert grid[0].tolist() == [STATES.index("unknown"), STATES.index("dominant"), STATES.index("irrelevant")]
    assert grid[labels.index("weight  order 1"), 2] == STATES.index("likely_irrelevant")
    assert len(set(STATE_COLOURS)) == len(STATES)


def test_ten_orders_get_a_row_each_per_property():
    runs = [[episode(size="dominant")] * 8 for _ in range(10)]
    grid, labels = state_grid(runs)
    assert grid.shape == (4 * 10 + 3, 8)                    # 10 rows per property, a gap between properties
    assert np.isnan(grid[10]).all() and labels[11] == "shape  order 1"
    assert state_grid(runs * 2)[0].shape[0] == 4 * MAX_CURVES + 3
    fig = figure2(runs)
    assert len(fig.axes) == 2 and fig.get_figheight() > 4.6   # taller with more rows, so the cells stay readable
