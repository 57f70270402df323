"""The paper's Figure 2 from a run: left, the certainty of each property's causal knowledge after every episode;
right, the prediction error against Archimedes over episodes, against the floor the robot's senses leave.

As the paper plots them: certainty on a 0..1 axis, one colour per property, and every point names its state by its
letter (dominant and irrelevant both have certainty 1, so the letter is what tells a flip from one to the other).
The error on a log axis: it falls by orders of magnitude, and a learner can only approach, never pass, the error of
the best reading of Archimedes its senses allow (the dashed floor, `train.learning.experiment.senses_floor`).
More than MAX_CURVES orders are drawn as medians with bands. A population run (`train.learning.population`, every order of
the set) passes its per-episode errors: the right panel's median and 25-75 % / 10-90 % bands are then over ALL its
orders, weighted by how many orders share each error, and the share of orders whose final knowledge is not the
majority's is stated (a few dozen lexicographic orders hid that 43 % of a 9-object set's orders disagreed).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402
from matplotlib.ticker import FuncFormatter, MaxNLocator, NullFormatter  # noqa: E402

from aesop_torch.names import OBJECT_PROPERTIES, PROPERTIES, STATES, object_properties  # noqa: E402
from train.common.quantiles import weighted_quantiles  # noqa: E402

MAX_CURVES = 12  # orders drawn one by one; with more, medians and bands over all orders (a person reads ~12 curves)
STATE_LETTERS = "ULDI"   # per names.STATES: unknown, likely irrelevant, dominant, irrelevant
STATE_MARKERS = tuple(rf"$\mathbf{{{ch}}}$" for ch in STATE_LETTERS)   # each point drawn as its state's letter
# per names.OBJECT_PROPERTIES (ColorBrewer Dark2): shape, fill and elongation apart, the rest as before
PROPERTY_COLOURS = ("#1b9e77", "#d95f02", "#66a61e", "#e6ab02", "#7570b3", "#e7298a")
ERROR_CLIP = 1e-4        # errors below (a fraction: 0.01 %), exact zeros included, drawn there on the log axis
BAND = (0.1, 0.9)        # a population's band: these quantiles over orders
ERROR_BANDS = (BAND, (0.25, 0.75))   # the error's bands, wide then narrow: the spread and the middle half of orders
# the left panel's line of each order (up to MAX_CURVES): the colour is the property's, the dashes the order's
ORDER_DASHES = ("-", (0, (5, 2)), (0, (1, 1.5)), (0, (6, 2, 1, 2)), (0, (10, 3)), (0, (2, 3)), (0, (6, 2, 1, 2, 1, 2)),
                (0, (1, 4)), (0, (12, 2, 3, 2)), (0, (4, 1, 1, 1)), (0, (8, 2, 1, 2, 1, 2, 1, 2)), (0, (3, 5)))
assert len(ORDER_DASHES) >= MAX_CURVES
assert len(STATE_LETTERS) == len(STATES) and len(PROPERTY_COLOURS) == len(OBJECT_PROPERTIES)


def _properties(runs: list[list[dict]]) -> tuple:
    """The object's properties the runs' knowledge names (the paper's four, or the split five)."""
    first = next((r[0]["knowledge"] for r in runs if r), {})
    return object_properties(first) or PROPERTIES


def knowledge_arrays(runs: list[list[dict]]) -> tuple[np.ndarray, np.ndarray]:
    """(certainty, state code), both (orders, properties, episodes); NaN and -1 past the end of a shorter order."""
    n = max((len(r) for r in runs), default=0)
    props = _properties(runs)
    cert = np.full((len(runs), len(props), n), np.nan)
    state = np.full(cert.shape, -1, dtype=int)
    for b, run in enumerate(runs):
        for t, rec in enumerate(run):
            for i, p in enumerate(props):
                cert[b, i, t] = rec["knowledge"][p]["certainty"]
                state[b, i, t] = STATES.index(rec["knowledge"][p]["state"])
    return cert, state


def error_array(runs: list[list[dict]]) -> np.ndarray:
    """(orders, episodes) probe error as a fraction, clipped below at ERROR_CLIP; NaN where there is none."""
    n = max((len(r) for r in runs), default=0)
    err = np.full((len(runs), n), np.nan)
    for b, run in enumerate(runs):
        err[b, :len(run)] = [np.nan if r["probe_rel_error"] is None else r["probe_rel_error"] for r in run]
    return np.where(np.isnan(err), np.nan, np.maximum(err, ERROR_CLIP))


def _median_band(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Median, low and high quantile (BAND) over axis 0, NaN where no order has a value (without numpy's warning)."""
    some = ~np.isnan(a).all(axis=0)
    out = np.full((3,) + a.shape[1:], np.nan)
    out[:, some] = np.nanquantile(a[:, some], (0.5,) + BAND, axis=0)
    return out[0], out[1], out[2]


def error_bands(runs: list[list[dict]], population: dict | None = None) -> tuple[int, np.ndarray]:
    """(orders counted, (1 + 2 len(ERROR_BANDS), episodes) quantiles of the probe error, a fraction: the median, then
    each band's low and high). From population["curves"] (every order, weighted by its count) when given, else from
    the runs, one each. Orders without a prediction yet are left out of an episode; NaN where none has one."""
    qs = (0.5,) + tuple(q for band in ERROR_BANDS for q in band)
    if population is not None:
        eps = population["curves"]["probe_rel_error"]
        per_episode = [(e["values"], e["counts"]) for e in eps]
        n = int(population["orders"])
    else:
        n = len(runs)
        per_episode = []
        for t in range(max((len(r) for r in runs), default=0)):
            vals = [r[t]["probe_rel_error"] for r in runs if len(r) > t and r[t]["probe_rel_error"] is not None]
            per_episode.append((vals, [1] * len(vals)))
    out = np.array([weighted_quantiles(v, c, qs) for v, c in per_episode]).reshape(-1, len(qs)).T
    return n, np.where(np.isnan(out), np.nan, np.maximum(out, ERROR_CLIP))


def disagreement(runs: list[list[dict]], population: dict | None = None) -> tuple[float, int, int, str]:
    """(share, count, orders, majority key) of the orders whose final knowledge is not the most common one: the
    population's when given, else the runs' (keys as train.runner.summary's: one letter of STATE_LETTERS per property)."""
    if population is not None:
        n = int(population["orders"])
        share = 1.0 - float(population["agree_fraction"])
        return share, round(share * n), n, population["most_common_knowledge"]
    keys = ["".join(STATE_LETTERS[STATES.index(r[-1]["knowledge"][p]["state"])] for p in _properties(runs))
            for r in runs if r]
    if not keys:
        return 0.0, 0, 0, ""
    common = max(dict.fromkeys(keys), key=keys.count)   # ties: the first seen, as train.learning.population.agreement
    other = sum(k != common for k in keys)
    return other / len(keys), other, len(keys), common


def _letters(ax, x: np.ndarray, y: np.ndarray, state: np.ndarray, colour: str, alpha: float) -> None:
    """Each point (x, y) drawn as its state's letter; y and state (orders, episodes) or (episodes,), state -1 drawn
    nowhere. Past 30 episodes only where the state changes (and the first and last), so the letters stay legible."""
    shown = np.ones(state.shape, dtype=bool)
    if state.shape[-1] > 30:
        shown[..., 1:-1] = state[..., 1:-1] != state[..., :-2]
    for s, marker in enumerate(STATE_MARKERS):
        on = (state == s) & shown & ~np.isnan(y)
        if on.any():
            ax.scatter(np.broadcast_to(x, y.shape)[on], y[on], marker=marker, s=45, color=colour, alpha=alpha,
                       linewidths=0, zorder=3, gid=STATE_LETTERS[s])


def _context_panels(fig, axes, runs: list[list[dict]], contexts: list, xs) -> None:
    """Certainty per property within each context (records' certainty_by_context): the median over orders."""
    props = _properties(runs)
    for ax, c in zip(axes, contexts):
        for p in props:
            v = np.full((len(runs), len(xs)), np.nan)
            for b, run in enumerate(runs):
                for t, rec in enumerate(run):
                    v[b, t] = rec.get("certainty_by_context", {}).get(c, {}).get(p, np.nan)
            with warnings.catch_warnings():   # an episode past a shorter order's end: NaN, not a warning
                warnings.simplefilter("ignore", RuntimeWarning)
                med = np.nanmedian(v, axis=0)
            ax.plot(xs, med, linewidth=1.3,
                    color=PROPERTY_COLOURS[OBJECT_PROPERTIES.index(p)], label=p)
        ax.set_ylim(-0.06, 1.08)
        ax.set_ylabel(c, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.25, linewidth=0.5)
    axes[0].set_title("certainty per context (median over orders)", fontsize=9)
    axes[-1].set_xlabel("episode")
    axes[0].legend(fontsize=6, ncol=len(props), loc="lower center", bbox_to_anchor=(0.5, 1.12), frameon=False)


def figure2(runs: list[list[dict]], floor: float | None = None, population: dict | None = None):
    """runs: per order, the episode records of summary.json; floor: the senses' error (a fraction, drawn dashed
    on the right; None draws none); population: a population run's {"orders", "agree_fraction",
    "most_common_knowledge", "curves"} (`run_population(..., curves=True)`), whose bands the right panel draws over
    every order (the left stays the runs', the orders run in detail). Returns a matplotlib Figure. Errors are drawn
    in percent."""
    cert, state = knowledge_arrays(runs)
    err = error_array(runs)
    n_orders, _, n_eps = cert.shape
    xs = np.arange(1, n_eps + 1)
    banded = n_orders > MAX_CURVES
    contexts = next((list(r[0]["certainty_by_context"]) for r in runs if r and "certainty_by_context" in r[0]), [])
    if contexts:   # a model with knowledge per context: a third column, its certainty per context
        fig = plt.figure(figsize=(18, 5.6))
        grid = fig.add_gridspec(len(contexts), 3, width_ratios=[3, 2, 2])
        left, right = fig.add_subplot(grid[:, 0]), fig.add_subplot(grid[:, 1])
        _context_panels(fig, [fig.add_subplot(grid[k, 2]) for k in range(len(contexts))], runs, contexts, xs)
    else:
        fig, (left, right) = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [3, 2]})
    # a small sideways step per property, so equal certainties (all 0 at first, 1 once decided) stay apart
    props = _properties(runs)
    colours = [PROPERTY_COLOURS[OBJECT_PROPERTIES.index(p)] for p in props]
    dodge = (np.arange(len(props)) - (len(props) - 1) / 2) * min(0.12, 4.0 / max(n_eps, 1))
    for i, colour in enumerate(colours):
        x = xs + dodge[i]
        if banded:
            med, lo, hi = _median_band(cert[:, i])
            left.fill_between(xs, lo, hi, facecolor=to_rgba(colour, 0.12), edgecolor=to_rgba(colour, 0.6),
                              linewidth=0.6)
            left.plot(x, med, color=colour, linewidth=1.6)
            # the state most orders are in, on the median
            counts = (state[:, i, :, None] == np.arange(len(STATES))).sum(axis=0)
            _letters(left, x, med, np.where(counts.any(axis=1), counts.argmax(axis=1), -1), colour, 0.95)
        else:
            alpha = 0.9 if n_orders == 1 else max(0.3, 0.9 / np.sqrt(n_orders))
            for b in range(n_orders):
                left.plot(x, cert[b, i], color=colour, linewidth=0.9, alpha=alpha, linestyle=ORDER_DASHES[b],
                          label=f"{props[i]}, order {b + 1}")
            _letters(left, x, cert[:, i], state[:, i], colour, min(1.0, alpha + 0.2))
    left.set_ylim(-0.06, 1.08)
    left.set_yticks(np.linspace(0, 1, 6))
    left.set_ylabel("certainty")
    how = f"median, {BAND[0]:.0%}-{BAND[1]:.0%} band and most orders' state of {n_orders} orders" if banded else \
        f"{n_orders} order{'s' * (n_orders != 1)}, one line each"
    if population is not None:
        first = f"the first {n_orders} of {int(population['orders']):,} orders, run in detail"
        how = how.replace(f"of {n_orders} orders", f"of {first}") if banded else f"{first}, one line each"
    left.set_title(f"causal knowledge per property after each episode{chr(10) if population else ' '}({how})",
                   fontsize=9)
    # which line is which: the colour names the property, the dashes the order (a banded panel: the median of all),
    # the letter the state
    handles = []
    for p, colour in zip(props, colours):
        handles.append(Line2D([], [], color=colour, linewidth=2, label=p))
    for s, marker in zip(STATES, STATE_MARKERS):
        handles.append(Line2D([], [], color="black", marker=marker, markersize=7, linestyle="none",
                              label=s.replace("_", " ")))
    if banded:
        orders = [Line2D([], [], color="black", linewidth=1.6, label=f"median of {n_orders} orders")]
    else:
        orders = [Line2D([], [], color="black", linewidth=0.9, linestyle=ORDER_DASHES[b], label=f"order {b + 1}")
                  for b in range(n_orders)]
    ncol = max(len(props), len(STATES))   # the legend fills column by column: a property, a state, orders
    rows = 2 + -(-len(orders) // ncol)
    columns = []
    for k in range(ncol):
        column = handles[k:k + 1] if k < len(props) else []
        column += handles[len(props) + k:len(props) + k + 1] if k < len(STATES) else []
        column += orders[k::ncol]
        columns += column + [Line2D([], [], linestyle="none", label="")] * (rows - len(column))
    left.legend(handles=columns, fontsize=7, ncol=ncol, loc="upper center", bbox_to_anchor=(0.5, -0.12),
                frameon=False)

    pct = 100 * err
    title = "prediction error vs Archimedes (probe objects)"
    if banded or population is not None:
        n_err, q = error_bands(runs, population)
        q = 100 * q
        ex = np.arange(1, q.shape[1] + 1)
        for k, (band, alpha) in enumerate(zip(ERROR_BANDS, (0.2, 0.35))):
            right.fill_between(ex, q[1 + 2 * k], q[2 + 2 * k], color="#3182bd", alpha=alpha, linewidth=0,
                               label=f"{band[0]:.0%}-{band[1]:.0%} of orders")
        right.plot(ex, q[0], color="#08519c", marker=".", linewidth=1.5, label="median of orders")
        share, other, n_keys, common = disagreement(runs, population)
        title = (f"prediction error vs Archimedes (probe objects)\norders: {n_err:,}"
                 f"{' (all of the population)' if population is not None else ''}; bands: quantiles over orders\n"
                 f"final knowledge not the majority's ({common}): {share:.1%} of orders ({other:,} of {n_keys:,})")
    else:
        colours = plt.get_cmap("tab20" if n_orders > 10 else "tab10").colors
        for b in range(n_orders):
            ok = ~np.isnan(pct[b])
            right.plot(xs[ok], pct[b, ok], marker=".", linewidth=1, color=colours[b % len(colours)],
                       label=f"order {b + 1}")
    if floor is not None:
        right.axhline(100 * max(floor, ERROR_CLIP), color="black", linestyle="--", linewidth=1.2,
                      label=f"senses' floor ({100 * floor:.2g} %)")
    right.set_yscale("log")
    plain = FuncFormatter(lambda v, _: f"{v:g}")   # 0.01, 1, 100 rather than 10^-2
    right.yaxis.set_major_formatter(plain)
    lo, hi = right.get_ylim()
    right.yaxis.set_minor_formatter(plain if hi < 10 * lo else NullFormatter())   # within a decade: 2, 3, ... too
    right.set_title(title, fontsize=9)
    right.set_ylabel("median |predicted - Archimedes| / Archimedes (%, log)")
    right.legend(fontsize=7, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.12), frameon=False)
    for ax in (left, right):
        ax.set_xlabel("episode")
        ax.grid(alpha=0.25, linewidth=0.5)
        if n_eps <= 30:   # every episode; a long life gets matplotlib's few round ticks
            ax.set_xticks(xs)
        else:
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    fig.tight_layout()
    return fig


def save_figure2(runs: list[list[dict]], path, dpi: int = 110, floor: float | None = None,
                 population: dict | None = None) -> np.ndarray:
    """figure2(runs, floor, population) drawn once: written to `path` as PNG (the bytes `savefig(path, dpi=dpi)`
    writes) and returned as pixels, (H, W, 3) uint8, for tensorboard. The runner calls it on a worker while the goal
    trials play."""
    fig = figure2(runs, floor=floor, population=population)
    try:
        fig.set_dpi(dpi)
        fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())
        plt.imsave(path, rgba, format="png", dpi=dpi)
        return rgba[..., :3].copy()
    finally:
        plt.close(fig)
