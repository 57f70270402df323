"""The paper's claims on object sets the project has never seen: order independence and Archimedes for novel objects.

    python benches/generalization.py [--sets 100] [--long-sets 30] [--orders 24] [--first-seed 0]
                                     [--model extended|paper] [--out PNG] [--record]

Generated sets (`sim.make_objects`, seeds first-seed.., with `--pairs`: a colour pair, a weight pair, and random
objects of every shape, sinkers and floaters, in random jars): 8 train and 8 probe objects each, and longer sets of
24 train objects for the curve's tail. Outcomes and measurements carry the simulated robot's noise
(`sim.sensor_model.SensorModel`, tied to the simulator by tests/test_sensor_model.py). Each set is learned in
`--orders` random orders by as many agents side by side. Printed:

- the fraction of sets whose final knowledge is the same in every order;
- the fraction of (set, order) whose final knowledge equals the batch answer (`aesop_torch.rules.batch_knowledge`:
  every pair of the set's train episodes compared at once);
- the median novel-object error |predicted - Archimedes| / Archimedes (median over probes per (set, order), then
  over (set, order); nothing recalled counts as 100 %) after 1..8 episodes, and after 16 and 24 on the long sets,
  beside two peers fed the same episodes in the same orders: k nearest neighbours (k = 3, distance-weighted) and a
  small MLP (2 x 32 tanh, Adam, 400 full-batch steps), both on the raw measurements on log scales
  ([rgb, log extents, fill, log mass] -> log cm^3); and a reference that is told what the agent must learn, the
  law's form and each probe's true fate (a least-squares power law of measured mass and volume per fate, `law_form`):
  what the same episodes allow a learner that only has to fit the slopes, not a peer;
- a PNG of the learning curves: `--out PNG`, by default benches/generalization.png (tracked: the README shows it)
  with --record and the system's temporary directory (/tmp/generalization.png) without it.
Both agreement figures are printed for the sets of 24 too. Last line: `sets_order_independent=F
sequential_equals_batch=F median_error_8=E median_error_24=E sets_order_independent_24=F sequential_equals_batch_24=F`.
`--record` writes the output into BENCHMARKS.md and the curves into benches/generalization.png; without it no
tracked file is written.

The agent runs as the sweep benches/generalization.toml runs it: each set is train/sweep.py's cell
(`train.sweeps.cell.run_cell`: the set's seed draws the noise, the orders and the agent; all its orders one batched agent,
the probes predicted after every episode) and its figures (the error curve, both agreements, the batch answers,
colour and weight) are train/report.py's, so `python train/sweep.py benches/generalization.toml` then
`python -m train.report` gives them digit for digit (the condition named --model), and at scale on a Ray cluster.
The peers and the law-form reference are no sweep conditions: they run here on the same sets and orders.

The model's numbers were chosen on sets of seeds 1000 and up; the default seeds here (0..) were never looked at
while choosing them.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from aesop_torch.malloc import keep_freed_memory  # noqa: E402

import torch  # noqa: E402

from sim.make_objects import generate  # noqa: E402
from sim.objects import parse_objects  # noqa: E402
from sim.sensor_model import SensorModel  # noqa: E402
from train.learning.experiment import closed_form_outcomes, draw_orders, stack_measurements  # noqa: E402
from train.common.progress import Step  # noqa: E402
from train.sweeps import cell as sweep_cell  # noqa: E402
from train.sweeps import spec as sweep_spec  # noqa: E402
from train.sweeps.report import summarise  # noqa: E402
from cli_args import count, record_flag, seed  # noqa: E402
from record import run_main  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current (--record)

PNG = Path(__file__).with_name("generalization.png")   # tracked: rewritten only with --record


def raw_features(meas: dict) -> torch.Tensor:
    """(n, 8) the peers' inputs: rgb, log extents (cm), fill, log mass (g)."""
    return torch.cat([meas["rgb"], meas["extent_cm"].log(), meas["fill"][:, None], meas["mass_g"].log()[:, None]], 1)


def probe_errors(pred: torch.Tensor, truth: torch.Tensor) -> torch.Tensor:
    """(..., n_probes) predictions -> each probe's relative error (NaN counts as 1: nothing predicted)."""
    return torch.nan_to_num((pred - truth).abs() / truth, nan=1.0)


