"""The paper's Figure 2 from a run: left, causal knowledge per property over episodes; right, prediction error
against Archimedes over episodes, one curve per order."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from aesop_torch.rules import PROPERTIES  # noqa: E402

MAX_CURVES = 12  # beyond this a population is drawn as its median and spread, not one line per order


def figure2(runs: list[list[dict]]):
    """runs: per order, the episode records of summary.json. Returns a matplotlib Figure."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.6), gridspec_kw={"width_ratios": [3, 2]})
    episodes = range(1, len(runs[0]) + 1)
    for p, style in zip(PROPERTIES, ("-o", "--s", ":^", "-.D")):
        # certainty of the first order, as the paper plots one exploration; state names at the last episode.
        # Distinct line styles: curves that reach 1 together stay visible on top of each other.
        left.plot(episodes, [r["knowledge"][p]["certainty"] for r in runs[0]], style, label=p, alpha=0.8)
    last = runs[0][-1]["knowledge"] if runs[0] else {}
    left.set_title("causal knowledge (order 1): " + ", ".join(f"{p} {last[p]['state']}" for p in last), fontsize=8)
    left.set_xlabel("episode (object explored)")
    left.set_ylabel("certainty (0 unknown, 1 dominant or irrelevant)")
    left.set_ylim(-0.05, 1.05)
    left.set_xticks(list(episodes), [r["object"] for r in runs[0]], rotation=30, ha="right", fontsize=7)
    left.legend(fontsize=8)
    for i, run in enumerate(runs[:MAX_CURVES]):
        xs = [t + 1 for t, r in enumerate(run) if r["probe_rel_error"] is not None]
        ys = [100 * r["probe_rel_error"] for r in run if r["probe_rel_error"] is not None]
        right.plot(xs, ys, marker=".", label=f"order {i + 1}")
    right.set_title("prediction error vs Archimedes (probe objects)", fontsize=9)
    right.set_xlabel("episode")
    right.set_ylabel("median |predicted - Archimedes| / Archimedes (%)")
    right.legend(fontsize=7)
    fig.tight_layout()
    return fig
