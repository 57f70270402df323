"""The paper's Figure 2 from a run: left, the certainty of each property's causal knowledge after every episode;
right, the prediction error against Archimedes over episodes, against the floor the robot's senses leave.

As the paper plots them: certainty on a 0..1 axis, one colour per property, and every point names its state by its
letter (dominant and irrelevant both have certainty 1, so the letter is what tells a flip from one to the other).
The error on a log axis: it falls by orders of magnitude, and a learner can only approach, never pass, the error of
the best reading of Archimedes its senses allow (the dashed floor, `train.experiment.senses_floor`).
A population (more than MAX_CURVES orders) is drawn as medians with 10-90 % bands over all its orders.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402
from matplotlib.ticker import FuncFormatter, MaxNLocator, NullFormatter  # noqa: E402

from aesop_torch.rules import PROPERTIES, STATES  # noqa: E402

MAX_CURVES = 12  # orders drawn one by one; with more, medians and bands over all orders (a person reads ~12 curves)
STATE_LETTERS = "ULDI"   # per rules.STATES: unknown, likely irrelevant, dominant, irrelevant
STATE_MARKERS = tuple(rf"$\mathbf{{{ch}}}$" for ch in STATE_LETTERS)   # each point drawn as its state's letter
PROPERTY_COLOURS = ("#1b9e77", "#d95f02", "#7570b3", "#e7298a")   # per rules.PROPERTIES (ColorBrewer Dark2)
ERROR_CLIP = 1e-4        # errors below (a fraction: 0.01 %), exact zeros included, drawn there on the log axis
BAND = (0.1, 0.9)        # a population's band: these quantiles over orders
assert len(STATE_LETTERS) == len(STATES) and len(PROPERTY_COLOURS) == len(PROPERTIES)


def knowledge_arrays(runs: list[list[dict]]) -> tuple[np.ndarray, np.ndarray]:
    """(certainty, state code), both (orders, properties, episodes); NaN and -1 past the end of a shorter order."""
    n = max((len(r) for r in runs), default=0)
    cert = np.full((len(runs), len(PROPERTIES), n), np.nan)
    state = np.full(cert.shape, -1, dtype=int)
    for b, run in enumerate(runs):
        for t, rec in enumerate(run):
            for i, p in enumerate(PROPERTIES):
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


def figure2(runs: list[list[dict]], floor: float | None = None):
    """runs: per order, the episode records of summary.json; floor: the senses' error (a fraction, drawn dashed
    on the right; None draws none). Returns a matplotlib Figure. Errors are drawn in percent."""
    cert, state = knowledge_arrays(runs)
    err = error_array(runs)
    n_orders, _, n_eps = cert.shape
    xs = np.arange(1, n_eps + 1)
    population = n_orders > MAX_CURVES
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [3, 2]})
    # a small sideways step per property, so equal certainties (all 0 at first, 1 once decided) stay apart
    dodge = (np.arange(len(PROPERTIES)) - (len(PROPERTIES) - 1) / 2) * min(0.12, 4.0 / max(n_eps, 1))
    for i, colour in enumerate(PROPERTY_COLOURS):
        x = xs + dodge[i]
        if population:
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
                left.plot(x, cert[b, i], color=colour, linewidth=0.9, alpha=alpha)
            _letters(left, x, cert[:, i], state[:, i], colour, min(1.0, alpha + 0.2))
    left.set_ylim(-0.06, 1.08)
    left.set_yticks(np.linspace(0, 1, 6))
    left.set_ylabel("certainty")
    how = f"median, {BAND[0]:.0%}-{BAND[1]:.0%} band and most orders' state of {n_orders} orders" if population else \
        f"{n_orders} order{'s' * (n_orders != 1)}, one line each"
    left.set_title(f"causal knowledge per property after each episode ({how})", fontsize=9)
    handles = []
    for p, colour, s, marker in zip(PROPERTIES, PROPERTY_COLOURS, STATES, STATE_MARKERS):   # a column each
        handles.append(Line2D([], [], color=colour, linewidth=2, label=p))
        handles.append(Line2D([], [], color="black", marker=marker, markersize=7, linestyle="none",
                              label=s.replace("_", " ")))
    left.legend(handles=handles, fontsize=7, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.12),
                frameon=False)

    pct = 100 * err
    if population:
        med, lo, hi = _median_band(pct)
        right.fill_between(xs, lo, hi, color="#3182bd", alpha=0.25, linewidth=0,
                           label=f"{BAND[0]:.0%}-{BAND[1]:.0%} of {n_orders} orders")
        right.plot(xs, med, color="#08519c", marker=".", linewidth=1.5, label="median")
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
    right.set_title("prediction error vs Archimedes (probe objects)", fontsize=9)
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


def save_figure2(runs: list[list[dict]], path, dpi: int = 110, floor: float | None = None) -> np.ndarray:
    """figure2(runs, floor) drawn once: written to `path` as PNG (the bytes `savefig(path, dpi=dpi)` writes) and
    returned as pixels, (H, W, 3) uint8, for tensorboard. The runner calls it on a worker while the goal trials
    play."""
    fig = figure2(runs, floor=floor)
    try:
        fig.set_dpi(dpi)
        fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())
        plt.imsave(path, rgba, format="png", dpi=dpi)
        return rgba[..., :3].copy()
    finally:
        plt.close(fig)
