"""The expected fate read from a boundary: a small logistic fit over the recalled episodes' perceived properties.

Whether an object floats is a boundary in what the robot perceives: most changes of one property leave the fate as
it was, and a few cross it. A vote of the recalled fates (readouts.recall_average over them, the `boundary`
ablation) gives the fate of the episodes most like the present object, whichever side of the boundary the present
object lies on: a 158 g cube recalled beside a 150 g floating cube is expected to float. Here the recalled episodes'
fates (sank 1, floated 0) are fitted by a logistic regression on the live properties' perceived values (each map's
decoded value, as local_readout reads them: colour in RGB, fill, the extent ratios, size and weight on their maps'
log scales), centred on the present object, so the fit's intercept is the log-odds that the present object sinks.
The form is generic: a linear boundary over what the robot perceives, no density and no law; how much each property
matters is the fit's slope, learned from the recalled fates. Batched over agents, deterministic (a fixed number of
Newton steps from zero), torch only.
"""

from __future__ import annotations

import torch


def logistic_at(d: torch.Tensor, fates: torch.Tensor, weight: torch.Tensor, cols: torch.Tensor, ridge: float,
                steps: int = 12) -> torch.Tensor:
    """(B,) P(sinks) at the origin of d: logistic regression of the fates (B, K) long (1 sank, 0 floated, -1 not
    seen) on the features d (B, K, F), relative to the present object, over the columns `cols` (B, F) bool (the rest
    multiplied out), each episode counted with its weight (B, K) >= 0 (0: left out). Newton steps from zero with a
    ridge of `ridge` on the slopes (the recalled fates are often separable: it keeps the boundary finite) and 1e-6
    on the intercept. Where nothing is weighted the fit stays at zero: 0.5."""
    B, K, F = d.shape
    A = torch.cat([torch.ones(B, K, 1, dtype=d.dtype), d * cols[:, None]], -1)  # (B, K, 1 + F)
    w = weight * (fates >= 0)
    y = (fates == 1).to(d.dtype)
    reg = torch.eye(1 + F, dtype=d.dtype) * ridge
    reg[0, 0] = 1e-6
    beta = torch.zeros(B, 1 + F, dtype=d.dtype)
    for _ in range(steps):
        prob = torch.sigmoid(torch.einsum("bkf,bf->bk", A, beta))
        grad = torch.einsum("bkf,bk->bf", A, w * (y - prob)) - beta @ reg
        hess = torch.einsum("bkf,bk,bkg->bfg", A, w * prob * (1 - prob), A) + reg
        beta = beta + torch.linalg.solve(hess, grad[..., None])[..., 0]
    return torch.sigmoid(beta[:, 0])


def expected_fate(x: torch.Tensor, xk: torch.Tensor, fates: torch.Tensor, weight: torch.Tensor,
                  columns: torch.Tensor, ridge: float, steps: int = 12) -> torch.Tensor:
    """(B,) how likely the present object sinks, from the boundary fitted over the recalled episodes.

    x (B, D) the present object's perceived values; xk (B, K, D) each recalled episode's (NaN where not valid);
    fates (B, K) long (1 sank, 0 floated, -1 not seen or not valid); weight (B, K) >= 0 each episode's weight in the
    fit; columns (B, D) bool, the values of the live properties (local_readout.property_columns's layout). 0.5 where
    no recalled episode has a seen fate (nothing to tell)."""
    ok = (weight > 0) & (fates >= 0) & ~torch.isnan(xk).any(-1)
    d = torch.nan_to_num((xk - x[:, None]).double())
    w = torch.where(ok, weight.double(), torch.zeros((), dtype=torch.float64))
    p = logistic_at(d, torch.where(ok, fates, torch.full_like(fates, -1)), w, columns, ridge, steps)
    return torch.where(ok.any(-1), p, torch.full_like(p, 0.5)).float()
