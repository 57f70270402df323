"""Our SOM beside a peer running the same algorithm, like for like, timed side by side in one process.

1. Online vs online: ours `train_online` against MiniSom's `train(data, T, random_order=True)`: one sample per
   update, gaussian neighbourhood, learning rate and radius both decaying as x / (1 + 2t / T) (MiniSom's default
   `asymptotic_decay`: the radius ends at sigma / 3), the same sigma and learning rate, T = 50,000 updates, both
   from the same random codebook (MiniSom's `random_weights_init`, copied into ours). Each draws its own sample
   order (the same multiset of samples).
2. Batch vs batch: ours `train_batch` against a batch SOM in numpy written below (MiniSom has no batch trainer):
   the same algorithm (each epoch every sample goes to its best matching unit and each unit moves to the
   neighbourhood-weighted mean of the samples), the same gaussian, the radius shrinking geometrically from sigma
   to the same end radius, sigma / 3 (online's end), 10 epochs, both from our PCA initial codebook.
Same data (5,000 uniform points in the unit cube per seed), float64 and one thread for both. Times are medians
over SEEDS seeds x REPEATS repeats (ours and the peer alternately); QE and TE (MiniSom's definitions, computed by
MiniSom for every codebook) are medians over the seeds. Speed is compared where QE and TE agree; the last rows put
the batch and online results side by side. Last line: `online_speedup=X batch_speedup=Y` for the 30x30 map.
Needs `pip install minisom` (a benchmark-only dependency; `make bench` installs it).
Run: python benches/som_vs_minisom.py [--record]   (--record writes the output into BENCHMARKS.md)
"""

import argparse
import datetime
import os
import statistics
import sys
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):   # numpy's BLAS on one thread too,
    os.environ.setdefault(_var, "1")                                          # as torch (set before numpy loads)
import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from aesop_torch.malloc import keep_freed_memory  # noqa: E402

from aesop_torch.som import SelfOrganizingMap, SOMConfig  # noqa: E402
from cli_args import record_flag  # noqa: E402
from record import run_main  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current (--record)
from train.learning.sim_pool import cores  # noqa: E402

MiniSom = None   # the peer's class, imported by main() once the arguments are read (--help needs no MiniSom)
SAMPLES, UPDATES, EPOCHS = 5000, 50_000, 10
SEEDS, REPEATS = (0, 1, 2), 3
LEARNING_RATE = 0.5        # MiniSom's default


def numpy_batch_som(data, w0, rows, cols, sigma, sigma_end, epochs, step):
    """Batch SOM in numpy, the algorithm of `SelfOrganizingMap.train_batch`: BMUs by squared distance in blocks of
    `step` samples (ours: `SelfOrganizingMap.rows_per_chunk`), per-unit sums by bincount, the gaussian neighbourhood
    applied along rows and then columns (it factorises)."""
    n, d = rows * cols, data.shape[1]
    w = w0.copy()
    dr2 = (np.arange(rows)[:, None] - np.arange(rows)) ** 2.0
    dc2 = (np.arange(cols)[:, None] - np.arange(cols)) ** 2.0
    x2 = (data * data).sum(1)
    for e in range(epochs):
        radius = sigma * (sigma_end / sigma) ** (e / (epochs - 1) if epochs > 1 else 1.0)
        w2 = (w * w).sum(1)
        bmu = np.concatenate([(x2[i:i + step, None] - 2.0 * data[i:i + step] @ w.T + w2).argmin(1)
                              for i in range(0, len(data), step)])
        sums = np.stack([np.bincount(bmu, data[:, k], n) for k in range(d)] + [np.bincount(bmu, None, n)], 1)
        hr, hc = np.exp(dr2 / (-2.0 * radius ** 2)), np.exp(dc2 / (-2.0 * radius ** 2))
        smooth = (hr @ sums.reshape(rows, cols * (d + 1))).reshape(rows, cols, d + 1)
        smooth = np.einsum("cj,rjd->rcd", hc, smooth).reshape(n, d + 1)
        ok = smooth[:, d] > 1e-12
        w[ok] = smooth[ok, :d] / smooth[ok, d:]
    return w


def errors(codebook, rows, cols, data):
    """(QE, TE) of a codebook (units row-major) by MiniSom's own functions."""
    ms = MiniSom(rows, cols, data.shape[1])
    ms._weights = np.asarray(codebook, dtype=np.float64).reshape(rows, cols, -1).copy()
    return ms.quantization_error(data), ms.topographic_error(data)


