"""Checkpoints: a damaged or foreign file is refused in one line before anything is rewritten; Ctrl-C and a full
disk end the runner with one line, the last checkpoint intact, and --resume exact.

The runner runs in this process on a stand-in for the physics (closed-form outcomes), so that interrupting it at a
chosen point is cheap and deterministic; tests/test_run.py covers the real physics (and SIGKILL).
"""

import errno
import hashlib
import json
import random
import types
from pathlib import Path

import pytest
import torch

from train.learning import checkpoint as ck
from train import run as runner
from train.learning.experiment import Experiment, closed_form_outcomes, load_experiment

PAPER = {"train": [
    {"name": "red_heavy_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 420},
    {"name": "blue_heavy_cylinder", "shape": "cylinder", "color": "blue", "dims_cm": [6.36, 11.5], "mass_g": 420},
    {"name": "red_light_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 14}],
    "probe": [
    {"name": "green_light_cylinder", "shape": "cylinder", "color": "green", "dims_cm": [6.36, 11.5], "mass_g": 20}]}


class FakePhysics:
    """Physics' interface, answered in closed form (no simulator)."""

    def __init__(self, objects, seed=0, gui=False, workers=None):
        self.workers = 1
        self.outcomes, self.probes = closed_form_outcomes(objects)

    def start(self):
        pass

    def submit(self, jobs):
        return map(self._answer, jobs)

    def submit_early(self, jobs):   # Physics hands a new run's measurements over early; here submit answers them
        pass

    def _answer(self, job):
        kind, name, _ = job
        if kind == "inspect":
            return self.probes[name]["measurement"]
        o = self.outcomes[name]
        return types.SimpleNamespace(measurement=o["measurement"], observed_cm3=o["observed_cm3"],
                                     archimedes_cm3=o["archimedes_cm3"], goal_reachable_before=o["goal_before"],
                                     goal_reached_after=o["goal_after"], sank=o["sank"], true=o["true"], frames=None)

    def run(self, jobs, progress=None, submitted=None):
        results = []
        for job, r in zip(jobs, self.submit(jobs) if submitted is None else submitted):
            results.append(r)
            if progress:
                progress(job)
        return results

    def drops(self, names, record=False, progress=None):
        return self.run([("drop", n, record) for n in names], progress)

    def close(self):
        pass


@pytest.fixture
def fake_physics(monkeypatch):
    import train.learning.sim_pool
    monkeypatch.setattr(train.learning.sim_pool, "Physics", FakePhysics)


@pytest.fixture(scope="module")
def paper_file(tmp_path_factory):
    f = tmp_path_factory.mktemp("objects") / "paper.json"
    f.write_text(json.dumps(PAPER))
    return f


def argv(paper_file, out, *extra):
    return ["--objects", str(paper_file), "--orders", "3", "--out", str(out), *extra]


def tree(d: Path) -> dict:
    """Every file under d with the sha256 of its bytes: equal before and after means nothing was rewritten."""
    return {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.rglob("*"))
            if p.is_file()}


@pytest.fixture
def whole(paper_file, tmp_path, fake_physics, capsys):
    """An uninterrupted run: the reference every interrupted-and-resumed run must reproduce byte for byte."""
    out = tmp_path / "whole"
    assert runner.main(argv(paper_file, out)) == 0
    capsys.readouterr()
    return out


# -- the file itself -----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def saved(tmp_path_factory, paper_file):
    from sim.objects import load_objects
    objects = load_objects(paper_file)
    outcomes, probes = closed_form_outcomes(objects)
    exp = Experiment([o.name for o in objects.train], [o.name for o in objects.probe], [[0, 1, 2], [2, 1, 0]],
                     outcomes=outcomes, probes=probes)
    exp.step(lambda name, b, t: outcomes[name])
    exp.step(lambda name, b, t: outcomes[name])
    path = tmp_path_factory.mktemp("ckpt") / "latest.pt"
    run = {"objects": objects.canonical(), "seed": 0, "physics": "cached", "orders_arg": "2", "model": "paper",
           "ablate": []}
    ck.save_atomic({"run": run, "experiment": exp.state_dict()}, path)
    return path, exp


def test_a_checkpoint_from_before_the_two_models_reads_as_the_extended_model(tmp_path, paper_file):
    """Before `model` existed every checkpoint held the extended model: one without the field loads as that."""
    from aesop_torch.agent import AgentConfig
    from sim.objects import load_objects
    objects = load_objects(paper_file)
    outcomes, probes = closed_form_outcomes(objects)
    exp = Experiment([o.name for o in objects.train], [o.name for o in objects.probe], [[0, 1, 2]],
                     config=AgentConfig.extended(), outcomes=outcomes, probes=probes)
    exp.step(lambda name, b, t: outcomes[name])
    state = exp.state_dict()
    for key in ("model", "ablate", "compare_with"):
        del state["config"][key]
    run = {"objects": objects.canonical(), "seed": 0, "physics": "cached", "orders_arg": "listed"}
    ck.save_atomic({"run": run, "experiment": state}, tmp_path / "old.pt")
    again = load_experiment(tmp_path / "old.pt")
    m = exp.probes["green_light_cylinder"]["measurement"]
    assert again.config.model == "extended" and torch.equal(again.predict(m), exp.predict(m))
    assert ck.load(tmp_path / "old.pt")["run"]["model"] == "extended"


def test_round_trip_is_verified_and_readable_weights_only(saved):
    path, exp = saved
    raw = torch.load(path, weights_only=True)
    assert raw["format"] == ck.FORMAT and raw["experiment"]["t"] == 2 and len(raw["sha256"]) == 64
    state = ck.load(path)
    assert ck.digest(state["experiment"]) == ck.digest(exp.state_dict())
    again = load_experiment(path)
    m = exp.probes["green_light_cylinder"]["measurement"]
    assert torch.equal(again.predict(m), exp.predict(m)) and again.records == exp.records


def damaged_copies(path: Path, tmp_path: Path, n: int):
    data = path.read_bytes()
    rng = random.Random(0)
    for i in range(n):
        b = bytearray(data)
        if i % 2:
            at = rng.randrange(len(b) - 16)
            b[at:at + 16] = bytes(rng.randrange(256) for _ in range(16))    # 16 random bytes
        else:
            at = rng.randrange(len(b))
            b[at] ^= 1 << rng.randrange(8)                                  # one flipped bit
        f = tmp_path / f"damaged_{i}.pt"
        f.write_bytes(bytes(b))
        yield f


def test_damaged_files_are_refused_or_read_unchanged(saved, tmp_path):
    # a change torch.load does not see (zip padding, timestamps) may load: then the content must be exactly the
    # original; any change to the content must be refused
    path, _ = saved
    reference, refused = ck.digest(ck.load(path)), 0
    for f in damaged_copies(path, tmp_path, 60):
        try:
            state = ck.load(f)
        except ck.CheckpointError as e:
            assert "\n" not in str(e) and str(f) in str(e)
            refused += 1
        else:
            assert ck.digest(state) == reference
    assert refused >= 30


def test_checksum_catches_a_changed_value_even_when_the_zip_reads_fine(saved, tmp_path):
    path, _ = saved
    raw = torch.load(path, weights_only=True)
    raw["experiment"]["records"][0][0]["predicted_cm3"] = 12.0      # a different prediction, re-saved cleanly
    torch.save(raw, tmp_path / "edited.pt")
    with pytest.raises(ck.CheckpointError, match="checksum mismatch"):
        ck.load(tmp_path / "edited.pt")


def resaved(saved, tmp_path, edit):
    """The checkpoint with `edit` applied to its state and a valid checksum: wrong structure, right bytes."""
    path, _ = saved
    state = ck.load(path)
    edit(state)
    f = tmp_path / "foreign.pt"
    torch.save({"format": ck.FORMAT, "version": ck.VERSION, "sha256": ck.digest(state), **state}, f)
    return f


@pytest.mark.parametrize("edit, words", [
    (lambda s: s["experiment"].pop("records"), "records"),
    (lambda s: s["experiment"].update(t=7), "out of range"),
    (lambda s: s["experiment"].update(orders=[[0, 0, 1]]), "permutation"),
    (lambda s: s["experiment"]["records"][1].pop(), "records"),
    (lambda s: s["run"].pop("seed"), "run keys"),
    (lambda s: s["experiment"]["outcomes"].pop("blue_heavy_cylinder"), "no outcome"),
    (lambda s: s["experiment"]["agent"].update({"hub.W": torch.zeros(2, 3)}), "hub.W"),
    (lambda s: s["experiment"]["agent"].pop("memory.patterns"), "missing"),
    (lambda s: s["experiment"]["agent"]["hub.strength"].fill_(float("nan")), "non-finite"),
    (lambda s: s["experiment"]["probes"]["green_light_cylinder"]["measurement"].update(rgb=[1.0]), "malformed"),
])
def test_wrong_structure_is_refused_in_one_line(saved, tmp_path, edit, words):
    f = resaved(saved, tmp_path, edit)
    with pytest.raises(ck.CheckpointError, match="wrong structure") as e:
        ck.load(f)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_an_older_unchecksummed_checkpoint_is_refused_until_upgraded(saved, tmp_path):
    state = ck.load(saved[0])
    torch.save(state, tmp_path / "old.pt")     # what this code wrote before checkpoints had a format and checksum
    with pytest.raises(ck.CheckpointError, match="older version"):
        ck.load(tmp_path / "old.pt")
    ck.upgrade(tmp_path / "old.pt")
    assert ck.digest(ck.load(tmp_path / "old.pt")) == ck.digest(state)


def test_foreign_and_oversized_files_are_refused(saved, tmp_path, monkeypatch):
    torch.save({"run": {}, "experiment": {}, "x": 1}, tmp_path / "old.pt")   # no format tag: foreign
    torch.save([1, 2, 3], tmp_path / "list.pt")
    (tmp_path / "text.pt").write_text("not a checkpoint")
    for name in ("old.pt", "list.pt", "text.pt"):
        with pytest.raises(ck.CheckpointError, match="not a"):
            ck.load(tmp_path / name)
    with pytest.raises(ck.CheckpointError, match="regular file"):
        ck.load(tmp_path)
    monkeypatch.setattr(ck, "MAX_BYTES", 1000)
    with pytest.raises(ck.CheckpointError, match="larger than"):
        ck.load(saved[0])


# -- the runner ------------------------------------------------------------------------------------------------------

def test_resume_refuses_a_damaged_checkpoint_before_rewriting_anything(paper_file, whole, tmp_path, capsys):
    out = tmp_path / "damaged"
    out.mkdir()
    for p in whole.rglob("*"):
        if p.is_file():
            (out / p.relative_to(whole)).parent.mkdir(parents=True, exist_ok=True)
            (out / p.relative_to(whole)).write_bytes(p.read_bytes())
    ckpt = out / "checkpoints" / "latest.pt"
    b = bytearray(ckpt.read_bytes())
    b[len(b) // 3] ^= 0x10
    ckpt.write_bytes(bytes(b))
    before = tree(out)
    assert runner.main(argv(paper_file, out, "--resume")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--resume" in err[0] and "latest.pt" in err[0], err
    assert tree(out) == before


def test_full_disk_ends_in_one_line_and_resume_is_exact(paper_file, whole, tmp_path, fake_physics, monkeypatch,
                                                        capsys):
    out = tmp_path / "full"
    real, calls = ck._write_bytes, []

    def full_after_three(f, data):   # the 6th atomic write (config.json, run.json, then the checkpoint at the start,
        calls.append(1)               # after the simulations, after episode 1, after episode 2) finds the disk full
        if len(calls) == 6:
            raise OSError(errno.ENOSPC, "No space left on device", f.name)
        real(f, data)

    monkeypatch.setattr(ck, "_write_bytes", full_after_three)
    assert runner.main(argv(paper_file, out)) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0] and "1 of 3 episodes" in err[0], err
    assert ck.load(out / "checkpoints" / "latest.pt")["experiment"]["t"] == 1
    assert not list((out / "checkpoints").glob("*.tmp"))         # the half-written file is gone
    assert not (out / "summary.json").exists()
    monkeypatch.setattr(ck, "_write_bytes", real)
    assert runner.main(argv(paper_file, out, "--resume")) == 0
    assert (out / "summary.json").read_bytes() == (whole / "summary.json").read_bytes()


def test_ctrl_c_ends_in_one_line_and_resume_is_exact(paper_file, whole, tmp_path, fake_physics, monkeypatch, capsys):
    out = tmp_path / "interrupted"
    real_step = Experiment.step

    def interrupted_in_episode_3(self, world_episode):
        if self.t == 2:
            raise KeyboardInterrupt
        return real_step(self, world_episode)

    monkeypatch.setattr(Experiment, "step", interrupted_in_episode_3)
    assert runner.main(argv(paper_file, out)) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "interrupted" in err[0] and "2 of 3 episodes" in err[0] and "--resume" in err[0], err
    assert ck.load(out / "checkpoints" / "latest.pt")["experiment"]["t"] == 2
    monkeypatch.setattr(Experiment, "step", real_step)
    assert runner.main(argv(paper_file, out, "--resume")) == 0
    assert (out / "summary.json").read_bytes() == (whole / "summary.json").read_bytes()


def test_a_contextual_checkpoint_round_trips_with_its_knowledge_per_context(tmp_path, paper_file):
    """The contextual model's state (its per-context strengths, its split maps) and records (certainty per context)
    pass the checkpoint's checks and load to the same predictions and knowledge."""
    from aesop_torch.agent import AgentConfig
    from sim.objects import load_objects
    objects = load_objects(paper_file)
    outcomes, probes = closed_form_outcomes(objects)
    exp = Experiment([o.name for o in objects.train], [o.name for o in objects.probe], [[0, 1, 2]],
                     config=AgentConfig.contextual(), outcomes=outcomes, probes=probes)
    for _ in range(3):
        exp.step(lambda name, b, t: outcomes[name])
    run = {"objects": objects.canonical(), "seed": 0, "physics": "cached", "orders_arg": "listed",
           "model": "contextual", "ablate": []}
    ck.save_atomic({"run": run, "experiment": exp.state_dict()}, tmp_path / "ctx.pt")
    again = load_experiment(tmp_path / "ctx.pt")
    m = exp.probes["green_light_cylinder"]["measurement"]
    assert again.config.model == "contextual" and torch.equal(again.predict(m), exp.predict(m))
    assert torch.equal(again.agent.rules.strength, exp.agent.rules.strength)
    assert again.knowledge_as_it_is()[0]["by_context"]["fate"]["dominant"] == ["weight"]
