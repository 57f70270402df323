"""Forged checkpoints (issue 33, item 5): files whose checksum is right but whose content was made to hurt or
mislead. Each is refused in one line (CheckpointError; exit 2 from `train/run.py --resume`), before any tensor's
bytes are read when the tensors' headers are wrong, and the file is left as it was.

The runs are the closed-form stand-in for the physics of tests/test_checkpoint.py (its fixtures, imported).
"""

import hashlib
import math
import random

import pytest
import torch

from test_checkpoint import FakePhysics, argv, fake_physics, paper_file, saved, tree, whole  # noqa: F401 fixtures
from train.learning import checkpoint as ck
from train import run as runner
from train.learning.experiment import Experiment, closed_form_outcomes, load_experiment


def write_forged(state: dict, f, sha256: str | None = None):
    """The state with a checksum that matches it (or `sha256`, for a state digest() cannot or must not read)."""
    torch.save({"format": ck.FORMAT, "version": ck.VERSION, "sha256": sha256 or ck.digest(state), **state}, f)
    return f


def forged(saved, tmp_path, edit):
    state = ck.load(saved[0])
    edit(state)
    return write_forged(state, tmp_path / "forged.pt")


def refused(f, words: str) -> str:
    before = hashlib.sha256(f.read_bytes()).hexdigest()
    with pytest.raises(ck.CheckpointError) as e:
        load_experiment(f)
    message = str(e.value)
    assert words in message and "\n" not in message and str(f) in message, message
    assert hashlib.sha256(f.read_bytes()).hexdigest() == before
    return message


@pytest.fixture
def digest_unused(monkeypatch):
    """Call it once the forged file is written: from then on digest() must not run (the headers condemn the file)."""
    def never(obj):
        raise AssertionError("digest() read a tensor the headers should have refused")
    return lambda: monkeypatch.setattr(ck, "digest", never)


# -- tensors refused from their headers ------------------------------------------------------------------------------

def test_a_stride_0_tensor_of_4_tb_in_a_small_file_is_refused_before_any_byte_is_read(saved, tmp_path,
                                                                                      digest_unused):
    state = ck.load(saved[0])
    state["experiment"]["agent"]["hub.branches"] = torch.zeros(1).expand(10 ** 6, 10 ** 6)   # 4e12 bytes, 4 stored
    # its true digest would hash 4 TB, so it carries none that matches: the refusal comes before the checksum is
    # computed (digest_unused); the next test forges a stride-0 tensor whose checksum does match
    f = write_forged(state, tmp_path / "huge.pt", "0" * 64)
    assert f.stat().st_size < 1_000_000
    digest_unused()
    message = refused(f, "not all stored")
    assert "(1000000, 1000000)" in message and "strides (0, 0)" in message


def test_a_stride_0_tensor_of_the_right_shape_is_refused_with_a_valid_checksum(saved, tmp_path):
    def edit(s):
        ref = s["experiment"]["agent"]["hub.branches"]
        s["experiment"]["agent"]["hub.branches"] = torch.zeros(1).expand(ref.shape)   # the config's shape, 4 bytes
    f = forged(saved, tmp_path, edit)
    raw = torch.load(f, weights_only=True)
    assert raw["sha256"] == ck.digest({"run": raw["run"], "experiment": raw["experiment"]})   # the checksum passes
    refused(f, "not all stored")


@pytest.mark.parametrize("make, words", [
    (lambda t: t.to_sparse(), "sparse_coo"),
    (lambda t: t.to_sparse_csr(), "sparse_csr"),
    (lambda t: t.double(), "torch.float64"),
    (lambda t: t.to(torch.complex64), "torch.complex64"),
])
def test_sparse_and_foreign_tensors_are_refused_in_one_line(saved, tmp_path, digest_unused, make, words):
    state = ck.load(saved[0])
    state["experiment"]["agent"]["hub.strength"] = make(state["experiment"]["agent"]["hub.strength"])
    f = write_forged(state, tmp_path / "sparse.pt", "0" * 64)
    digest_unused()
    refused(f, words)


def test_tensors_sharing_one_storage_cannot_add_up_beyond_the_file(saved, tmp_path, digest_unused):
    """Each view holds its elements, but 10,000 views of one 400 kB storage would have digest() read 4 GB."""
    state = ck.load(saved[0])
    block = torch.zeros(100_000)
    state["experiment"]["records"][0][0]["views"] = [block[:] for _ in range(10_000)]
    f = write_forged(state, tmp_path / "views.pt", "0" * 64)
    digest_unused()
    refused(f, "more than")