def side_by_side(ours, peer):
    """Median times of ours() and peer(), run alternately; their last results."""
    t_o, t_p = [], []
    for _ in range(REPEATS):
        t = time.perf_counter()
        a = ours()
        t_o.append(time.perf_counter() - t)
        t = time.perf_counter()
        b = peer()
        t_p.append(time.perf_counter() - t)
    return t_o, t_p, a, b


def run(side: int) -> tuple[float, float]:
    sigma = side / 4
    cfg = SOMConfig(rows=side, cols=side, dim=3, sigma=sigma, sigma_end=sigma / 3, learning_rate=LEARNING_RATE)
    rows = {k: [] for k in ("on_t", "ms_t", "b_t", "nb_t", "on", "ms", "b", "nb")}
    for seed in SEEDS:
        data = torch.rand(SAMPLES, 3, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
        d = data.numpy()
        start = MiniSom(side, side, 3, sigma=sigma, learning_rate=LEARNING_RATE, random_seed=seed)
        start.random_weights_init(d)
        w_random = start._weights.reshape(-1, 3).copy()

        def ours_online():
            som = SelfOrganizingMap(cfg).double()
            som.weights.copy_(torch.from_numpy(w_random))
            som.train_online(data, UPDATES, torch.Generator().manual_seed(seed))
            return som.weights.numpy()

        def minisom_online():
            ms = MiniSom(side, side, 3, sigma=sigma, learning_rate=LEARNING_RATE, random_seed=seed)
            ms._weights = w_random.reshape(side, side, 3).copy()
            ms.train(d, UPDATES, random_order=True)
            return ms._weights.reshape(-1, 3)

        pca = SelfOrganizingMap(cfg).double()
        pca.init_weights(data)
        w_pca = pca.weights.numpy().copy()

        def ours_batch():
            som = SelfOrganizingMap(cfg).double()
            som.weights.copy_(torch.from_numpy(w_pca))
            som.train_batch(data, EPOCHS)
            return som.weights.numpy()

        def numpy_batch():
            return numpy_batch_som(d, w_pca, side, side, sigma, sigma / 3, EPOCHS, pca.rows_per_chunk)

        t_o, t_p, a, b = side_by_side(ours_online, minisom_online)
        rows["on_t"] += t_o
        rows["ms_t"] += t_p
        rows["on"].append(errors(a, side, side, d))
        rows["ms"].append(errors(b, side, side, d))
        t_o, t_p, a, b = side_by_side(ours_batch, numpy_batch)
        rows["b_t"] += t_o
        rows["nb_t"] += t_p
        rows["b"].append(errors(a, side, side, d))
        rows["nb"].append(errors(b, side, side, d))
    med = statistics.median

    def line(name, t, errs):
        qe, te = med(e[0] for e in errs), med(e[1] for e in errs)
        print(f"  {name:34s} {med(t):8.3f} s   QE {qe:.4f}   TE {te:.3f}")
        return med(t)

    print(f"{side}x{side} map, sigma {sigma:g} -> {sigma / 3:.3g}, {SAMPLES} samples, seeds {SEEDS}, "
          f"{REPEATS} repeats each; median time, median QE / TE:")
    a, b = line(f"ours train_online ({UPDATES} updates)", rows["on_t"], rows["on"]), \
        line("MiniSom train (same updates)", rows["ms_t"], rows["ms"])
    c, e = line(f"ours train_batch ({EPOCHS} epochs)", rows["b_t"], rows["b"]), \
        line("numpy batch SOM (same epochs)", rows["nb_t"], rows["nb"])
    print(f"  online: ours {b / a:.2f}x MiniSom's speed; batch: ours {e / c:.2f}x numpy's; "
          f"batch vs online (different algorithms): {b / c:.0f}x MiniSom's speed at QE "
          f"{med(x[0] for x in rows['b']) / med(x[0] for x in rows['ms']):.2f}x and TE "
          f"{med(x[1] for x in rows['b']) / max(med(x[1] for x in rows['ms']), 1e-9):.1f}x MiniSom's")
    return b / a, e / c


def main() -> None:
    global MiniSom
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    record_flag(ap)
    ap.parse_args()
    try:
        from minisom import MiniSom
    except ImportError:
        sys.exit("benches/som_vs_minisom.py needs MiniSom: pip install minisom")
    keep_freed_memory()   # for the peer in this process too (aesop_torch/malloc.py)
    torch.set_num_threads(1)   # MiniSom's numpy work on these small arrays runs on one core too
    print(f"{datetime.date.today()}, {cores()} cores, torch {torch.__version__}, 1 thread, float64")
    run(10)
    online, batch = run(30)
    print(f"online_speedup={online:.2f} batch_speedup={batch:.2f}")


if __name__ == "__main__":
    run_main("som_vs_minisom", main)
