"""The paper's Figure 2 from a run: left, the causal knowledge *state* of each property after every episode, one row
per order; right, prediction error against Archimedes over episodes, one curve per order.

The left panel shows states, not certainty: dominant and irrelevant both have certainty 1, so a certainty curve
hides a property flipping from one to the other (and lines of equal certainty sit on top of each other). Each state
has its own colour and letter, so every flip in every order is a change of cell along a row.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import BoundaryNorm, ListedColormap  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from aesop_torch.rules import PROPERTIES, STATES  # noqa: E402

MAX_CURVES = 12  # orders drawn (rows per property on the left, curves on the right); a person reads about this many
# one colour per rules.STATES entry, in its order: grey = nothing known, pale orange = leaning irrelevant,
# blue = dominant, red = irrelevant (dominant and irrelevant far apart in hue and lightness, also in grey print)
STATE_COLOURS = ("#d9d9d9", "#fdc086", "#2c7fb8", "#d7301f")
STATE_LETTERS = "ULDI"
assert len(STATE_COLOURS) == len(STATE_LETTERS) == len(STATES)


def state_grid(runs: list[list[dict]]) -> tuple[np.ndarray, list[str]]:
    """(rows, episodes) state codes (NaN: a gap between properties) and the row labels: per property, one row per
    order (at most MAX_CURVES orders)."""
    shown = runs[:MAX_CURVES]
    n = max((len(r) for r in shown), default=0)
    rows, labels = [], []
    for i, p in enumerate(PROPERTIES):
        if i:
            rows.append([np.nan] * n)
            labels.append("")
        for b, run in enumerate(shown):
            rows.append([STATES.index(e["knowledge"][p]["state"]) for e in run] + [np.nan] * (n - len(run)))
            labels.append(f"{p}  order {b + 1}" if b == 0 else f"{b + 1}")
    return np.array(rows, dtype=float).reshape(len(rows), n), labels


def figure2(runs: list[list[dict]]):
    """runs: per order, the episode records of summary.json. Returns a matplotlib Figure."""
    grid, labels = state_grid(runs)
    n_rows, n_eps = grid.shape
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, max(4.6, 1.2 + 0.16 * n_rows)),
                                      gridspec_kw={"width_ratios": [3, 2]})
    cmap = ListedColormap(STATE_COLOURS).with_extremes(bad="white")
    left.imshow(np.ma.masked_invalid(grid), cmap=cmap, norm=BoundaryNorm(np.arange(len(STATES) + 1) - 0.5, cmap.N),
                aspect="auto", interpolation="nearest", extent=(0.5, n_eps + 0.5, n_rows - 0.5, -0.5))
    if n_rows * n_eps <= 800:   # letters too, for print and colour-blind readers, while cells are large enough
        for r, c in zip(*np.nonzero(~np.isnan(grid))):
            code = int(grid[r, c])
            left.text(c + 1, r, STATE_LETTERS[code], ha="center", va="center", fontsize=6,
                      color="white" if code >= 2 else "black")
    left.set_yticks(range(n_rows), labels, fontsize=6)
    left.tick_params(axis="y", length=0)
    if n_eps <= 30:   # every episode; a long life gets matplotlib's few round ticks
        left.set_xticks(range(1, n_eps + 1))
    else:
        left.xaxis.set_major_locator(MaxNLocator(integer=True))
    left.set_xlabel("episode (objects in each order's own sequence)")
    more = f" (first {MAX_CURVES} of {len(runs)} orders)" if len(runs) > MAX_CURVES else ""
    left.set_title("causal knowledge per property after each episode" + more, fontsize=9)
    left.legend(handles=[Patch(color=c, label=f"{ch} {s.replace('_', ' ')}")
                         for c, ch, s in zip(STATE_COLOURS, STATE_LETTERS, STATES)],
                fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.08 if n_rows > 20 else -0.14), ncol=4,
                frameon=False)
    for i, run in enumerate(runs[:MAX_CURVES]):
        xs = [t + 1 for t, r in enumerate(run) if r["probe_rel_error"] is not None]
        ys = [100 * r["probe_rel_error"] for r in run if r["probe_rel_error"] is not None]
        right.plot(xs, ys, marker=".", label=f"order {i + 1}")
    right.set_title("prediction error vs Archimedes (probe objects)" + more, fontsize=9)
    right.set_xlabel("episode")
    right.set_ylabel("median |predicted - Archimedes| / Archimedes (%)")
    if n_eps > 30:    # a long life: the tail matters, where the error is a few percent
        right.set_yscale("log")
    right.legend(fontsize=7)
    fig.tight_layout()
    return fig


def save_figure2(runs: list[list[dict]], path, dpi: int = 110) -> np.ndarray:
    """figure2(runs) drawn once: written to `path` as PNG (the bytes `savefig(path, dpi=dpi)` writes) and returned
    as pixels, (H, W, 3) uint8, for tensorboard. The runner calls it on a worker while the goal trials play."""
    fig = figure2(runs)
    try:
        fig.set_dpi(dpi)
        fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())
        plt.imsave(path, rgba, format="png", dpi=dpi)
        return rgba[..., :3].copy()
    finally:
        plt.close(fig)
