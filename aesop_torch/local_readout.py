"""A local readout: the expected reward read from the recalled episodes by a weighted fit over the properties the
rules found dominant.

The paper averages the rewards of the recalled episodes (readouts.recall_average), so it can never predict more
than the most it has seen, nor tell where between two seen rewards a new object lies. Here, among the episodes
recalled in the expected fate, the log reward is fitted as a linear function of the dominant properties' perceived
values (each map's decoded value, as the robot perceives it: colour in RGB, fill, the extent ratios, size and weight
on their maps' log scales), weighted by recall strength, centred on the present object, and read at it. The form is
generic (no volume, no density, no law): what the fit follows is what the rules made dominant, and how much each
matters is the fit's slope, learned from the rewards. With nothing dominant it is the paper's weighted average.
The log reward, because rewards span orders of magnitude and the maps perceive size and weight on log scales.
"""

from __future__ import annotations

import torch

from .readouts import recall_average


def property_columns(values: dict, properties: tuple) -> tuple[torch.Tensor, list[slice]]:
    """{property: (..., dim)} decoded values -> (..., D) their concatenation in `properties` order, and each
    property's slice of it."""
    cols, out, at = [], [], 0
    for p in properties:
        v = values[p]
        cols.append(slice(at, at + v.shape[-1]))
        out.append(v)
        at += v.shape[-1]
    return torch.cat(out, -1), cols


def local_fit(x: torch.Tensor, xk: torch.Tensor, rewards: torch.Tensor, weight: torch.Tensor,
              columns: torch.Tensor, ridge: float) -> torch.Tensor:
    """The weighted fit of log reward on the features in `columns`, read at x.

    x (B, D) the present object's features; xk (B, K, D) each recalled episode's; rewards (B, K) (NaN: none);
    weight (B, K) >= 0 (0: not used); columns (B, D) bool, the features fitted. The fit is y_k = a + b . (xk - x)
    by weighted least squares, with a ridge on b of `ridge` x the total weight (a fit on episodes that share a
    value is flat along it instead of singular), and the prediction exp(a). NaN where no weight."""
    ok = (weight > 0) & ~torch.isnan(rewards) & (rewards > 0)
    w = torch.where(ok, weight, torch.zeros_like(weight)).double()
    y = torch.where(ok, rewards, torch.ones_like(rewards)).double().log()
    d = torch.nan_to_num((xk - x[:, None]).double()) * columns[:, None].double()   # (B, K, D), unused columns 0
    A = torch.cat([torch.ones_like(d[..., :1]), d], -1)                      # (B, K, 1 + D)
    total = w.sum(-1)
    reg = torch.diag_embed(torch.cat([torch.zeros_like(total[:, None]),
                                      (ridge * total[:, None]).expand(-1, d.shape[-1])], -1))
    # a column not fitted: its slope pinned to 0 by a unit ridge (its feature is 0 everywhere)
    reg = reg + torch.diag_embed(torch.cat([torch.zeros_like(total[:, None]), (~columns).double()], -1))
    reg[:, 0, 0] += 1e-12 * total.clamp_min(1e-300)
    lhs = torch.einsum("bk,bki,bkj->bij", w, A, A) + reg
    rhs = torch.einsum("bk,bki,bk->bi", w, A, y)
    coef = torch.linalg.solve(lhs + torch.eye(lhs.shape[-1], dtype=lhs.dtype) * (total == 0)[:, None, None],
                              rhs[..., None])[..., 0]
    out = coef[:, 0].exp().to(rewards.dtype)
    return torch.where(total > 0, out, torch.full_like(out, float("nan")))


def local_readout(values: dict, recalled: dict, rewards: torch.Tensor, strength: torch.Tensor, in_fate: torch.Tensor,
                  dominant: torch.Tensor, properties: tuple, config) -> torch.Tensor:
    """(B,) the expected reward: the local fit over the dominant properties among the episodes recalled in the
    expected fate (in_fate (B, K) bool), or, with nothing dominant, their recall-strength-weighted average; where no
    recalled episode is of the expected fate, the average of all recalled. dominant (B, P) bool per property of
    `properties`; strength (B, K) recall strengths (0 where not valid); config: the AgentConfig (fit_sharpness,
    recall_sharpness, readout_ridge)."""
    use = torch.where(in_fate.any(-1, keepdim=True), in_fate, strength > 0)
    s = torch.where(use, strength, torch.zeros_like(strength))
    average = recall_average(rewards, s, config.recall_sharpness)
    x, cols = property_columns(values, properties)
    xk, _ = property_columns(recalled, properties)
    columns = torch.zeros_like(x, dtype=torch.bool)
    for i, c in enumerate(cols):
        columns[:, c] = dominant[:, i, None]
    w = (s / s.amax(-1, keepdim=True).clamp_min(1e-30)) ** config.fit_sharpness
    fit = local_fit(x, xk, rewards, w, columns, config.readout_ridge)
    return torch.where(columns.any(-1) & ~torch.isnan(fit), fit, average)
