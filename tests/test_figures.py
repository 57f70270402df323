"""Figure 2 as the paper plots it: certainty 0..1 per property with every point's state named, and the error on a
log axis against the senses' floor; a population as medians and bands, not a tangle of curves."""

import math

import numpy as np
from matplotlib.collections import PolyCollection

from aesop_torch.rules import PROPERTIES, STATES
from train.learning.experiment import senses_floor
from train.runner.figures import MAX_CURVES, STATE_LETTERS, figure2, knowledge_arrays, save_figure2

CERT = {"unknown": 0.0, "likely_irrelevant": 0.3, "dominant": 1.0, "irrelevant": 1.0}


def episode(error=0.5, **states):
    return {"knowledge": {p: {"state": states.get(p, "unknown"), "certainty": CERT[states.get(p, "unknown")]}
                          for p in PROPERTIES}, "probe_rel_error": error}


def curves(ax):
    """The lines spanning the episodes (not the floor, which spans the axis)."""
    return [ln for ln in ax.lines if ln.get_transform() == ax.transData]


def letters(ax):
    """{state letter: number of points drawn as it} on an axis."""
    out = {}
    for c in ax.collections:
        if c.get_gid():
            out[c.get_gid()] = out.get(c.get_gid(), 0) + len(c.get_offsets())
    return out


def test_the_left_lines_carry_the_certainties_and_a_flip_at_certainty_one_changes_letter():
    runs = [[episode(), episode(color="dominant"), episode(color="irrelevant", weight="likely_irrelevant")],
            [episode(size="likely_irrelevant"), episode(size="irrelevant"), episode(size="irrelevant")]]
    cert, state = knowledge_arrays(runs)
    assert cert.shape == state.shape == (2, len(PROPERTIES), 3)
    assert state[0, 0].tolist() == [STATES.index(s) for s in ("unknown", "dominant", "irrelevant")]
    fig = figure2(runs)
    left, right = fig.axes
    lines = curves(left)
    assert len(lines) == len(PROPERTIES) * 2                              # a line per property per order
    got = sorted(tuple(ln.get_ydata()) for ln in lines)
    want = sorted(tuple(cert[b, i]) for b in range(2) for i in range(len(PROPERTIES)))
    assert got == want and (0.0, 1.0, 1.0) in got and (0.0, 0.0, 0.3) in got
    assert left.get_ylim()[0] <= 0 and left.get_ylim()[1] >= 1 and left.get_ylim()[1] < 1.2
    # every one of the 2 x 4 x 3 points is drawn as its state's letter: dominant once, irrelevant three times
    drawn = letters(left)
    assert drawn["D"] == 1
    assert drawn["I"] == 3 and drawn["L"] == 2
    assert sum(drawn.values()) == 2 * len(PROPERTIES) * 3 and set(drawn) == set(STATE_LETTERS)
    names = [t.get_text() for t in left.get_legend().get_texts()]
    assert set(PROPERTIES) <= set(names) and "likely irrelevant" in names


def test_the_error_is_on_a_log_axis_against_the_floor():
    runs = [[episode(None), episode(0.5), episode(0.0)], [episode(None), episode(0.2), episode(0.05)]]
    fig = figure2(runs, floor=0.03)
    right = fig.axes[1]
    assert right.get_yscale() == "log"
    floor = [ln for ln in right.lines if ln.get_linestyle() == "--"]
    assert len(floor) == 1 and np.allclose(floor[0].get_ydata(), 3.0)    # percent, across the axis
    assert "floor" in floor[0].get_label()
    orders = curves(right)
    assert [ln.get_xdata().tolist() for ln in orders] == [[2, 3], [2, 3]]   # the None episodes skipped
    assert orders[0].get_ydata()[1] == 0.01 and orders[1].get_ydata().tolist() == [20, 5]   # 0 clipped at 0.01 %
    assert not [ln for ln in figure2(runs).axes[1].lines if ln.get_linestyle() == "--"]   # floor=None: none