# -- values out of their range ----------------------------------------------------------------------------------------

def _set(path, value):
    def edit(s):
        d = s
        for k in path[:-1]:
            d = d[k]
        d[path[-1]] = value
    return edit


def _fill(key, value):
    return lambda s: s["experiment"]["agent"][key].fill_(value)


def _roll_back(s):
    """t one episode back, records cut to match: the agents still hold the episode the records no longer show."""
    e = s["experiment"]
    e["t"] -= 1
    for r in e["records"]:
        r.pop()


@pytest.mark.parametrize("edit, words", [
    # finite but huge: a codebook holds weighted means of inputs in 0..1; a strength is at most the dominant one
    (_fill("maps.color.weights", 1e30), "'maps.color.weights' holds values outside [0, 1]"),
    (_fill("hub.strength", 1e30), "'hub.strength' holds values outside [0, 3]"),
    (_fill("hub.branches", -1.0), "'hub.branches'"),
    (_fill("maps.size.locations", 3.0), "grid"),
    (_fill("memory.count", 10 ** 12), "'memory.count'"),
    # the config, through the config's own validation (train.common.config, as --set would)
    (_set(("experiment", "config", "encoder", "mass_min_g"), 0.0), "encoder.mass_min_g takes a number (float) > 0"),
    (_set(("experiment", "config", "recall_sharpness"), math.nan), "recall_sharpness takes a finite number"),
    (_set(("experiment", "config", "rules", "certainty_step"), math.nan), "rules.certainty_step"),
    (_set(("experiment", "config", "hub", "n_neurons"), 10 ** 9), "hub.n_neurons"),
    (_set(("experiment", "config", "bogus"), 1), "unknown key bogus"),
    # a valid config whose agents would take 2 x 3 x (20 x 1000 + 1000) bytes, more than the file: refused before
    # they are built (the largest sheet train.common.config.RANGES admits, 1000 columns)
    (lambda s: (s["experiment"]["config"]["memory"].update(cols=1000),
                s["experiment"]["config"]["hub"].update(n_neurons=1000)),
     "config asks for agents of more than 126,000 bytes"),
    # outcomes and probes
    (lambda s: s["experiment"]["outcomes"]["red_light_cylinder"]["measurement"].update(mass_g=-14.0),
     "mass_g -14.0 not positive"),
    (lambda s: s["experiment"]["outcomes"]["red_light_cylinder"].update(observed_cm3=1e300), "the jar holds"),
    (lambda s: s["experiment"]["probes"]["green_light_cylinder"]["measurement"].update(fill=1.5), "fill 1.5"),
    (lambda s: s["experiment"]["probes"]["green_light_cylinder"]["measurement"].update(rgb=[2.0, 0.0, 0.0]),
     "outside 0..1"),
    # orders, records and t
    (_set(("experiment", "orders"), [[0, 1, 3], [2, 1, 0]]), "permutation"),
    (_set(("experiment", "orders"), [[0, 1], [1, 0]]), "permutation"),
    (lambda s: s["experiment"]["orders"].reverse(), "is not a record of"),
    (_roll_back, "'memory.count' holds values outside [0, 1]"),
    # the run's objects: what the objects file takes, and the experiment's names
    (lambda s: s["run"]["objects"]["train"][0].update(mass_g=-1.0), "the run's objects"),
    (lambda s: s["run"]["objects"]["train"].reverse(), "not the experiment's"),
])
def test_values_out_of_range_are_refused_in_one_line(saved, tmp_path, edit, words):
    refused(forged(saved, tmp_path, edit), words)


def test_the_bounds_hold_on_the_real_checkpoint(saved):
    """The oracle for the bounds above: the real run's values sit inside them ."""
    agent = ck.load(saved[0])["experiment"]["agent"]
    assert 0 <= float(agent["maps.color.weights"].min()) and float(agent["maps.color.weights"].max()) <= 1
    assert float(agent["hub.strength"].max()) <= max(1.0, saved[1].config.rules.dominant_strength)
    assert agent["memory.count"].tolist() == [sum(r["encoded"] for r in rec) for rec in saved[1].records]


