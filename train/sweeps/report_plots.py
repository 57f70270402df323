"""The report's plots: the median error against experience with its interval, and order agreement and colour's
fate per condition (docs/sweeps.md "The report")."""

from __future__ import annotations

from pathlib import Path


def plot_errors(s: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, MaxNLocator, NullFormatter
    groups = [g for g in s["groups"] if any(s["errors"].get((c, g)) for c in s["conditions"])] or s["groups"]
    fig, axes = plt.subplots(1, len(groups), figsize=(5.2 * len(groups), 4.2), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, g in zip(axes[0], groups):
        drawn = False
        for i, c in enumerate(s["conditions"]):
            errs = s["errors"].get((c, g))
            if not errs:
                continue
            ep = list(errs)
            med = [100 * errs[e][1] for e in ep]
            col = colours[i % len(colours)]
            ax.plot(ep, med, "-o", color=col, markersize=3, label=c)
            cis = s["ci"].get((c, g), {})
            band = [e for e in ep if cis.get(e)]
            if band:
                ax.fill_between(band, [100 * cis[e][0] for e in band], [100 * cis[e][1] for e in band], color=col,
                                alpha=0.18, linewidth=0)
            drawn = True
        ax.set_title(g, fontsize=10)
        ax.set_xlabel("episodes (objects explored)")
        ax.set_ylabel("novel-object error, % (median, 95 % interval)")
        if drawn:
            ax.set_yscale("log")
            ax.legend(fontsize=8)
            plain = FuncFormatter(lambda v, _: f"{v:g}")
            lo, hi = ax.get_ylim()
            ax.yaxis.set_major_formatter(plain)      # 30, not 3 x 10^1
            two_five = FuncFormatter(lambda v, _: f"{v:g}" if f"{v:e}"[0] in "25" else "")
            ax.yaxis.set_minor_formatter(two_five if hi / lo < 1000 else NullFormatter())   # 2, 5, 20, 50, ...
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        else:
            ax.text(0.5, 0.5, "no probe errors", ha="center", va="center", transform=ax.transAxes)
        ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_agreement(s: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    conds, groups = s["conditions"], s["groups"]
    fig, axes = plt.subplots(1, 2, figsize=(max(8.0, 1.1 * len(conds) * 2 + 2), 4.2))
    width = 0.8 / max(1, len(groups))
    x = np.arange(len(conds))
    for ax, key, title in ((axes[0], "order_agreement", "same knowledge in every order (% of cells)"),
                           (axes[1], "colour_irrelevant", "colour ends irrelevant (% of runs)")):
        for j, g in enumerate(groups):
            ks = [s["knowledge"].get((c, g)) or {} for c in conds]
            vals = [k.get(key) for k in ks]
            bars = ax.bar(x + (j - (len(groups) - 1) / 2) * width, [np.nan if v is None else 100 * v for v in vals],
                          width, label=g)
            labels = ["n/a" if v is None else f"{100 * v:.0f} %" + (
                "\n(nothing\nlearned)" if key == "order_agreement" and k.get("nothing_learned") else "")
                for v, k in zip(vals, ks)]
            ax.bar_label(bars, labels=labels, fontsize=7)
        ax.set_xticks(x, conds, rotation=30, ha="right", fontsize=8)
        ax.set_ylim(0, 125)
        ax.set_ylabel("%")
        ax.set_title(title, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
        if len(groups) > 1:
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