def test_a_population_draws_bands_over_all_orders_not_a_curve_each():
    rng = np.random.default_rng(0)
    runs = [[episode(float(rng.uniform(0.01, 1)), color="dominant" if t > b % 4 else "unknown") for t in range(6)]
            for b in range(20)]
    assert len(runs) > MAX_CURVES
    left, right = figure2(runs, floor=0.02).axes
    for ax in (left, right):
        assert any(isinstance(c, PolyCollection) for c in ax.collections)
    assert len(curves(left)) == len(PROPERTIES) and len(curves(right)) == 1   # medians, not 20 curves each
    assert sum(letters(left).values()) == len(PROPERTIES) * 6     # the most common state, on the median
    colour = curves(left)[0].get_ydata()
    assert colour.tolist() == np.median([[1.0 if t > b % 4 else 0.0 for t in range(6)] for b in range(20)],
                                        axis=0).tolist()
    err = np.array([[r["probe_rel_error"] for r in run] for run in runs])
    assert np.allclose(curves(right)[0].get_ydata(), 100 * np.median(err, axis=0))


def test_save_figure2_writes_a_png_and_returns_its_pixels(tmp_path):
    runs = [[episode(0.4, shape="likely_irrelevant"), episode(0.1, shape="dominant")]] * 3
    pixels = save_figure2(runs, tmp_path / "f.png", dpi=50, floor=0.05)
    assert pixels.dtype == np.uint8 and pixels.ndim == 3 and pixels.shape[2] == 3
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_senses_floor_is_the_median_error_of_the_best_sensed_reading():
    floater = {"measurement": {"rgb": [1, 0, 0], "extent_cm": [5, 5, 5], "fill": 0.2, "mass_g": 10.0},
               "archimedes_cm3": 10.5}     # reads min(10, 0.2 * 125 = 25) = 10: 0.5 / 10.5 off
    sinker = {"measurement": {"rgb": [0, 0, 1], "extent_cm": [2, 2, 2], "fill": 1.0, "mass_g": 50.0},
              "archimedes_cm3": 8.0}       # reads min(50, 8) = 8: exact
    assert math.isclose(senses_floor({"a": floater, "b": sinker}), (0.5 / 10.5 + 0.0) / 2)
    assert math.isclose(senses_floor({"a": floater}), 0.047619, rel_tol=1e-4)
    assert senses_floor({}) is None


