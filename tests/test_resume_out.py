"""--resume --out DIR alone continues a run with its own settings; leftovers of a run killed before its first
checkpoint, links inside --out and unusable --out paths are handled in one line."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import torch

from in_process import run_main, wait_until_unlocked

ROOT = Path(__file__).resolve().parents[1]
OBJECTS = {"train": [
    {"name": "red_heavy_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 420},
    {"name": "blue_heavy_cylinder", "shape": "cylinder", "color": "blue", "dims_cm": [6.36, 11.5], "mass_g": 420},
    {"name": "red_light_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 14}]}


def run(*args, timeout=300):
    return subprocess.run([sys.executable, str(ROOT / "train" / "run.py"), *args], capture_output=True, text=True,
                          timeout=timeout)


def one_line(r, code=2):
    lines = r.stderr.strip().splitlines()
    assert r.returncode == code and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    return lines[0]


def objects_file(tmp_path):
    f = tmp_path / "objects.json"
    f.write_text(json.dumps(OBJECTS))
    return f


def test_resume_alone_continues_the_run_bit_identical(tmp_path):
    # per-episode physics: every episode simulates a drop, so the kill lands between episodes
    args = ["--objects", str(objects_file(tmp_path)), "--orders", "1", "--seed", "1", "--physics", "per-episode",
            "--set", "recall_sharpness=8"]
    whole = tmp_path / "whole"
    assert run_main(*args, "--out", whole).returncode == 0   # in this process: SIGKILL's run is the next one
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, str(ROOT / "train" / "run.py"), *args, "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ckpt = out / "checkpoints" / "latest.pt"
    deadline = time.time() + 200
    while proc.poll() is None and time.time() < deadline:
        if ckpt.exists() and torch.load(ckpt, weights_only=True)["experiment"]["t"] >= 1:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "summary.json").exists(), "the run finished before it could be killed"
    wait_until_unlocked(out)   # its workers' exit, before a resume in this process
    # a flag that contradicts the run's settings: one line naming the stored value, nothing changed
    for other, said in ((["--seed", "3"], "--seed 3 contradicts the run's seed 1"),
                        (["--orders", "2"], "--orders 2 contradicts the run's orders 1"),
                        (["--set", "recall_sharpness=4"], "contradicts the run's recall_sharpness 8"),
                        (["--model", "extended"], "contradicts the run's model"),
                        (["--physics", "cached"], "contradicts the run's physics per-episode")):
        before = ckpt.read_bytes()
        assert said in one_line(run_main("--resume", "--out", out, *other))
        assert ckpt.read_bytes() == before and not (out / "summary.json").exists()
    # without run.json (a run from before it, or the file removed) the flags are the run's only account of itself:
    # the refusal says the directory holds none and names the checkpoint's setting that differs, nothing changed
    (out / "run.json").rename(tmp_path / "run.json")
    before = ckpt.read_bytes()
    line = one_line(run_main("--resume", "--out", out))
    assert f"{out} holds no run.json" in line and "other objects" in line and "orders_arg" not in line, line
    line = one_line(run_main("--resume", "--out", out, "--objects", args[1]))
    assert f"{out} holds no run.json" in line and "its checkpoint ran --seed 1" in line, line
    assert ckpt.read_bytes() == before and not (out / "summary.json").exists()
    (tmp_path / "run.json").rename(out / "run.json")
    # alone, or with flags that agree: continues to the uninterrupted run's summary
    r = run_main("--resume", "--out", out, "--seed", "1", "--orders", "1")
    assert r.returncode == 0, r.stderr
    resumed, uninterrupted = (json.loads((d / "summary.json").read_text()) for d in (out, whole))
    resumed.pop("commit"), uninterrupted.pop("commit")   # other work may be committed between the two runs
    assert resumed == uninterrupted


def test_leftover_temp_checkpoint_does_not_block_a_fresh_run_or_resume(tmp_path):
    objects = objects_file(tmp_path)
    out = tmp_path / "out"
    (out / "checkpoints").mkdir(parents=True)
    (out / "checkpoints" / "latest.pt.k3j2x.tmp").write_bytes(b"half a checkpoint")
    (out / "config.json").write_text("{}\n")
    # a resume says there is no checkpoint, in one line, and leaves the leftovers
    assert "no checkpoint" in one_line(run_main("--resume", "--out", out, "--objects", str(objects)))
    r = run_main("--objects", objects, "--orders", "1", "--out", out)
    assert r.returncode == 0, r.stderr
    assert (out / "summary.json").is_file() and not (out / "checkpoints" / "latest.pt.k3j2x.tmp").exists()


def test_a_link_inside_out_is_refused_on_resume_and_nothing_written(tmp_path):
    out = tmp_path / "out"
    (out / "checkpoints").mkdir(parents=True)
    (out / "checkpoints" / "latest.pt").write_bytes(b"x")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    for name in ("tb", "summary.json"):
        link = out / name
        link.symlink_to(elsewhere / name)
        before = sorted(p.name for p in out.iterdir())
        line = one_line(run("--resume", "--out", str(out), timeout=60))
        assert "symbolic link" in line and str(link) in line, line
        assert sorted(p.name for p in out.iterdir()) == before and list(elsewhere.iterdir()) == []
        link.unlink()


def test_unusable_out_is_one_line_exit_2(tmp_path):
    f = tmp_path / "afile"
    f.write_text("mine")
    for out in (f, f / "sub"):
        for resume in ([], ["--resume"]):
            line = one_line(run("--out", str(out), *resume, timeout=60))
            assert str(f) in line, line
    assert f.read_text() == "mine"


def test_make_objects_runs_as_a_script_from_anywhere(tmp_path):
    script = [sys.executable, str(ROOT / "sim" / "make_objects.py")]
    r = subprocess.run(script + ["--seed", "1", "--train", "4", "--out", "-"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert len(json.loads(r.stdout)["train"]) == 4
    r = subprocess.run(script + ["--bogus"], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