def rel_errors(pred: torch.Tensor, truth: torch.Tensor) -> torch.Tensor:
    """(B, n_probes) predictions -> (B,) median over probes of the relative error (NaN counts as 1)."""
    err = probe_errors(pred, truth)
    return err.median(dim=1).values if err.shape[1] % 2 else err.sort(dim=1).values[:, err.shape[1] // 2 - 1:
                                                                                    err.shape[1] // 2 + 1].mean(1)


def knn(train_x: torch.Tensor, train_y: torch.Tensor, x: torch.Tensor, k: int = 3) -> torch.Tensor:
    """Distance-weighted k nearest neighbours, batched: train (B, t, F), (B, t); queries (Q, F) -> (B, Q) log cm^3."""
    scale = torch.tensor([1, 1, 1, 0.5, 0.5, 0.5, 0.2, 1.0])           # rgb, log extents, fill, log mass
    d = torch.cdist(x[None].expand(train_x.shape[0], -1, -1) / scale, train_x / scale)     # (B, Q, t)
    k = min(k, train_x.shape[1])
    dist, idx = d.topk(k, dim=-1, largest=False)
    w = 1.0 / (dist + 1e-6)
    return (w * train_y.gather(1, idx.flatten(1)).view_as(idx)).sum(-1) / w.sum(-1)


def mlp(train_x: torch.Tensor, train_y: torch.Tensor, x: torch.Tensor, seed: int, steps: int = 400,
        hidden: int = 32) -> torch.Tensor:
    """A 2 x `hidden` tanh MLP per batch row, all trained at once (full batch, Adam): (B, t, F) -> (B, Q)."""
    g = torch.Generator().manual_seed(seed)
    B, t, F = train_x.shape
    mu, sd = train_x.mean(1, keepdim=True), train_x.std(1, keepdim=True, unbiased=False).clamp_min(0.1)
    ym, ys = train_y.mean(1, keepdim=True), train_y.std(1, keepdim=True, unbiased=False).clamp_min(0.1)
    X, Y, Xq = (train_x - mu) / sd, (train_y - ym) / ys, (x[None] - mu) / sd

    def layer(i, o):
        return [(torch.randn(B, i, o, generator=g) / math.sqrt(i)).requires_grad_(),
                torch.zeros(B, 1, o).requires_grad_()]

    params = layer(F, hidden) + layer(hidden, hidden) + layer(hidden, 1)

    def forward(z):
        w1, b1, w2, b2, w3, b3 = params
        return (torch.tanh(torch.tanh(z @ w1 + b1) @ w2 + b2) @ w3 + b3)[..., 0]

    opt = torch.optim.Adam(params, lr=0.01, weight_decay=1e-3)
    with torch.enable_grad():
        for _ in range(steps):
            opt.zero_grad()
            loss = ((forward(X) - Y) ** 2).mean()
            loss.backward()
            opt.step()
    with torch.no_grad():
        return forward(Xq) * ys + ym


def law_features(meas: dict) -> torch.Tensor:
    """(n, 2) the law-form reference's inputs: log mass (g), log volume (fill x the extents' product, cm^3)."""
    return torch.stack([meas["mass_g"].log(), (meas["fill"] * meas["extent_cm"].prod(-1)).log()], 1)


def law_form(train_x: torch.Tensor, train_y: torch.Tensor, train_sank: torch.Tensor, x: torch.Tensor,
             sinks: torch.Tensor, ridge: float = 1e-5) -> torch.Tensor:
    """A reference, not a peer: it is told what the agent must learn. Per probe, a least-squares fit of log cm^3
    on (log mass, log volume) over the seen episodes of the probe's *true* fate (Archimedes' form: each fate's
    displacement is a power law of the measured mass or volume, its slopes fitted, not given). train (B, t, 2),
    (B, t), (B, t) bool; probes (Q, 2), (Q,) bool -> (B, Q) log cm^3; the mean of all seen where none of its fate."""
    out = []
    for q in range(x.shape[0]):
        w = (train_sank == sinks[q]).double()                                  # (B, t)
        A = torch.cat([torch.ones_like(train_y[..., None]), train_x - x[q]], -1).double()
        reg = torch.eye(3, dtype=A.dtype) * ridge * w.sum(-1)[:, None, None].clamp_min(1)
        reg[:, 0, 0] = 1e-12
        beta = torch.linalg.solve(torch.einsum("btf,bt,btg->bfg", A, w, A) + reg,
                                  torch.einsum("btf,bt,bt->bf", A, w, train_y.double()))
        out.append(torch.where(w.sum(-1) > 0, beta[:, 0], train_y.double().mean(-1)))
    return torch.stack(out, 1).float()


def world(seed: int, n_train: int, n_probe: int = 8):
    """A generated set's world, as train/sweep.py's cell sees it (train.sweeps.cell.world_outcomes, closed_form): the train
    objects' measurements and outcomes, the probes' measurements, truths and fates."""
    objs = parse_objects(generate(seed, n_train, n_probe, pairs=True))
    outcomes, probes = closed_form_outcomes(objs, sensor=SensorModel(), seed=seed)
    names, probe_names = [o.name for o in objs.train], [o.name for o in objs.probe]
    return {"meas": stack_measurements([outcomes[n]["measurement"] for n in names]),
            "observed": torch.tensor([outcomes[n]["observed_cm3"] for n in names]),
            "sank": torch.tensor([outcomes[n]["sank"] for n in names]),
            "pmeas": stack_measurements([probes[n]["measurement"] for n in probe_names]),
            "truth": torch.tensor([probes[n]["archimedes_cm3"] for n in probe_names]),
            "probe_sinks": torch.tensor([o.sinks for o in objs.probe])}


def peer_set(seed: int, n_train: int, n_orders: int) -> dict:
    """The peers (kNN, MLP) and the law-form reference on one set, fed the episodes in the orders the set's cell
    learns them (`draw_orders` from the set's seed): {who: (n_train, B) errors after each episode}."""
    w = world(seed, n_train)
    orders = torch.tensor(draw_orders(n_train, str(n_orders), seed))
    x_all, y_all, xq = raw_features(w["meas"]), w["observed"].log(), raw_features(w["pmeas"])
    law_all, law_q, truth = law_features(w["meas"]), law_features(w["pmeas"]), w["truth"]
    errs = {"knn": [], "mlp": [], "law": []}
    for t in range(n_train):
        seen = orders[:, :t + 1]
        tx, ty = x_all[seen], y_all[seen]
        errs["knn"].append(rel_errors(knn(tx, ty, xq).exp(), truth))
        errs["mlp"].append(rel_errors(mlp(tx, ty, xq, seed * 1000 + t).exp(), truth))
        errs["law"].append(rel_errors(law_form(law_all[seen], ty, w["sank"][seen], law_q, w["probe_sinks"]).exp(),
                                      truth))
    return {k: torch.stack(v, 0) for k, v in errs.items()}


# the sweep file's set groups (benches/generalization.toml) of the bench's two kinds of set
GROUPS = {8: "sets of 8", 24: "sets of 24"}


def sweep_doc(model: str, sets: int, long_sets: int, orders: int, first_seed: int) -> dict:
    """This run's agent and sets as a sweep file: at the defaults, benches/generalization.toml's cells of the
    condition named --model."""
    return {"world": "closed_form", "conditions": [{"name": model, "model": model}],
            "sets": [{"name": GROUPS[n_train], "generate": {"seeds": [first_seed, first_seed + n_sets],
                                                            "train": n_train, "probe": 8, "pairs": True},
                      "orders": orders} for n_train, n_sets in ((8, sets), (24, long_sets))]}


def agent_rows(doc: dict, bar=None):
    """The rows (a pyarrow Table of train.sweeps.cell.schema()) of the sweep file `doc`: its cells run here, one after
    another (`train.sweeps.cell.run_cell`); equal, row for row, to train/sweep.py on the same file."""
    import pyarrow as pa
    _, cells = sweep_spec.resolve(doc, ROOT)
    tables = []
    for c in cells:
        tables.append(sweep_cell.run_cell(c["spec"], c["objects"]))
        if bar is not None:
            bar.update(1)
    return pa.concat_tables(tables)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sets", type=count, default=100)
    ap.add_argument("--long-sets", type=count, default=30)
    ap.add_argument("--orders", type=count, default=24)
    ap.add_argument("--first-seed", type=seed, default=0)
    ap.add_argument("--model", choices=("paper", "extended"), default="extended",
                    help="the agent's model (the batch answer is the extended model's rules over every pair)")
    ap.add_argument("--out", type=Path, help=f"the curves' PNG (default: {PNG.relative_to(ROOT)} with --record, "
                                             f"else {Path(tempfile.gettempdir()) / PNG.name})")
    record_flag(ap, "BENCHMARKS.md and the curves into " + str(PNG.relative_to(ROOT)))
    a = ap.parse_args()
    png = a.out or (PNG if a.record else Path(tempfile.gettempdir()) / PNG.name)
    keep_freed_memory()   # freed tensors reused, for the peers in this process too (aesop_torch/malloc.py)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    # the agent: train/sweep.py's cells (benches/generalization.toml at the defaults), its figures train/report.py's
    doc = sweep_doc(a.model, a.sets, a.long_sets, a.orders, a.first_seed)
    with Step("cells", a.sets + a.long_sets, unit="cell", stream=sys.stderr) as bar:   # stderr: not recorded
        rows = agent_rows(doc, bar)
    s = summarise(rows)
    peers = {}
    for n_train, n_sets in ((8, a.sets), (24, a.long_sets)):
        with Step(f"sets of {n_train}", n_sets, unit="set", stream=sys.stderr) as bar:   # the peers
            peers[n_train] = []
            for i in range(n_sets):
                peers[n_train].append(peer_set(a.first_seed + i, n_train, a.orders))
                bar.update(1)
        print(f"{n_sets} sets of {n_train} train objects x {a.orders} orders: {time.perf_counter() - t0:.0f} s",
              flush=True)

    def agreement(n_train):
        """(sets whose final knowledge is the same in every order, (set, order) whose knowledge is the batch's)"""
        k = s["knowledge"][a.model, GROUPS[n_train]]
        return k["order_agreement"], k["equals_batch"]

    short = s["knowledge"][a.model, GROUPS[8]]
    (same, equal), (same_24, equal_24) = agreement(8), agreement(24)
    print(f"\nknowledge over {short['cells']} sets of 8 (letters: colour shape size weight; U unknown, L likely "
          f"irrelevant, D dominant, I irrelevant)")
    print(f"  same knowledge in every order:        {_f3(same)} of sets ({_f3(same_24)} of the sets of 24)")
    print(f"  sequential equals the batch answer:   {equal:.3f} of (set, order) ({equal_24:.3f} for the sets of 24)")
    print(f"  batch answers: " + ", ".join(f"{k} {v}" for k, v in short["batch_answers"].items()))
    print(f"  colour irrelevant in {short['colour_irrelevant']:.3f}, weight dominant in {short['weight_dominant']:.3f} "
          f"of (set, order)")

    curves = {}
    for n_train, rs in peers.items():
        errs = s["errors"][a.model, GROUPS[n_train]]
        curves[n_train] = {"agent": [errs[t + 1][1] for t in range(n_train)]}
        curves[n_train].update({who: [float(torch.cat([r[who][t] for r in rs]).median()) for t in range(n_train)]
                                for who in rs[0]})
    print("\nmedian novel-object error vs Archimedes (median over probes, then over (set, order))")
    print(f"{'episodes':>9} {'agent':>8} {'kNN':>8} {'MLP':>8}   {'law form':>8} (told the form and the fate)")
    table = [(8, t) for t in range(8)] + [(24, t) for t in (7, 15, 23)]
    for n_train, t in table:
        c = curves[n_train]
        tag = f"{t + 1}" + (" (long)" if n_train == 24 else "")
        print(f"{tag:>9} {c['agent'][t]:>8.3f} {c['knn'][t]:>8.3f} {c['mlp'][t]:>8.3f}   {c['law'][t]:>8.3f}")
    ahead = all(curves[n]["agent"][t] < min(curves[n]["knn"][t], curves[n]["mlp"][t]) for n, t in table)
    print(f"agent ahead of both peers at every episode count: {ahead}")
    _plot(curves, png)
    print(f"curves: {png.resolve().relative_to(ROOT) if png.resolve().is_relative_to(ROOT) else png}; "
          f"{time.perf_counter() - t0:.0f} s")
    print(f"sets_order_independent={_f3(same)} sequential_equals_batch={equal:.3f} "
          f"median_error_8={curves[8]['agent'][7]:.3f} median_error_24={curves[24]['agent'][23]:.3f} "
          f"sets_order_independent_24={_f3(same_24)} sequential_equals_batch_24={equal_24:.3f}")


def _f3(x) -> str:
    """A share to 3 places; 1.000 where every cell has one order (--orders 1: nothing to disagree)."""
    return f"{1.0 if x is None else x:.3f}"


def _plot(curves: dict, png: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, (n_train, c) in zip(axes, curves.items()):
        for who, style in (("agent", "-o"), ("knn", "--s"), ("mlp", ":^"), ("law", "-.")):
            ax.plot(range(1, n_train + 1), [100 * e for e in c[who]], style, label=who, markersize=3)
        ax.set_title(f"{n_train} train objects per set", fontsize=9)
        ax.set_xlabel("episodes (objects explored)")
        ax.set_ylabel("median |predicted - Archimedes| / Archimedes (%)")
        ax.set_yscale("log")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=100)


if __name__ == "__main__":
    run_main("generalization", main)
