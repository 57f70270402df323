"""Quantiles of values that stand for many orders each (a population's distinct errors with their counts).

Defined as numpy's default (linear) quantile of the list with every value repeated `count` times, without building
that list: 9! orders share a few thousand distinct errors.
"""

from __future__ import annotations

import numpy as np


def weighted_quantiles(values, counts, qs) -> np.ndarray:
    """np.quantile(np.repeat(values, counts), qs), counts whole numbers >= 0. NaN for each q when no count is
    positive. ValueError in one line for mismatched lengths, a negative or fractional count, a q outside 0..1."""
    v = np.asarray(values, dtype=float).ravel()
    c = np.asarray(counts, dtype=float).ravel()
    q = np.atleast_1d(np.asarray(qs, dtype=float))
    if v.shape != c.shape:
        raise ValueError(f"weighted_quantiles: {v.size} values but {c.size} counts")
    if (c < 0).any() or (c != np.round(c)).any():
        raise ValueError("weighted_quantiles: counts must be whole numbers >= 0")
    if ((q < 0) | (q > 1) | np.isnan(q)).any():
        raise ValueError("weighted_quantiles: quantiles must lie in 0..1")
    total = int(c.sum())
    if total == 0:
        return np.full(q.shape, np.nan)
    order = np.argsort(v, kind="stable")
    v, cum = v[order], np.cumsum(c[order])
    h = (total - 1) * q                        # the position in the repeated, sorted list (numpy's 'linear')
    lo, hi = np.floor(h).astype(int), np.ceil(h).astype(int)
    at = lambda k: v[np.searchsorted(cum, k, side="right")]   # noqa: E731   the k-th (0-based) repeated value
    return at(lo) + (h - lo) * (at(hi) - at(lo))
