"""Our SOM beside MiniSom: same data, same map size, same number of sample presentations.

MiniSom trains online (one sample per step, `train(..., random_order=True)`); ours uses the batch SOM (every epoch
presents every sample once), so both see samples x epochs presentations. Prints times, quantization and topographic
errors, and the speed ratio; last line `som_speedup_vs_minisom=X` for the 30x30 map.
Needs `pip install minisom` (a benchmark-only dependency; `make bench` installs it).
Run: python benches/som_vs_minisom.py [threads]
"""

import sys
import time

import numpy as np
import torch

from aesop_torch.som import SelfOrganizingMap, SOMConfig
from record import recorded   # benches/record.py: keeps BENCHMARKS.md current

try:
    from minisom import MiniSom
except ImportError:
    sys.exit("benches/som_vs_minisom.py needs MiniSom: pip install minisom")

THREADS = int(sys.argv[1]) if len(sys.argv) > 1 else 1
torch.set_num_threads(THREADS)  # both run single-threaded by default: MiniSom's numpy work here is one core too
SAMPLES, EPOCHS, REPEATS = 5000, 10, 3


def best_of(fn):
    times = []
    for _ in range(REPEATS):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def run(side: int):
    data = torch.rand(SAMPLES, 3, generator=torch.Generator().manual_seed(0))
    cfg = SOMConfig(rows=side, cols=side, dim=3, sigma=side / 4, sigma_end=0.5)

    def ours():
        som = SelfOrganizingMap(cfg)
        som.init_weights(data)
        som.train_batch(data, EPOCHS)
        return som

    def peer():
        ms = MiniSom(side, side, 3, sigma=side / 4, learning_rate=0.5, random_seed=0)
        d = data.numpy().astype(np.float64)
        ms.random_weights_init(d)
        ms.train(d, SAMPLES * EPOCHS, random_order=True)
        return ms

    t_ours, som = best_of(ours)
    t_peer, ms = best_of(peer)
    d = data.numpy().astype(np.float64)
    qe_o, te_o = som.quantization_error(data), som.topographic_error(data)
    qe_p, te_p = ms.quantization_error(d), ms.topographic_error(d)
    print(f"{side}x{side}, {SAMPLES} samples x {EPOCHS} = {SAMPLES * EPOCHS} presentations, {THREADS} thread(s):")
    print(f"  ours (batch SOM)  {t_ours:7.3f} s   QE {qe_o:.4f}   TE {te_o:.3f}")
    print(f"  MiniSom (online)  {t_peer:7.3f} s   QE {qe_p:.4f}   TE {te_p:.3f}")
    print(f"  speed ratio {t_peer / t_ours:.1f}x   QE ratio ours/MiniSom {qe_o / qe_p:.3f}")
    return t_peer / t_ours


if __name__ == "__main__":
    with recorded("som_vs_minisom"):
        run(10)
        print(f"som_speedup_vs_minisom={run(30):.1f}")
