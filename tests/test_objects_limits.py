"""The objects file's limits that come from elsewhere agree with where they come from (the hand's least felt mass),
a file beyond them is refused up front, a run its memory or hub cannot hold (when_full = refuse) is refused up front
by the runner, and refusing any file takes seconds, not minutes (the nesting check is linear in the file's size)."""

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aesop_torch.hub import HubConfig
from in_process import run_main
from aesop_torch.memory import MemoryConfig
from sim.objects import MAX_FILE_BYTES, ObjectsConfig, ObjectsFileError, parse_objects
from sim.sensor_model import SensorModel

ROOT = Path(__file__).resolve().parents[1]
CFG = ObjectsConfig()


def cube(i: int) -> dict:
    return {"name": f"o{i}", "shape": "cube", "color": "red", "dims_cm": [2.0], "mass_g": 5}


def test_the_object_limit_is_no_longer_the_memorys_a_forgetting_memory_runs_past_it():
    # the file allows lives longer than the default memory and hub; the runner refuses what a `refuse` one can't hold
    assert CFG.max_objects == 2000 > MemoryConfig().max_episodes == HubConfig().max_assemblies == 230


def test_the_lightest_object_is_the_least_the_hand_reports():
    from sim.world import WorldConfig
    assert CFG.min_mass_g == SensorModel().min_felt_mass_g == WorldConfig().min_felt_mass_g


@pytest.mark.parametrize("n_train, n_pool", [(2001, 0), (1800, 201), (1, 2000)])
def test_more_objects_than_the_file_allows_are_refused_up_front(n_train, n_pool):
    data = {"train": [cube(i) for i in range(n_train)], "pool": [cube(n_train + i) for i in range(n_pool)]}
    with pytest.raises(ObjectsFileError) as e:
        parse_objects(data)
    msg = str(e.value)
    assert f"{n_train + n_pool} objects" in msg and "2000" in msg and "\n" not in msg


def test_as_many_objects_as_the_file_allows_are_admitted():
    assert len(parse_objects({"train": [cube(i) for i in range(2000)]}).train) == 2000
    s = parse_objects({"train": [cube(i) for i in range(1800)], "pool": [cube(1800 + i) for i in range(200)],
                       "probe": [cube(2000 + i) for i in range(40)]})     # probes are only predicted: not counted
    assert len(s.train) + len(s.pool) == 2000 and len(s.probe) == 40


@pytest.mark.parametrize("sets, words", [
    ([], "memory.max_episodes = 230 and memory.when_full = refuse, hub.max_assemblies = 230"),  # the defaults: both
    (["memory.when_full=forget_oldest"], "hub.max_assemblies = 230 and hub.when_full = refuse"),
    (["memory.when_full=forget_weakest", "hub.max_assemblies=100", "hub.when_full=refuse"], "hub.max_assemblies = 100"),
])
def test_the_runner_refuses_a_life_its_memory_or_hub_cannot_hold_before_writing_anything(tmp_path, sets, words):
    f = tmp_path / "many.json"
    f.write_text(json.dumps({"train": [cube(i) for i in range(231)]}))
    r = run_main("--objects", f, "--orders", "1", "--out", tmp_path / "o", *[a for s in sets for a in ("--set", s)])
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "231 train objects" in lines[0] and words in lines[0], r.stderr
    part = words.split(".")[0]
    assert f"--set {part}.when_full=forget_oldest" in lines[0], lines[0]
    assert not (tmp_path / "o").exists()


def test_check_capacity_counts_train_objects_against_a_refusing_memory_and_hub():
    from aesop_torch.agent import AgentConfig
    from train.common.models import check_capacity
    cfg = AgentConfig()
    assert check_capacity(cfg, 230) is None
    both = check_capacity(cfg, 231)   # both refuse: one line names both, and the fix for both
    assert "memory.max_episodes = 230 and memory.when_full = refuse, hub.max_assemblies = 230" in both, both
    assert "--set memory.when_full=forget_oldest --set hub.when_full=forget_oldest" in both, both
    assert "--set memory.max_episodes=231 --set hub.max_assemblies=231" in both, both
    cfg.memory.when_full = "forget_oldest"
    assert "hub.max_assemblies = 230" in check_capacity(cfg, 231)
    cfg.hub.when_full = "forget_weakest"
    assert check_capacity(cfg, 2000) is None
    cfg.memory.when_full, cfg.memory.max_episodes = "refuse", 4
    assert check_capacity(cfg, 4) is None and "would stop at episode 5" in check_capacity(cfg, 5)


# Files of at most MAX_FILE_BYTES that made the old nesting scan ('"(?:[^"\\]|\\.)*"' removed by re.sub) retry
# from every quote: an unterminated string of escaped quotes took ~35 minutes. Each is refused in a fraction of a
# second now (measured: < 0.1 s for the scan, ~1 s for the subprocess with its imports).
PATHOLOGICAL = {
    "unterminated string of escaped quotes": '"' + '\\"' * ((MAX_FILE_BYTES - 1) // 2),
    "escaped quotes without an opening quote": '\\"' * (MAX_FILE_BYTES // 2),
    "a key of escaped quotes, unterminated": '{"train": [], "' + '\\"' * ((MAX_FILE_BYTES - 20) // 2),
    "quote and backslash pairs": '"\\' * (MAX_FILE_BYTES // 2),
    "only quotes": '"' * (MAX_FILE_BYTES - 1),
    "a million brackets": "[" * MAX_FILE_BYTES,
    "brackets inside an unterminated string": '"' + '[\\"' * ((MAX_FILE_BYTES - 1) // 3),
}


@pytest.mark.parametrize("name", list(PATHOLOGICAL))
def test_a_pathological_megabyte_is_refused_in_seconds(tmp_path, name):
    text = PATHOLOGICAL[name]
    assert MAX_FILE_BYTES - 10 <= len(text.encode()) <= MAX_FILE_BYTES
    f = tmp_path / "bad.json"
    f.write_text(text)
    code = ("import sys, time; from sim.objects import ObjectsFileError, load_objects\n"
            "t = time.perf_counter()\n"
            "try:\n    load_objects(sys.argv[1])\nexcept ObjectsFileError as e:\n"
            "    print(f'{time.perf_counter() - t:.3f}', e)\n")
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", code, str(f)], cwd=ROOT, capture_output=True, text=True, timeout=60)
    wall = time.perf_counter() - t0
    assert r.returncode == 0 and r.stderr == "", r.stderr
    seconds, _, msg = r.stdout.strip().partition(" ")
    assert msg and "\n" not in msg, r.stdout      # refused, in one line
    assert float(seconds) < 5.0 and wall < 30.0, (seconds, wall)