def test_a_population_run_bands_the_error_over_all_its_orders_and_states_the_disagreement(tmp_path):
    """Two orders run in detail, four in the population: the right panel's median and bands are the counted
    quantiles of the population's four orders, not the two runs'. By hand, episode 1: errors 0.1, 0.1, 0.1, 0.5
    (positions 0..3, q at 3 q): median 0.1, 75 % 0.1 + 0.25 x 0.4 = 0.2, 90 % 0.1 + 0.7 x 0.4 = 0.38; episode 2:
    0.02 for all four."""
    runs = [[episode(0.9), episode(0.9, color="dominant")], [episode(0.8), episode(0.8)]]
    population = {"orders": 4, "agree_fraction": 0.75, "most_common_knowledge": "ILDD",
                  "curves": {"probe_rel_error": [{"values": [0.5, 0.1], "counts": [1, 3], "none": 0},
                                                 {"values": [0.02], "counts": [4], "none": 0}]}}
    left, right = figure2(runs, floor=0.01, population=population).axes
    med = curves(right)
    assert len(med) == 1 and np.allclose(med[0].get_ydata(), [10.0, 2.0])          # percent
    bands = [c for c in right.collections if isinstance(c, PolyCollection)]
    tops = sorted(max(y for x, y in c.get_paths()[0].vertices if x == 1) for c in bands)
    bottoms = [min(y for x, y in c.get_paths()[0].vertices if x == 1) for c in bands]
    assert np.allclose(tops, [20.0, 38.0]) and np.allclose(bottoms, [10.0, 10.0])
    labels = [t.get_text() for t in right.get_legend().get_texts()]
    assert "10%-90% of orders" in labels and "25%-75% of orders" in labels
    title = right.get_title()
    assert "orders: 4" in title and "quantiles" in title and "25.0% of orders (1 of 4)" in title and "ILDD" in title
    assert "first 2 of 4" in left.get_title()
    pixels = save_figure2(runs, tmp_path / "pop.png", dpi=40, floor=0.01, population=population)
    assert pixels.ndim == 3 and (tmp_path / "pop.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_many_runs_without_a_population_state_their_own_disagreement():
    """Thirteen orders in detail (more than MAX_CURVES), four of them ending with colour dominant: 4 of 13 disagree
    with the majority (all unknown, UUUU)."""
    runs = [[episode(0.5), episode(0.2, color="dominant" if b < 4 else "unknown")] for b in range(13)]
    assert len(runs) > MAX_CURVES
    title = figure2(runs).axes[1].get_title()
    assert "orders: 13" in title and f"{4 / 13:.1%} of orders (4 of 13)" in title and "UUUU" in title


def test_a_model_with_contexts_draws_its_certainty_per_context():
    """Records with certainty_by_context (the contextual model's floating, sinking, fate) get a panel per context,
    a line per property of the split five, at the certainty the records hold (median over the orders)."""
    split = ("color", "fill", "elongation", "size", "weight")

    def rec(t):
        by = {c: {p: (1.0 if (c, p) == ("fate", "weight") and t > 0 else 0.0) for p in split}
              for c in ("floating", "sinking", "fate")}
        return {"knowledge": {p: {"state": "unknown", "certainty": 0.0} for p in split}, "probe_rel_error": 0.5,
                "certainty_by_context": by}

    fig = figure2([[rec(0), rec(1)], [rec(0), rec(1)]])
    assert len(fig.axes) == 5
    fate = fig.axes[4]
    assert fate.get_ylabel() == "fate" and len(fate.lines) == len(split)
    weight = [ln for ln in fate.lines if ln.get_label() == "weight"][0]
    assert list(weight.get_ydata()) == [0.0, 1.0]
    assert all(list(ln.get_ydata()) == [0.0, 0.0] for ln in fig.axes[2].lines)     # floating: nothing known


def test_the_left_legend_says_which_line_is_which_order_and_property():
    """Three orders: each property's three lines drawn with three dash patterns, the same pattern for an order in
    every property, each line labelled with its property and order, and the legend naming the properties (colours)
    and the orders (patterns); a banded panel names its line the median of its orders."""
    runs = [[episode(), episode(color="dominant")], [episode(), episode()], [episode(size="irrelevant")] * 2]
    left = figure2(runs).axes[0]
    lines = curves(left)
    assert len(lines) == 3 * len(PROPERTIES)
    assert sorted(ln.get_label() for ln in lines) == sorted(f"{p}, order {b}" for p in PROPERTIES for b in (1, 2, 3))
    dashes = lambda ln: (ln.get_linestyle(), ln._unscaled_dash_pattern)   # noqa: E731  '--' for every pattern else
    style = {ln.get_label(): dashes(ln) for ln in lines}
    for b in (1, 2, 3):   # one pattern per order, whatever the property
        assert len({style[f"{p}, order {b}"] for p in PROPERTIES}) == 1
    assert len({style[f"color, order {b}"] for b in (1, 2, 3)}) == 3
    legend = left.get_legend()
    names = [t.get_text() for t in legend.get_texts()]
    assert {"order 1", "order 2", "order 3"} <= set(names) and set(PROPERTIES) <= set(names)
    drawn = {t.get_text(): h for t, h in zip(legend.get_texts(), legend.legend_handles)}
    for b in (1, 2, 3):   # the legend's pattern for an order is its lines'
        assert dashes(drawn[f"order {b}"]) == style[f"color, order {b}"]
    banded = figure2([[episode(), episode()]] * (MAX_CURVES + 1)).axes[0].get_legend()
    assert f"median of {MAX_CURVES + 1} orders" in [t.get_text() for t in banded.get_texts()]
