"""The library's calls on a few agents (load_experiment, Experiment.predict, probe_predictions) run on one torch
thread, and give the caller's thread count back: on a busy 2-core machine a second thread only waited (predict of
4 agents: 10 ms quiet, 600 ms beside another job)."""

import subprocess
import sys
from pathlib import Path

import pytest
import torch

from train.learning.experiment import load_experiment, one_thread

CKPT = Path(__file__).resolve().parents[1] / "checkpoints" / "default.pt"


@pytest.fixture
def two_threads():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


def test_one_thread_restores_the_callers_count_even_on_error(two_threads):
    with one_thread():
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == 2
    with pytest.raises(RuntimeError), one_thread():
        raise RuntimeError("boom")
    assert torch.get_num_threads() == 2


def test_predict_and_probe_predictions_run_on_one_thread(two_threads, monkeypatch):
    exp = load_experiment(CKPT)
    assert torch.get_num_threads() == 2
    seen = []
    for name in ("predict", "activities"):   # probe_predictions perceives each probe with activities
        real = getattr(exp.agent, name)
        monkeypatch.setattr(exp.agent, name, lambda *a, real=real, **k: seen.append(torch.get_num_threads())
                            or real(*a, **k))
    m = exp.probes[exp.probe_names[0]]["measurement"]
    pred = exp.predict(m)
    assert torch.get_num_threads() == 2
    probes = exp.probe_predictions()
    assert torch.get_num_threads() == 2
    assert seen and set(seen) == {1}
    assert torch.equal(pred, probes[:, 0])   # the same answers as the probe-by-probe predict


def test_checkpoint_and_experiment_import_no_cycle():
    """train.learning.checkpoint verifies a checkpoint (agents built from its config included) without train.learning.experiment,
    which imports it."""
    code = "import sys; from train.learning.checkpoint import load; load(sys.argv[1]); print('train.learning.experiment' in sys.modules)"
    r = subprocess.run([sys.executable, "-c", code, str(CKPT)], capture_output=True, text=True, timeout=120,
                       cwd=CKPT.parents[1])
    assert r.returncode == 0 and r.stdout.strip() == "False", r.stderr
