"""checkpoints/default.pt is what `make default-checkpoint` makes: checkpoints/latest.pt of `python train/run.py`
with no arguments. Checked against what the runner does today (its own functions: the default flags, the config it
resolves, the experiment it builds), so the test stays true when the runner's config grows a field and the file is
remade, and fails when it is not remade: the run's record, the agents' whole config (layout and values), a default
object's simulated outcome, and the exploration replayed on the file's outcomes to the same records, final knowledge
and predictions for every default object."""

import json
import math
import os
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "checkpoints" / "default.pt"


def test_the_shipped_default_checkpoint_is_what_a_fresh_default_run_writes(tmp_path):
    from train import run
    from train.runner import loop as run_loop
    from train.common.config import first_difference
    from train.learning.experiment import load_experiment, outcome_record
    from train.learning.sim_pool import Physics

    stored = torch.load(SHIPPED, weights_only=True)
    shipped = load_experiment(SHIPPED)
    args = run.parse_args(["--out", str(tmp_path / "out")])   # the runner's defaults, as it resolves them
    objects = run.load_run_objects(args)
    args.run_config = run.resolve_config(args, objects)
    exp, resumed, lock = run_loop.prepare(args, objects, run.count_orders(len(objects.train), args.orders))
    os.close(lock)
    assert not resumed
    assert stored["run"] == {"objects": objects.canonical(), "seed": args.seed, "physics": args.physics,
                             "orders_arg": args.orders, "model": args.model, "ablate": args.ablate}
    # every field of the agents' config, as the run holds it (JSON's lists for tuples); the first that differs named
    here, there = (json.loads(json.dumps(c)) for c in (exp.state_dict()["config"], stored["experiment"]["config"]))
    assert here == there, f"{first_difference(here, there)}: remake it (make default-checkpoint)"
    assert stored["experiment"]["orders"] == exp.state_dict()["orders"]
    # the physics: a default object simulated now, as a worker would, gives the file's outcome
    physics = Physics(objects, seed=args.seed, workers=1)
    try:
        fresh = outcome_record(physics.drops(["red_heavy_cylinder"])[0])
    finally:
        physics.close()
    assert close(fresh, shipped.outcomes["red_heavy_cylinder"])
    # the exploration on the file's outcomes: the same episodes, knowledge and predictions
    exp.outcomes, exp.probes = dict(shipped.outcomes), dict(shipped.probes)
    while not exp.done:
        exp.step(lambda name, b, t: exp.outcomes[name])
    assert close(exp.records, shipped.records)
    assert close(exp.final_knowledge(), shipped.final_knowledge())
    for spec in objects.train + objects.probe:
        m = spec.exact_measurement()
        assert torch.allclose(exp.predict(m), shipped.predict(m), rtol=1e-5, atol=1e-4), spec.name


def close(a, b, where: str = "") -> bool:
    """a == b, numbers within a relative 1e-5 (another CPU may round the last bits of float32 sums otherwise): the
    first difference raises AssertionError naming where it is."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), f"{where}: keys {sorted(a.keys() ^ b.keys())}"
        return all(close(a[k], b[k], f"{where}.{k}") for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        assert len(a) == len(b), f"{where}: {len(a)} != {len(b)} items"
        return all(close(x, y, f"{where}[{i}]") for i, (x, y) in enumerate(zip(a, b)))
    if isinstance(a, float) or isinstance(b, float):
        assert a == b or math.isclose(a, b, rel_tol=1e-5, abs_tol=1e-6), f"{where}: {a} != {b}"
        return True
    assert a == b, f"{where}: {a!r} != {b!r}"
    return True