# -- the runner ------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("edit", ["stride0", "sparse", "huge_weights", "rolled_back"])
def test_resume_refuses_a_forged_checkpoint_with_exit_2_and_changes_nothing(paper_file, whole, tmp_path, capsys,
                                                                             edit):
    out = tmp_path / "forged"
    for p in whole.rglob("*"):
        if p.is_file():
            (out / p.relative_to(whole)).parent.mkdir(parents=True, exist_ok=True)
            (out / p.relative_to(whole)).write_bytes(p.read_bytes())
    ckpt = out / "checkpoints" / "latest.pt"
    state = ck.load(ckpt)
    agent, sha = state["experiment"]["agent"], None
    if edit == "stride0":
        agent["hub.branches"] = torch.zeros(1).expand(agent["hub.branches"].shape)
    elif edit == "sparse":
        agent["hub.strength"], sha = agent["hub.strength"].to_sparse(), "0" * 64
    elif edit == "huge_weights":
        agent["maps.weight.weights"].fill_(1e30)
    else:
        _roll_back(state)
    write_forged(state, ckpt, sha)
    before = tree(out)
    assert runner.main(argv(paper_file, out, "--resume")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--resume" in err[0] and "latest.pt" in err[0], err
    assert tree(out) == before


# -- the largest run the objects file allows -------------------------------------------------------------------------

def test_a_checkpoint_of_a_run_with_the_most_objects_the_file_allows_loads(tmp_path):
    """As many train objects as sim.objects.ObjectsConfig allows (its cap, read, not assumed), the agents' memory
    and hub sized to hold them all: the checks refuse none of it, and the run resumes exactly where it was."""
    from aesop_torch.agent import AgentConfig
    from sim.make_objects import generate
    from sim.objects import ObjectsConfig, parse_objects

    n = ObjectsConfig().max_objects
    objects = parse_objects(generate(0, n_train=n, n_probe=2))
    # closed_form_outcomes solves each floater's depth (~30 ms an object): a free floater displaces its mass in
    # water of 1 g/cm^3, a sinker its volume, which is all a checkpoint's checks need
    cm3 = {s.name: min(s.mass_g, s.volume_cm3) for s in objects.train + objects.probe}
    outcomes = {s.name: {"measurement": s.exact_measurement(), "observed_cm3": cm3[s.name],
                         "archimedes_cm3": cm3[s.name], "goal_before": False, "goal_after": False,
                         "sank": bool(s.sinks)} for s in objects.train}
    probes = {s.name: {"measurement": s.exact_measurement(), "archimedes_cm3": cm3[s.name]} for s in objects.probe}
    config = AgentConfig.paper()
    config.memory.max_episodes = config.hub.max_assemblies = n
    names = [o.name for o in objects.train]
    exp = Experiment(names, [o.name for o in objects.probe], [list(range(n)), list(range(n))[::-1]], config=config,
                     outcomes=outcomes, probes=probes)
    exp.step(lambda name, b, t: outcomes[name])
    exp.step(lambda name, b, t: outcomes[name])
    run = {"objects": objects.canonical(), "seed": 0, "physics": "cached", "orders_arg": "2", "model": "paper",
           "ablate": []}
    ck.save_atomic({"run": run, "experiment": exp.state_dict()}, tmp_path / "latest.pt")
    again = load_experiment(tmp_path / "latest.pt")
    assert len(again.train_names) == n and again.agent.memory.patterns.shape[1] == n and again.t == 2
    assert ck.digest(again.state_dict()) == ck.digest(exp.state_dict())


def test_an_extended_life_whose_uncertainty_fired_more_often_than_its_episodes_loads(tmp_path):
    """The extended model counts Uncertainty once per comparison, and an episode is compared with every episode it
    recalls: over 8 episodes the count may pass 8 (a fresh `--model extended` run's own checkpoint was refused)."""
    from aesop_torch.agent_config import AgentConfig
    from sim.objects import load_objects
    objects = load_objects(runner.DEFAULT_OBJECTS)
    outcomes, probes = closed_form_outcomes(objects)
    names = [o.name for o in objects.train]
    rng = random.Random(0)
    orders = [rng.sample(range(len(names)), len(names)) for _ in range(8)]   # orders 5, 7 and 8 count 9
    exp = Experiment(names, [o.name for o in objects.probe], orders, outcomes=outcomes, probes=probes,
                     config=AgentConfig.extended())
    for _ in names:
        exp.step(lambda name, b, t: outcomes[name])
    count = exp.agent.rules.uncertain_count
    assert int(count.max()) > exp.t   # the case: more Uncertainty than episodes
    path = tmp_path / "latest.pt"
    run = {"objects": objects.canonical(), "seed": 0, "physics": "cached", "orders_arg": "8",
           "model": "extended", "ablate": []}
    ck.save_atomic({"run": run, "experiment": exp.state_dict()}, path)
    assert torch.equal(load_experiment(path).agent.rules.uncertain_count, count)
