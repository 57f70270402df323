"""Self-organizing map (Kohonen), the paper's property-specific layer-1 maps.

The paper trains its maps "using standard SOM procedure" and gives no numbers, so the definitions here follow
MiniSom (JustGlowing/minisom 2.3), the reference implementation most people compare against:
- units are laid out row-major: unit u sits at grid (u // cols, u % cols);
- gaussian neighbourhood exp(-d_grid^2 / (2 sigma^2));
- online `train_online`: one sample per iteration, learning rate and radius both decay as x / (1 + t / (T / 2))
  (MiniSom's default `asymptotic_decay`, which ends at a third of the start value);
- quantization error: mean distance from a sample to its best matching unit (BMU);
- topographic error: fraction of samples whose best and second-best units are not grid neighbours (8-neighbours
  count as adjacent: grid distance > 1.42 is an error).

`train_batch` is Kohonen's batch SOM, which is what the project uses: each epoch assigns every sample to its BMU
and sets each codebook vector to the neighbourhood-weighted mean of the samples, with the radius shrinking
geometrically from `sigma` to `sigma_end`. It is a handful of matmuls per epoch, so it is orders of magnitude faster
than the online loop and, with a small final radius, reaches a lower quantization error.

On top of the standard SOM, `activity` gives the paper's graded response: every unit responds with a gaussian of its
codebook vector's distance to the input, so a novel input partially activates the units of similar known inputs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn


def _spread(coord: torch.Tensor, n: int) -> torch.Tensor:
    """Grid coordinates 0..n-1 -> evenly spaced in [-1, 1] (all 0 for n == 1)."""
    return coord / (n - 1) * 2.0 - 1.0 if n > 1 else torch.zeros_like(coord)


@dataclass
class SOMConfig:
    rows: int = 8
    cols: int = 8
    dim: int = 3
    # start neighbourhood radius in grid units; about a quarter of the map's side, so the first epochs order
    # the whole map before units specialise (MiniSom's default of 1.0 is too local to unfold an 8x8 map).
    sigma: float = 2.0
    # final radius of batch training; at 0.5 a neighbour gets weight exp(-2) = 0.14, enough to keep the map
    # ordered while each unit settles near the mean of its own samples (low quantization error).
    sigma_end: float = 0.5
    # start learning rate of online `train_online` (MiniSom's default); it decays to a third by the end.
    learning_rate: float = 0.5
    # width of the graded activity, in input units. Set per map to about the spacing between neighbouring
    # codebook vectors (see encoders.default_map_configs): the same input activates its own unit near 1, a value
    # a couple of units away barely at all.
    activity_sigma: float = 0.15
    # online iterations before batch training (Kohonen's ordering phase), used by `fit`; 0: PCA init + batch
    # only. Categorical data need it: the batch SOM cannot split two categories that once shared a unit (each
    # unit settles on the mean of its samples), the online SOM's sample-by-sample updates can.
    ordering_iterations: int = 0
    # samples per chunk when computing distances to all units, so memory stays bounded (chunk x units floats); a
    # chunk also holds at most 2^20 distances (see `rows_per_chunk`).
    chunk_size: int = 8192

    def __post_init__(self):
        if self.rows < 1 or self.cols < 1 or self.dim < 1:
            raise ValueError(f"SOMConfig: rows, cols and dim must be >= 1, got {self.rows}, {self.cols}, {self.dim}")
        if self.sigma <= 0 or self.sigma_end <= 0 or self.activity_sigma <= 0 or self.learning_rate <= 0:
            raise ValueError("SOMConfig: sigma, sigma_end, learning_rate and activity_sigma must be > 0")


class SelfOrganizingMap(nn.Module):
    """A rows x cols SOM over dim-dimensional inputs; codebook and grid live in buffers.

    Every query method accepts inputs with any leading shape (..., dim).
    """

    def __init__(self, config: SOMConfig):
        super().__init__()
        self.config = config
        n = config.rows * config.cols
        self.register_buffer("weights", torch.zeros(n, config.dim))
        u = torch.arange(n)
        self.register_buffer("locations", torch.stack([u // config.cols, u % config.cols], -1).float())

    @property
    def n_units(self) -> int:
        return self.weights.shape[0]

    # -- queries ------------------------------------------------------------------------------------------------
    def _input(self, x, name: str = "x") -> torch.Tensor:
        x = torch.as_tensor(x, dtype=self.weights.dtype, device=self.weights.device)
        if x.ndim == 0 or x.shape[-1] != self.config.dim:
            raise ValueError(f"{name} must have last dimension {self.config.dim}, got shape {tuple(x.shape)}")
        return x

    def _sq_distances(self, x: torch.Tensor) -> torch.Tensor:
        """(N, dim) -> (N, n_units) squared euclidean distances, as one matmul (clamped: rounding can go < 0)."""
        w = self.weights
        d = (x * x).sum(-1, keepdim=True) - 2.0 * x @ w.T + (w * w).sum(-1)
        return d.clamp_min_(0.0)

    def _bmu(self, x: torch.Tensor) -> torch.Tensor:
        """(N, dim) -> (N,) BMU indices. ||x||^2 is the same for every unit, so argmin of ||w||^2 - 2 x.w
        (one fused addmm) is enough: the fast path used by training."""
        w = self.weights
        return torch.addmm((w * w).sum(-1), x, w.T, alpha=-2.0).argmin(-1)

    @property
    def rows_per_chunk(self) -> int:
        """Samples whose distances to every unit are computed at once: config.chunk_size, and at most 2^20
        distances. A block of 5000 samples x 900 units (36 MB in float64) is allocated afresh, page by page, at every
        call, and made a batch epoch of a 30x30 map 4x slower than blocks of 1165 samples (same BMUs: each row's
        distances do not depend on the block)."""
        return max(1, min(self.config.chunk_size, (1 << 20) // self.n_units))

    def _chunks(self, x: torch.Tensor):
        step = self.rows_per_chunk
        for i in range(0, x.shape[0], step):
            yield x[i:i + step]

    def winner(self, x) -> torch.Tensor:
        """(..., dim) -> (...) long: index of the best matching unit (lowest index on ties)."""
        x = self._input(x)
        flat = x.reshape(-1, self.config.dim)
        out = [self._bmu(c) for c in self._chunks(flat)]
        return (torch.cat(out) if out else flat.new_zeros(0, dtype=torch.long)).reshape(x.shape[:-1])

    def activity(self, x) -> torch.Tensor:
        """(..., dim) -> (..., n_units): graded response exp(-||x - w_u||^2 / (2 activity_sigma^2)) in (0, 1]."""
        x = self._input(x)
        d2 = self._sq_distances(x.reshape(-1, self.config.dim))
        a = torch.exp(-d2 / (2.0 * self.config.activity_sigma ** 2))
        return a.reshape(*x.shape[:-1], self.n_units)

    def decode(self, activity: torch.Tensor, floor: float = 0.05) -> torch.Tensor:
        """(..., n_units) graded activity -> (..., dim): the input that gives this activity, read from the population.

        A single winner's codebook vector is only as fine as the map (one unit of a 1 x 30 log-mass map spans a
        factor 1.3). Every unit's response is a gaussian of its distance to the input (`activity`), so
        sigma^2 log a_u + |w_u|^2 / 2 = x . w_u - |x|^2 / 2 is linear in (x, |x|^2): the units active above
        `floor` x the peak, weighted by their activity, give x by least squares, exactly for an unscaled or
        uniformly scaled response (a retro-activated copy), closely for a truncated one. Where fewer than dim + 1
        units respond, the activity-weighted mean of their codebook vectors. All-zero activity gives NaN."""
        a = torch.as_tensor(activity, dtype=self.weights.dtype, device=self.weights.device)
        if a.shape[-1] != self.n_units:
            raise ValueError(f"activity must have last dimension {self.n_units}, got shape {tuple(a.shape)}")
        shape = a.shape[:-1]
        a = a.reshape(-1, self.n_units)
        peak = a.amax(-1, keepdim=True)
        on = (a >= floor * peak) & (peak > 0)
        w = torch.where(on, a, torch.zeros_like(a))
        mean = (w @ self.weights) / w.sum(-1, keepdim=True)                     # the fallback, NaN when silent
        W, D = self.weights.double(), self.config.dim
        lhs = torch.cat([W, torch.full_like(W[:, :1], -0.5)], -1)                 # (units, D + 1): [w_u, -1/2]
        rhs = self.config.activity_sigma ** 2 * torch.where(on, a, torch.ones_like(a)).double().log() \
            + 0.5 * (W * W).sum(-1)
        sw = (w / peak.clamp_min(1e-30)).double()                                 # (N, units) weights
        A = torch.einsum("nu,uf,ug->nfg", sw, lhs, lhs) + 1e-9 * torch.eye(D + 1, dtype=W.dtype)
        b = torch.einsum("nu,uf,nu->nf", sw, lhs, rhs)
        ok = on.sum(-1) > D
        x = torch.linalg.solve(A, b)[:, :D].to(a.dtype) if ok.any() else mean
        return torch.where(ok[:, None], x, mean).reshape(*shape, D)

    def quantization(self, x) -> torch.Tensor:
        """(..., dim) -> (..., dim): the codebook vector of each input's BMU."""
        return self.weights[self.winner(x)]

    def quantization_error(self, data) -> float:
        """MiniSom's QE: mean euclidean distance from each sample to its BMU's codebook vector."""
        data = self._input(data, "data").reshape(-1, self.config.dim)
        return float((data - self.quantization(data)).norm(dim=-1).mean())

    def topographic_error(self, data) -> float:
        """MiniSom's TE (rectangular grid): fraction of samples whose two best units are not 8-neighbours."""
        data = self._input(data, "data").reshape(-1, self.config.dim)
        if self.n_units < 2:
            return float("nan")  # MiniSom: undefined for a 1-unit map
        errors = 0
        for c in self._chunks(data):
            w = self.weights
            best2 = torch.addmm((w * w).sum(-1), c, w.T, alpha=-2.0).topk(2, dim=-1, largest=False).indices
            gap = (self.locations[best2[:, 0]] - self.locations[best2[:, 1]]).norm(dim=-1)
            errors += int((gap > 1.42).sum())
        return errors / data.shape[0]

    # -- initialisation -----------------------------------------------------------------------------------------
    @torch.no_grad()
    def init_weights(self, data, generator: torch.Generator | None = None) -> None:
        """With a generator: every unit copies a random sample (MiniSom's random_weights_init).

        Without: PCA init, deterministic. The grid spans mean +- sqrt(3) std along the first two principal
        components (rows along the first; a one-row or one-column map, or 1-d data, uses the first only).
        sqrt(3) std is exactly the half-range of a uniform distribution, so the grid starts spread over the data.
        (MiniSom spans +-1 along the unit eigenvectors, which assumes normalised data; scaling by the std does not.)
        """
        data = self._input(data, "data").reshape(-1, self.config.dim)
        if data.shape[0] == 0:
            raise ValueError("data must hold at least one sample")
        if generator is not None:
            idx = torch.randint(data.shape[0], (self.n_units,), generator=generator).to(data.device)
            self.weights.copy_(data[idx])
            return
        mean = data.mean(0)
        if data.shape[0] < 2:
            self.weights.copy_(mean.expand_as(self.weights))
            return
        evals, evecs = torch.linalg.eigh(torch.cov(data.T).reshape(self.config.dim, self.config.dim))
        order = evals.argsort(descending=True)
        axes = evecs[:, order] * evals[order].clamp_min(0).sqrt() * math.sqrt(3.0)  # columns: scaled PCs
        r, c = _spread(self.locations[:, 0], self.config.rows), _spread(self.locations[:, 1], self.config.cols)
        if self.config.rows == 1 or self.config.cols == 1 or self.config.dim == 1:
            # a line map runs along the first PC; a 2-d map of 1-d data along it diagonally
            self.weights.copy_(mean + (r + c)[:, None] * axes[:, 0])
        else:
            self.weights.copy_(mean + r[:, None] * axes[:, 0] + c[:, None] * axes[:, 1])

    # -- training -----------------------------------------------------------------------------------------------
    @torch.no_grad()
    def train_online(self, data, num_iteration: int, generator: torch.Generator) -> None:
        """Online SOM exactly as MiniSom's `train(..., random_order=True)` (named train_online so that
        nn.Module.train(mode) keeps working on any model holding a map): sample t is data[perm[t] mod N]
        (every sample equally often, order drawn from the generator), w += eta(t) h(t) (x - w), with eta and
        sigma decaying as x / (1 + 2 t / T)."""
        data = self._input(data, "data")
        if data.ndim != 2 or data.shape[0] == 0:
            raise ValueError(f"data must be (N, {self.config.dim}) with N >= 1, got shape {tuple(data.shape)}")
        if num_iteration < 1:
            raise ValueError(f"num_iteration must be >= 1, got {num_iteration}")
        order = (torch.arange(num_iteration) % data.shape[0])[torch.randperm(num_iteration, generator=generator)]
        grid_d2 = torch.cdist(self.locations, self.locations).pow(2)
        w, cfg = self.weights, self.config
        for t, i in enumerate(order.tolist()):
            decay = 1.0 + t / (num_iteration / 2.0)
            eta, sig = cfg.learning_rate / decay, cfg.sigma / decay
            x = data[i]
            bmu = int(((w - x) ** 2).sum(-1).argmin())
            h = torch.exp(-grid_d2[bmu] / (2.0 * sig * sig)) * eta
            w += h[:, None] * (x - w)

    @torch.no_grad()
    def fit(self, data, epochs: int, generator: torch.Generator | None = None) -> None:
        """The project's recipe. Without an ordering phase: PCA init, then `epochs` of batch training.
        With one: random init from the data, `ordering_iterations` online steps, then batch training whose
        radius starts where the online phase ended (sigma / 3) and shrinks to sigma_end."""
        cfg = self.config
        if cfg.ordering_iterations <= 0:
            self.init_weights(data)
            self.train_batch(data, epochs)
            return
        if generator is None:
            raise ValueError("fit needs a generator when ordering_iterations > 0")
        self.init_weights(data, generator)
        self.train_online(data, cfg.ordering_iterations, generator)
        self.train_batch(data, epochs, sigma=cfg.sigma / 3.0)

    @torch.no_grad()
    def train_batch(self, data, epochs: int, sigma: float | None = None) -> None:
        """Batch SOM: per epoch, w_u = sum_i h(u, bmu_i) x_i / sum_i h(u, bmu_i), the radius shrinking
        geometrically from `sigma` (default: the config's) to sigma_end. Per-unit sums are accumulated chunk by
        chunk (index_add), so memory is O(chunk x units); the neighbourhood is then applied along rows and columns.
        Units whose neighbourhood weight underflows keep their vector."""
        data = self._input(data, "data")
        if data.ndim != 2 or data.shape[0] == 0:
            raise ValueError(f"data must be (N, {self.config.dim}) with N >= 1, got shape {tuple(data.shape)}")
        if epochs < 1:
            raise ValueError(f"epochs must be >= 1, got {epochs}")
        cfg, n = self.config, self.n_units
        R, C, D = cfg.rows, cfg.cols, cfg.dim
        start = cfg.sigma if sigma is None else sigma
        dr2 = (torch.arange(R)[:, None] - torch.arange(R)).pow(2).to(self.weights)   # (R, R) squared row gaps
        dc2 = (torch.arange(C)[:, None] - torch.arange(C)).pow(2).to(self.weights)   # (C, C) squared col gaps
        for e in range(epochs):
            frac = e / (epochs - 1) if epochs > 1 else 1.0
            radius = start * (cfg.sigma_end / start) ** frac
            sums = torch.zeros(n, D + 1, dtype=self.weights.dtype, device=self.weights.device)  # [sum x, count]
            for c in self._chunks(data):
                sums.index_add_(0, self._bmu(c), torch.cat([c, torch.ones_like(c[:, :1])], -1))
            # the gaussian of grid distance factorises into rows x cols, so the (units x units) neighbourhood
            # product is two small matmuls: sum_v h(u, v) s_v = H_rows S H_cols
            hr, hc = torch.exp(dr2 / (-2.0 * radius ** 2)), torch.exp(dc2 / (-2.0 * radius ** 2))
            smooth = (hr @ sums.view(R, C * (D + 1))).view(R, C, D + 1)
            smooth = torch.einsum("cj,rjd->rcd", hc, smooth).reshape(n, D + 1)
            num, den = smooth[:, :D], smooth[:, D]
            ok = den > 1e-12
            self.weights[ok] = num[ok] / den[ok, None]
