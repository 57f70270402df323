"""The episodic memory's recall as it was before it was made fast (commit 59ec298): dense products, the row-wise
k-winners by a sort, every cue's constants recomputed at every step. A peer for benches/memory_capacity.py, run
side by side in the same process: same stored episodes, same cues, its speed and its recalls beside ours.

`DenseEpisodicMemory` is an `EpisodicMemory` whose recall runs the old code; storing, the buffers and the checks are
the library's. Kept verbatim (apart from names, and the signatures `EpisodicMemory.recall` now calls, whose extra
arguments it ignores: the old code spans the whole sheet), so what it returns is what the library returned then.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from aesop_torch.memory import _EPS, EpisodicMemory


def dense_k_winners(a: torch.Tensor, row_k: torch.Tensor, threshold: float) -> torch.Tensor:
    kth = a.topk(int(row_k.max()), dim=-1).values.gather(-1, (row_k - 1).expand(*a.shape[:-2], -1)[..., None])
    above, tied = a > kth, a == kth
    room = row_k[:, None] - above.sum(-1, keepdim=True)
    return (above | (tied & (tied.cumsum(-1) <= room))) & (a > threshold)


class _DenseNet(NamedTuple):
    x: torch.Tensor
    total: torch.Tensor
    n: torch.Tensor
    z: torch.Tensor

    def take(self, i: torch.Tensor) -> "_DenseNet":
        return _DenseNet(self.x if self.x.shape[0] == 1 else self.x[i], self.total[i], self.n[i], self.z[i])

    def mean(self) -> torch.Tensor:
        return self.total / self.n.clamp(min=1)

    def predict(self, d: torch.Tensor, zscore: bool = True) -> torch.Tensor:
        p = self.mean()
        if not zscore:
            return p + self.covariance_product(d) / ((d * d).sum(1, keepdim=True) - d * d).clamp(min=_EPS)
        sigma = (p * (1 - p)).sqrt()
        inv = torch.where(sigma > 1e-6, 1.0 / sigma.clamp_min(1e-6), torch.zeros_like(sigma))
        dz = d * inv
        h = self.covariance_product(dz * inv)
        return p + h * (sigma * inv) / ((dz * dz).sum(1, keepdim=True) - dz * dz).clamp(min=_EPS)

    def covariance_product(self, d: torch.Tensor) -> torch.Tensor:
        x, S, n, z = self
        p = S / n.clamp(min=1)
        if x.shape[0] == 1 and d.shape[0] != 1:
            h = (d @ x[0].T) @ x[0]
        else:
            h = torch.bmm(torch.bmm(x, d[:, :, None]).transpose(1, 2), x)[:, 0]
        if z.shape[1]:
            h = h - ((z * d[:, None]).sum(-1, keepdim=True) * z).sum(1)
        return h - S * ((p * d).sum(1, keepdim=True) + (1 - p) * d)


class DenseEpisodicMemory(EpisodicMemory):
    """EpisodicMemory with the recall of commit 59ec298."""

    def _net(self, mem: slice, batch: int, compact: bool = False) -> tuple[_DenseNet, None]:
        x = self.patterns[mem, :int(self.count[mem].max())].flatten(2).float()
        total = x.sum(1).expand(batch, -1).contiguous()
        n = self.count[mem].to(x.dtype)[:, None].expand(batch, 1).contiguous()
        return _DenseNet(x, total, n, x.new_zeros(batch, 0, x.shape[2])), None

    @torch.no_grad()
    def predict(self, state: torch.Tensor) -> torch.Tensor:
        net, _ = self._net(slice(None), self.batch)
        s = state.flatten(1).to(net.x)
        return net.predict(s - net.mean(), self.config.zscore).view(state.shape)

    def _recall(self, cue, net, code, episodes, strength, valid):
        c = self.config
        B, K = cue.shape[0], episodes.shape[1]
        z = net.x.new_zeros(B, K, net.x.shape[2])
        total, n = net.total.clone(), net.n.clone()
        idx = torch.arange(B, device=cue.device)[n[:, 0] > 0]
        drive = cue.clone()
        for r in range(K):
            if idx.numel() == 0:
                break
            sub = _DenseNet(net.x, total, n, z[:, :r]).take(idx)
            state, fixed = self._settle(cue[idx] if c.cue_power == 1 else drive[idx], sub)
            obj = state[:, list(c.cue_rows)].flatten(1).float()
            s = (cue[idx] * obj).sum(1) / obj.sum(1).clamp(min=1.0)
            ok = fixed & (s >= c.min_strength)
            good = idx[ok]
            episodes[good, r], strength[good, r], valid[good, r] = state[ok], s[ok], True
            z[good, r] = state[ok].flatten(1).float()
            total[good] -= z[good, r]
            n[good] -= 1
            drive[good] *= 1 - obj[ok]
            idx = good[n[good, 0] > 0]

    def _settle(self, cue: torch.Tensor, net: _DenseNet) -> tuple[torch.Tensor, torch.Tensor]:
        c = self.config
        B, R, C = cue.shape[0], c.rows, c.cols
        p = net.mean().view(B, R, C)
        s = p.clone()
        rows = list(c.cue_rows)
        if c.cue_power != 1:
            peak = cue.amax(1, keepdim=True)
            cue = torch.where(peak > 0, cue / peak.clamp_min(1e-12), cue) ** c.cue_power
        s[:, rows] = cue.view(B, len(rows), C)
        for clamp, steps in ((True, c.cue_steps), (False, c.free_steps)):
            idx, sub = torch.arange(B, device=cue.device), net
            for _ in range(steps):
                cur = s[idx]
                new = dense_k_winners(sub.predict((cur - p[idx]).flatten(1), c.zscore).view_as(cur), self.row_k,
                                      c.threshold).to(cur.dtype)
                if clamp:
                    new[:, rows] = cue[idx].view(-1, len(rows), C)
                moving = (new != cur).flatten(1).any(1)
                s[idx] = new
                idx, sub = idx[moving], sub.take(moving) if not moving.all() else sub
                if idx.numel() == 0:
                    break
        fixed = torch.ones(B, dtype=torch.bool, device=cue.device)
        fixed[idx] = False
        return s.bool(), fixed


if __name__ == "__main__":
    import argparse
    argparse.ArgumentParser(description="The episodic memory's recall before it was made fast, a peer that "
                                        "benches/memory_capacity.py imports: nothing to run.").parse_args()
