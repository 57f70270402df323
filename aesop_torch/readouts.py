"""The paper's readout: the expected reward is a weighted average of the rewards of the recalled episodes.

"A weighted averaging of the rewards expected due to these past experiences is used as an estimate of net anticipated
reward" (the paper, section 3). The weight of an episode is its recall strength (how well the cue matches it), raised
to a power (AgentConfig.recall_sharpness): a cue touches most stored episodes a little, and at power 1 their mass
would outweigh the few it matches well. A weighted average cannot leave the range of the rewards it averages: this
readout does not extrapolate, and every number it gives is one the robot has seen, or between two it has seen.
"""

from __future__ import annotations

import torch


def recall_average(rewards: torch.Tensor, strength: torch.Tensor, sharpness: float = 1.0) -> torch.Tensor:
    """(..., K) recalled rewards (NaN: no reward) and recall strengths (0: not recalled) -> (...) the average of the
    rewards weighted by strength ** sharpness; NaN where nothing with a reward was recalled."""
    ok = ~torch.isnan(rewards) & (strength > 0)
    s = torch.where(ok, strength.double(), torch.zeros((), dtype=torch.float64))
    # relative to the strongest recall before the power, so a high power of small strengths does not underflow
    w = (s / s.amax(-1, keepdim=True).clamp_min(1e-300)) ** sharpness * ok
    total = w.sum(-1)
    avg = (w * torch.nan_to_num(rewards.double())).sum(-1) / total.clamp_min(1e-300)
    return torch.where(total > 0, avg, torch.full_like(avg, float("nan"))).to(rewards.dtype)
